"""Local passivity: the input- and output-strict passivity indices of the linearisation at an equilibrium."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from codegen.passivity._equilibrium import _equilibrium_point
from codegen.passivity._frequency import _frequency_response, _hamiltonian_crossings, _index_sweep, _nu_of, _rho_of
from codegen.passivity._model import _Model, _model
from codegen.passivity._result import PassivityTest
from phs.errors import InputDataError


@dataclass(frozen=True, eq=False)
class LocalPassivity:
    """Passivity of the linearisation at an equilibrium (see :func:`local_passivity`).

    Attributes
    ----------
    statespace : control.StateSpace
        The linearisation in reduced, scaled and balanced state coordinates ``z`` (``δx = T z``);
        inputs and outputs in the model's units.
    T : ndarray
        Map from ``z`` to the state deviation ``δx`` (n x r).
    removed : int
        Conserved directions of J removed before linearising (Casimirs).
    eigenvalues : ndarray
        Eigenvalues of the reduced state matrix.
    stability : str
        ``stable``, ``marginal`` or ``unstable``.
    input_index, output_index : float
        Input-feedforward index ``ν = inf_ω λ_min(He G(jω))`` and output-feedback index
        ``ρ = inf_ω λ_min(He G(jω)^-1)``: ``y^T u >= dV/dt + ν |u|^2`` and ``>= dV/dt + ρ |y|^2``.
    units : tuple of str
        Units of ν and ρ.
    verdict : str
        ``pass``, ``fail`` or ``undecided``.
    details : dict
        Frequencies, the Hamiltonian-matrix verification and its conditioning, the storage-function
        (Hessian of H) KYP residual and, where cvxopt is installed, python-control's LMI indices.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> loc = local_passivity(mass_spring_damper(b=0.4), u_eq={"F": 1.0})
    >>> loc.verdict, round(loc.output_index, 6), abs(loc.input_index) < 1e-9   # rho = b, nu = 0
    ('pass', 0.4, True)
    """

    system_name: str
    x_eq: dict
    u_eq: dict
    statespace: object
    T: np.ndarray
    removed: int
    eigenvalues: np.ndarray
    stability: str
    input_index: float
    output_index: float
    units: tuple
    verdict: str
    summary: str
    details: dict = field(default_factory=dict)
    element: str = ""

    def test(self) -> PassivityTest:
        """This result as the ``local`` test of a :class:`PassivityReport`."""
        d = self.details
        numbers = {"input_index": self.input_index, "output_index": self.output_index,
                   "input_index_unit": self.units[0], "output_index_unit": self.units[1],
                   "stability": self.stability, "spectral_abscissa": float(np.max(self.eigenvalues.real))
                   if len(self.eigenvalues) else 0.0, "states_after_reduction": int(self.T.shape[1]),
                   "conserved_directions_removed": self.removed, "u_eq": self.u_eq,
                   **{k: v for k, v in d.items() if k not in ("omega", "nu_curve", "rho_curve")}}
        return PassivityTest("local", self.verdict, d.get("method", ""), self.summary, numbers, dict(self.x_eq),
                             self.element, {k: d[k] for k in ("omega", "nu_curve", "rho_curve") if k in d})


def _conserved(M: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Orthonormal conserved directions (in scaled states x / s) of ``x' = M(x) [...]``: the left null space of
    ``diag(1/s) M``, columns equilibrated so only structural dependences fall below the threshold."""
    Ms = M / s[:, None]
    cn = np.linalg.norm(Ms, axis=0)
    Ms = Ms[:, cn > 0] / cn[cn > 0]
    if Ms.shape[1] == 0:
        return np.eye(len(s))
    U, sv, _ = np.linalg.svd(Ms)
    r = int(np.sum(sv > 1e-12 * sv[0])) if sv.size and sv[0] > 0 else 0
    return U[:, r:]


def _lti(model: _Model, x, u, p):
    """Linearisation at (x, u): scaled, reduced by the conserved directions, balanced."""
    system = model.system
    A, B, C, D, Hs, M, _ = (np.asarray(v, dtype=float) for v in model.flin(x, u, p))
    n, m = model.nx, model.nu
    A, B, C, D = A.reshape(n, n), B.reshape(n, m), C.reshape(m, n), D.reshape(m, m)
    s = np.array([st.typical for st in system.states])
    W = _conserved(M.reshape(n, -1), s)
    if W.shape[1]:
        Vr = scipy.linalg.null_space(W.T)
    else:
        Vr = np.eye(n)
    As = A * s[None, :] / s[:, None]
    Ar, Br, Cr = Vr.T @ As @ Vr, Vr.T @ (B / s[:, None]), (C * s[None, :]) @ Vr
    leak = float(np.linalg.norm(W.T @ As) / max(np.linalg.norm(As), 1e-300)) if W.shape[1] else 0.0
    if Ar.size:
        _, (sc, perm) = scipy.linalg.matrix_balance(Ar, permute=False, separate=True)
    else:
        sc = np.ones(0)
    Tb = np.diag(sc)
    Ab, Bb, Cb = Ar * sc[None, :] / sc[:, None], Br / sc[:, None], Cr * sc[None, :]
    Pz = Vr.T @ (Hs.reshape(n, n) * np.outer(s, s)) @ Vr
    Pb = Pz * np.outer(sc, sc)
    T = (s[:, None] * Vr) @ Tb
    return Ab, Bb, Cb, D, Pb, T, W.shape[1], {"conserved_leak": leak, "cond_balancing": float(np.max(sc) / np.min(sc))
                                               if sc.size else 1.0}


def _cvxopt_available() -> bool:
    try:
        import control.passivity as cp
    except ImportError:  # pragma: no cover - python-control is a dependency
        return False
    return cp.cvx is not None


def _units_of(system) -> tuple[str, str]:
    ins = {i.unit for i in system.inputs}
    outs = {i.output_unit for i in system.inputs}
    if len(ins) == 1 and len(outs) == 1:
        a, b = ins.pop(), outs.pop()
        return f"{b}/{a}", f"{a}/{b}"
    return "[y]/[u]", "[u]/[y]"


def local_passivity(system, x_eq=None, u_eq=None, *, params=None, x0=None, frequencies: int = 600,
                    cross_check: bool | None = None) -> LocalPassivity:
    """Passivity indices of the linearisation of ``system`` at an equilibrium.

    The linearisation ``δx' = A δx + B δu``, ``δy = C δx + D δu`` is taken at ``(x_eq, u_eq)`` with the
    generated Jacobians, in scaled states ``x / s``; the conserved directions of J (the left null space of
    ``[J - R, G - P]``: Casimirs such as the curling HASEL's top-film length, one per segment) are removed
    first, since they only add zero eigenvalues; the rest is balanced.  Then, with ``G(s)`` its transfer
    matrix:

    * the input-feedforward index ``ν = inf_ω λ_min(He G(jω))`` and the output-feedback index
      ``ρ = inf_ω λ_min(He G(jω)^-1)`` from a log-spaced frequency sweep (refined around its minima, plus
      ω = ∞), each verified by the imaginary-axis eigenvalues of the Hamiltonian matrix of the Popov function
      at the index minus a small margin (an LMI-free KYP test; its conditioning is reported);
    * the storage-function test: whether ``V = ½ δxᵀ ∇²H δx`` satisfies the KYP inequality (exact for a
      port-Hamiltonian linearisation);
    * where cvxopt is installed, python-control's LMI indices (``get_input_ff_index``,
      ``get_output_fb_index``) on the same scaled model, for comparison.

    The verdict is ``pass`` for a stable linearisation with ``ν >= 0`` (to 1e-8 of the gain) or when the
    storage function certifies it, ``fail`` for an unstable one or ``ν < 0``, else ``undecided``.

    Parameters
    ----------
    system : PHSystem
    x_eq : dict, array or EquilibriumResult, optional
        The equilibrium state; checked (an :class:`EquilibriumError` names a state that moves).  Default:
        solved with :func:`phs.equilibrium` under ``u_eq`` from ``x0``.
    u_eq : dict or float, optional
        Constant input at the equilibrium (default zero).
    params : dict, optional
        Parameter overrides.
    x0 : dict, optional
        Starting point of the equilibrium solver (fixes the conserved quantities).
    frequencies : int
        Number of frequencies of the sweep.
    cross_check : bool, optional
        Compare with python-control's LMI: ``None`` when cvxopt is installed, ``True`` requires it.

    Returns
    -------
    LocalPassivity

    Raises
    ------
    EquilibriumError
        When ``x_eq`` is not an equilibrium (or none is found).
    InputDataError
        For unknown state or input names, or ``cross_check=True`` without cvxopt.

    Examples
    --------
    >>> from systems.examples import rlc_circuit
    >>> loc = local_passivity(rlc_circuit(R=10.0), cross_check=False)
    >>> loc.verdict, round(loc.output_index, 6), loc.units                  # rho = R
    ('pass', 10.0, ('A/V', 'V/A'))
    """
    import control

    model = _model(system)
    p = system.param_vector(params, signs=False)  # a what-if value of the wrong sign is reported, not refused
    x, uv, how = _equilibrium_point(system, model, x_eq, u_eq, p, params, x0)
    x_named = dict(zip(system.state_names, map(float, x)))
    u_named = dict(zip(system.input_names, map(float, uv)))
    unit_nu, unit_rho = _units_of(system)
    if not system.inputs:
        return LocalPassivity(system.name, x_named, u_named, None, np.zeros((len(x), 0)), 0, np.zeros(0), "stable",
                              float("nan"), float("nan"), (unit_nu, unit_rho), "undecided",
                              "the system has no ports: passivity is not defined", {"method": how})
    if cross_check and not _cvxopt_available():
        raise InputDataError("local_passivity: cross_check=True needs cvxopt (pip install cvxopt)")
    A, B, C, D, Pb, T, removed, cond = _lti(model, x, uv, p)
    ss = control.ss(A, B, C, D)
    lam = np.linalg.eigvals(A) if A.size else np.zeros(0)
    lam_scale = float(np.max(np.abs(lam))) if lam.size else 0.0
    alpha = float(np.max(lam.real)) if lam.size else -np.inf
    tol_eig = 1e-11 * max(lam_scale, 1e-300)  # eigenvalue errors of the balanced matrix: ~1e-16 of its norm
    stability = "unstable" if alpha > tol_eig else ("marginal" if alpha >= -tol_eig else "stable")
    nz = np.abs(lam[np.abs(lam) > tol_eig])
    lo_w = max(float(np.min(nz)) / 1e3, 1e-12) if nz.size else 1e-3
    hi_w = float(np.max(nz)) * 1e3 if nz.size else 1e3
    w = np.unique(np.concatenate([np.logspace(np.log10(lo_w), np.log10(hi_w), frequencies),
                                  np.abs(lam.imag[np.abs(lam.imag) > 0])]))
    details: dict = {"method": how, **cond}
    gain = max(float(np.max(np.linalg.norm(_frequency_response(A, B, C, D, w), ord=2, axis=(1, 2)))), 1e-300)

    def rho_of(G):
        return _rho_of(G, 1e-12 * gain)

    nu, w_nu, nu_curve = _index_sweep(_nu_of, A, B, C, D, w)
    rho, w_rho, rho_curve = _index_sweep(rho_of, A, B, C, D, w)
    if stability == "stable" and np.linalg.cond(A) < 1e14:
        G_0 = (C @ np.linalg.solve(-A, B) + D)[None]
        nu, w_nu = (float(_nu_of(G_0)[0]), 0.0) if _nu_of(G_0)[0] < nu else (nu, w_nu)
        rho, w_rho = (float(rho_of(G_0)[0]), 0.0) if rho_of(G_0)[0] < rho else (rho, w_rho)
    details.update({"omega": w, "nu_curve": nu_curve, "rho_curve": rho_curve, "nu_frequency": w_nu,
                    "rho_frequency": w_rho, "gain": gain, "eigenvalue_spread": float(np.max(nz) / np.min(nz)) if nz.size else 1.0})
    m = B.shape[1]
    # LMI-free KYP verification: no imaginary-axis eigenvalue of the Popov Hamiltonian just below the index
    if stability == "stable":
        delta = 1e-6 * gain
        verified = False
        info = {}
        for _ in range(5):
            Mq = np.block([[np.zeros((m, m)), np.eye(m) / 2], [np.eye(m) / 2, -(nu - delta) * np.eye(m)]])
            try:
                cross, info = _hamiltonian_crossings(A, B, C, D, Mq)
            except np.linalg.LinAlgError:
                break
            cross = cross[cross > 0]
            if not cross.size:
                verified = True
                break
            extra = _nu_of(_frequency_response(A, B, C, D, cross))
            if np.min(extra) >= nu:  # crossings the sweep cannot confirm: report, do not loop
                break
            nu, w_nu = float(np.min(extra)), float(cross[int(np.argmin(extra))])
        details["hamiltonian_nu"] = {"verified": verified, "margin": delta, **info}
        if np.isfinite(rho):
            drho = 1e-6 * max(abs(rho), 1 / gain)
            Mq = np.block([[-(rho - drho) * np.eye(m), np.eye(m) / 2], [np.eye(m) / 2, 1e-6 * gain * np.eye(m)]])
            try:
                cross, info = _hamiltonian_crossings(A, B, C, D, Mq)
                details["hamiltonian_rho"] = {"verified": not np.any(cross > 0), "margin": drho, **info}
            except np.linalg.LinAlgError:
                details["hamiltonian_rho"] = {"verified": False}
    # storage function V = 1/2 dx^T Hess(H) dx in the KYP inequality
    K = np.block([[A.T @ Pb + Pb @ A, Pb @ B - C.T], [B.T @ Pb - C, -(D + D.T)]])
    kscale = max(np.linalg.norm(A.T @ Pb + Pb @ A), np.linalg.norm(Pb @ B) + np.linalg.norm(C), np.linalg.norm(D + D.T), 1e-300)
    kyp = float(np.max(np.linalg.eigvalsh((K + K.T) / 2)) / kscale) if K.size else 0.0
    pmin = float(np.min(np.linalg.eigvalsh(Pb)) / max(np.linalg.norm(Pb), 1e-300)) if Pb.size else 0.0
    storage_ok = kyp <= 1e-9 and pmin >= -1e-9
    details["storage_kyp"] = {"max_eigenvalue_relative": kyp, "min_eigenvalue_hessian_relative": pmin, "certifies": storage_ok}
    if cross_check is not False and _cvxopt_available():
        details["lmi"] = _lmi_indices(ss, nu, rho, gain)
    tol_nu = 1e-8 * gain
    element = ""
    if stability == "unstable":
        k = int(np.argmax(lam.real))
        vec = np.abs(T @ np.linalg.eig(A)[1][:, k]) / np.array([st.typical for st in system.states])
        names = [system.state_names[i] for i in np.argsort(-vec)[:3]]
        verdict, element = "fail", "unstable mode in " + ", ".join(names)
        summary = f"the linearisation is unstable (eigenvalue {lam[k]:.4g} 1/s): not passive with a positive storage"
    elif stability == "stable" and nu >= -tol_nu:
        verdict = "pass"
        summary = f"passive: input index ν = {nu:.4g} {unit_nu}, output index ρ = {rho:.4g} {unit_rho}"
    elif nu < -tol_nu:
        verdict = "fail"
        Gw = _frequency_response(A, B, C, D, np.array([w_nu if np.isfinite(w_nu) else 1e300]))[0]
        v = np.linalg.eigh((Gw + Gw.conj().T) / 2)[1][:, 0]
        element = "port " + ", ".join(system.input_names[i] for i in np.argsort(-np.abs(v))[:2] if abs(v[i]) > 0.3)
        summary = (f"not passive: He G(jω) has eigenvalue {nu:.4g} {unit_nu} < 0 at ω = {w_nu:.4g} rad/s "
                   f"(output index ρ = {rho:.4g} {unit_rho})")
    elif storage_ok:
        verdict = "pass"
        summary = f"passive (storage ½ δxᵀ∇²H δx satisfies the KYP inequality); ν = {nu:.4g} {unit_nu}, ρ = {rho:.4g} {unit_rho}"
    else:
        verdict = "undecided"
        summary = (f"eigenvalues on the imaginary axis and the Hessian of H is no KYP storage: ν = {nu:.4g} {unit_nu} "
                   f"away from the poles")
    details["method"] = (f"{how}; linearised with generated Jacobians, {removed} conserved direction(s) removed, scaled and "
                         f"balanced; frequency sweep ({len(w)} points) verified by the Popov Hamiltonian matrix"
                         + ("; python-control LMI (cvxopt) for comparison" if "lmi" in details else ""))
    return LocalPassivity(system.name, x_named, u_named, ss, T, removed, lam, stability, float(nu), float(rho),
                          (unit_nu, unit_rho), verdict, summary, details, element)


def _lmi_indices(ss, nu, rho, gain) -> dict:
    """python-control's LMI passivity indices (cvxopt) on the same scaled model, and whether they agree."""
    import control

    out: dict = {}
    for key, fn in (("input_index", control.get_input_ff_index), ("output_index", control.get_output_fb_index)):
        try:
            out[key] = float(fn(ss))
        except Exception as exc:  # the LMI solver's own failures are part of the comparison
            out[key] = None
            out[f"{key}_error"] = f"{type(exc).__name__}: {str(exc).splitlines()[0][:160] if str(exc) else ''}"
    try:
        out["ispassive"] = bool(control.ispassive(ss))
    except Exception as exc:
        out["ispassive"] = None
        out["ispassive_error"] = f"{type(exc).__name__}: {str(exc).splitlines()[0][:160] if str(exc) else ''}"
    agree = []
    if out.get("input_index") is not None:
        agree.append(abs(out["input_index"] - nu) <= 1e-4 * gain + 1e-6 * abs(nu))
    if out.get("output_index") is not None and np.isfinite(rho):
        agree.append(abs(out["output_index"] - rho) <= 1e-4 * max(abs(rho), 1 / gain))
    out["agree"] = bool(agree) and all(agree)
    return out
