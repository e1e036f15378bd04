"""Certificates of an IDA-PBC design, each with its numbers.

``matching``
    The closed loop under the generated law equals the target ``(J_d - R_d) dH_d/dx``: maximum over sample
    points on the leaf around ``x*`` of the scaled difference (and exact coefficient matching when the
    matching equations were polynomial).
``interconnection``
    ``J_d + J_d^T`` simplifies to zero (symbolic).
``dissipation``
    ``R_d`` positive semidefinite: the scaled margin of :func:`codegen.passivity.dissipation_margin` over the
    model's box when that module is present, and the smallest eigenvalue at the sample points.
``conserved``
    ``J_d - R_d`` keeps the plant's conserved quantities (their gradients annihilate it), so the closed loop
    regulates on the leaf it starts on.
``equilibrium``
    ``dH_d/dx(x*)`` has no component along the leaf (it is a pure conserved-quantity direction, absorbed by
    a Casimir function in the energy-Casimir sense), relative to the gradient of ``H`` that the shaping cancels.
``hessian``
    Eigenvalues of the Hessian of ``H_d`` along the leaf at ``x*``, with the states scaled by their typical
    magnitudes (second-order terms of the leaf included); with passive integral action the integrator adds ``K_i``.
``integrability`` (when ``Phi`` has no closed form)
    ``v`` restricted to the leaf is closed (``T^T dv/dx T`` symmetric), so ``Phi`` exists.
``linearization``
    Eigenvalues of the closed loop's Jacobian on the leaf (integrator states included).
``region``
    The largest sublevel set ``{H_d - H_d(x*) < c}`` of the rays sampled from ``x*`` along the leaf that stays
    inside the validity domain and the inputs' ranges; a run from inside it that ends at another rest state
    shows a lower pass between basins and shrinks it below the run's starting level (a sampled estimate).
``simulations``
    Closed-loop runs from random states inside that set: ``H_d`` (with the integrator's energy) non-increasing
    and convergence to ``x*``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from codegen._named import find_named
from codegen.idapbc.closed_loop import simulate_closed_loop
from codegen.idapbc.linear import closed_loop_modes, leaf_hessian
from phs._json import jsonable as _jsonable
from phs._results import ResultMixin, draw_verdicts, finish, panels, require_pandas
from phs.errors import PHSError

RUN_STEPS = 5000
"""CVODES's limit of internal steps per output interval (1/400 of the horizon) in the certificate's closed-loop
runs.  A run that needs more is counted as failed, saying so: near x* the closed loop takes a few tens of steps
per interval; a start where it is thousands of times faster (e.g. against the steep wall of a material spring)
would otherwise run for hours."""

RUN_SECONDS = 30.0
"""CPU seconds allowed to one certificate run (a second bound, for runs whose steps are slow rather than many)."""

UNFINISHED_SHRINK = 0.25
"""Share of its level below which the estimated set is shrunk when a run from inside it could not be finished
within :data:`RUN_STEPS` or :data:`RUN_SECONDS` (its start unverified; at most three rounds, as for a run that ends
at another rest state, after which the runs' certificate is undecided, not failed).  Against a wall that stiffens
as a power of the distance, a quarter of the energy is about half the distance.  Not chosen on a measurement."""


@dataclass(frozen=True)
class Certificate:
    """One certificate: verdict (``pass``, ``fail``, ``undecided``), method, a sentence with numbers, the numbers."""

    name: str
    verdict: str
    method: str
    summary: str
    numbers: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return self.verdict == "pass"

    def to_dict(self) -> dict:
        return {"name": self.name, "verdict": self.verdict, "method": self.method, "summary": self.summary,
                "numbers": _jsonable(self.numbers)}


class CertificateReport(ResultMixin):
    """The certificates of one controller; ``passed`` when every one passed.

    ``bool(report)`` is :attr:`passed` (an undecided certificate makes it False); ``report["hessian"]`` is one
    :class:`Certificate`; ``str(report)`` is the full text, ``repr`` one line; :meth:`plot` draws one coloured
    row per certificate and :meth:`to_pandas` gives one row per certificate.

    Examples
    --------
    >>> from codegen.idapbc import design
    >>> from systems.examples import mass_spring_damper
    >>> rep = design(mass_spring_damper(), {"position": 0.5}, damping=1.0).certify(rays=8, simulations=2)
    >>> rep["hessian"].verdict, rep.passed, bool(rep)
    ('pass', True, True)
    >>> rep  # doctest: +ELLIPSIS
    CertificateReport('msd', passed; matching pass, interconnection pass, ...)
    """

    def __init__(self, controller, items, info):
        self.controller = controller
        self.items = list(items)
        self.info = dict(info)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.items)

    def __bool__(self) -> bool:
        return self.passed

    def __getitem__(self, name: str) -> Certificate:
        return find_named(self.items, name, "certificate")

    def text(self) -> str:
        head = f"Certificates of the IDA-PBC controller for {self.controller.system.name!r}: " + (
            "all passed" if self.passed else "NOT ALL PASSED")
        return "\n".join([head] + [f"  [{c.verdict:^9}] {c.name} ({c.method}): {c.summary}" for c in self.items])

    def __str__(self) -> str:
        return self.text()

    def _headline(self) -> str:
        return (f"{self.controller.system.name!r}, {'passed' if self.passed else 'NOT ALL PASSED'}; "
                + ", ".join(f"{c.name} {c.verdict}" for c in self.items))

    def _table(self) -> tuple[list, list]:
        return ["certificate", "verdict", "method", "summary"], [(c.name, c.verdict, c.method, c.summary) for c in self.items]

    def to_dict(self) -> dict:
        return {"system": self.controller.system.name, "passed": self.passed,
                "certificates": {c.name: c.to_dict() for c in self.items}, "info": _jsonable(self.info)}

    def to_pandas(self):  # noqa: ANN201 - pandas is optional
        """One row per certificate (verdict, method, summary), indexed by its name.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> from codegen.idapbc import design
        >>> from systems.examples import mass_spring_damper
        >>> rep = design(mass_spring_damper(), {"position": 0.5}, damping=1.0).certify(rays=8, simulations=2)
        >>> rep.to_pandas().loc["hessian", "verdict"]  # doctest: +SKIP
        'pass'
        """
        pd = require_pandas("CertificateReport.to_pandas()")
        header, rows = self._table()
        return pd.DataFrame({c: [r[k] for r in rows] for k, c in enumerate(header[1:], start=1)},
                            index=pd.Index([r[0] for r in rows], name="certificate"))

    def plot(self, path=None, *, ax=None):  # noqa: ANN201 - matplotlib is imported on demand
        """One coloured row per certificate: green pass, red fail, amber undecided, with its numbers.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).
        ax : matplotlib Axes, optional
            Draw into this axes.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> from codegen.idapbc import design
        >>> from systems.examples import mass_spring_damper
        >>> rep = design(mass_spring_damper(), {"position": 0.5}, damping=1.0).certify(rays=8, simulations=2)
        >>> len(rep.plot().axes[0].texts) == len(rep.items)
        True
        """
        fig, grid = panels(ax, 1, figsize=(9, 0.4 * len(self.items) + 0.9), what="CertificateReport.plot")
        draw_verdicts(grid[0, 0], [(c.name, c.verdict, c.summary) for c in self.items],
                      title=f"IDA-PBC certificates for {self.controller.system.name}: "
                            + ("all passed" if self.passed else "NOT ALL PASSED"))
        return finish(fig, path)


# -- sampling on the leaf --------------------------------------------------------------------------
def _leaf_points(ctrl, k: int, seed: int, spread: float = 0.3):
    """Points of the leaf near x* inside the validity domain (free coordinates perturbed by spread * scale)."""
    rng = np.random.default_rng(seed)
    lf, num = ctrl.leaf, ctrl.num
    pts = []
    tries = 0
    while len(pts) < k and tries < 20 * k:
        tries += 1
        xf = ctrl.x_star[lf.free] + spread * num.scale[lf.free] * rng.uniform(-1, 1, len(lf.free))
        try:
            xp = lf.transport(ctrl.x_star, xf)
        except PHSError:
            continue
        u = np.asarray(ctrl._fx["u_full"](xp, np.zeros(ctrl.n_xi)), dtype=float).reshape(-1)
        if num.violated(xp, u) or not np.all(np.isfinite(u)):
            continue
        pts.append(xp)
    return pts


def _rays(ctrl, n_rays: int, seed: int, s_max: float = 3.0, n_pts: int = 36):
    """Rays from x* along the leaf: (s, state, H_d - H_d*, first unsafe index, why) per ray."""
    rng = np.random.default_rng(seed)
    lf, num, fx = ctrl.leaf, ctrl.num, ctrl._fx
    sF = num.scale[lf.free]
    grid = s_max * (np.arange(1, n_pts + 1) / n_pts) ** 1.5
    hd0 = float(fx["Hd"](ctrl.x_star))
    ranges = [(k, ctrl.system.inputs[j].range) for k, j in enumerate(ctrl.ctrl)]
    cov = fx["v"] if ctrl.phi_implicit else None
    out = []
    for _ in range(n_rays):
        d = rng.standard_normal(len(lf.free))
        d /= np.linalg.norm(d)
        x, phi, sprev = ctrl.x_star.copy(), 0.0, 0.0
        rec = []
        why = ""
        for s in grid:
            try:
                if cov is None:
                    x = lf.transport(x, ctrl.x_star[lf.free] + s * sF * d)
                    dphi = 0.0
                else:
                    x, dphi = lf.transport(x, ctrl.x_star[lf.free] + s * sF * d, covector=cov, rtol=1e-9)
            except PHSError:
                why = "the leaf cannot be followed further"
                break
            phi += dphi
            u = np.asarray(fx["u_full"](x, np.zeros(ctrl.n_xi)), dtype=float).reshape(-1)
            hd = float(fx["Hd"](x)) - hd0 + phi
            bad = num.violated(x, u)
            if not bad:
                for k, r in ranges:
                    uk = u[ctrl.ctrl[k]]
                    if r is not None and not (r[0] <= uk <= r[1]):
                        bad = [f"input {ctrl.input_names[k]} = {uk:.6g} outside [{r[0]:g}, {r[1]:g}]"]
            if not np.isfinite(hd):
                bad = bad or ["H_d not finite"]
            rec.append((s, x.copy(), hd, bad))
            sprev = s
        out.append((d, rec, why, sprev))
    return out


def certify(ctrl, *, samples: int = 24, rays: int = 32, simulations: int = 6, horizon: float | None = None,
            seed: int = 0, use_passivity: bool = True) -> CertificateReport:
    """Compute every certificate of the module docstring for ``ctrl``.

    Parameters
    ----------
    samples : int
        Points of the leaf around ``x*`` for the matching, dissipation and integrability checks.
    rays : int
        Rays of the sublevel-set estimate.
    simulations : int
        Closed-loop runs from random states inside the estimated set.
    horizon : float, optional
        Length of those runs [s] (default: 20 times the slowest closed-loop time constant).
    seed : int
        Seed of every random choice.
    use_passivity : bool
        Use :func:`codegen.passivity.dissipation_margin` for the ``dissipation`` certificate when available.

    Returns
    -------
    CertificateReport
    """
    wall = time.perf_counter()
    items = []
    fx, num, lf = ctrl._fx, ctrl.num, ctrl.leaf
    n, nxi = num.n, ctrl.n_xi
    s = num.scale
    pts = _leaf_points(ctrl, samples, seed)
    # matching
    worst, ref = 0.0, 0.0
    for x in pts:
        fcl = np.asarray(fx["plant"](x, np.zeros(nxi)), dtype=float).reshape(n) / s
        tgt = np.asarray(fx["target"](x), dtype=float).reshape(n) / s
        worst = max(worst, float(np.max(np.abs(fcl - tgt))))
        ref = max(ref, float(np.max(np.abs(tgt))))
    rel = worst / max(ref, 1e-300)
    method = ("coefficient matching (exact) and " if ctrl.structure.symbolic and not ctrl.structure.unsolved else "") \
        + f"sampled ({len(pts)} points of the leaf)"
    ok = rel <= 1e-8 and not ctrl.structure.unsolved and len(pts) > 0
    msg = f"max |f(x, u(x)) - (J_d - R_d) dH_d/dx| = {rel:.3g} of the largest scaled rate"
    if ctrl.structure.unsolved:
        msg += "; unsolved: " + "; ".join(ctrl.structure.unsolved)
    items.append(Certificate("matching", "pass" if ok else ("undecided" if not pts else "fail"), method, msg,
                             {"relative_residual": rel, "points": len(pts)}))
    # interconnection
    Jd = ctrl.J_d
    nonzero = [(i, j) for i in range(n) for j in range(i, n) if Jd[i, j] + Jd[j, i] != 0
               and sp.simplify(Jd[i, j] + Jd[j, i]) != 0]
    items.append(Certificate("interconnection", "fail" if nonzero else "pass", "symbolic",
                             "J_d + J_d^T simplifies to zero" if not nonzero else
                             "J_d is not skew at " + ", ".join(f"({ctrl.system.state_names[i]}, {ctrl.system.state_names[j]})"
                                                              for i, j in nonzero[:4])))
    items.append(_dissipation(ctrl, pts, use_passivity))
    # conserved quantities kept
    if lf.k:
        keep = 0.0
        for x in pts or [ctrl.x_star]:
            W = lf.W(x) * s[None, :]
            M = (np.asarray(fx["Jd"](x), dtype=float) - np.asarray(fx["Rd"](x), dtype=float)) / s[:, None]
            W = W / np.linalg.norm(W, axis=1, keepdims=True)
            keep = max(keep, float(np.max(np.abs(W @ M))) / max(float(np.max(np.abs(M))), 1e-300))
        items.append(Certificate("conserved", "pass" if keep <= 1e-9 else "fail", f"sampled ({len(pts)} points)",
                                 f"{lf.k} conserved quantit{'y' if lf.k == 1 else 'ies'} of J (dependent states "
                                 f"{', '.join(ctrl.system.state_names[i] for i in lf.dep)}); |w^T (J_d - R_d)| <= "
                                 f"{keep:.3g} of |J_d - R_d|", {"count": lf.k, "relative": keep}))
    # equilibrium
    x = ctrl.x_star
    T = lf.tangent(x)
    dHd = np.asarray(fx["dHd"](x), dtype=float).reshape(n)
    dH = np.asarray(num.fn.grad_hamiltonian(x, ctrl.assignment.u, num.p), dtype=float).reshape(n)
    tan_d = (T.T @ dHd) * s[lf.free]
    tan_h = (T.T @ dH) * s[lf.free]
    reference = max(float(np.max(np.abs(tan_h))) if tan_h.size else 0.0, float(np.max(np.abs(dH * s))), 1e-300)
    e_rel = float(np.max(np.abs(tan_d))) / reference if tan_d.size else 0.0
    numbers = {"tangential_gradient_scaled": tan_d, "relative": e_rel}
    text = f"|T^T dH_d/dx(x*)| = {e_rel:.3g} of the gradient of H the shaping cancels"
    if lf.k:
        W = lf.W(x)
        beta = np.linalg.lstsq(W.T, dHd, rcond=None)[0]
        numbers["casimir_multipliers"] = beta
        text += f"; normal part along the {lf.k} conserved direction(s) absorbed by a Casimir function"
    items.append(Certificate("equilibrium", "pass" if e_rel <= 1e-8 else "fail", "evaluated at x*", text, numbers))
    # hessian
    Hs = leaf_hessian(ctrl)
    ev = np.linalg.eigvalsh(Hs) if Hs.size else np.zeros(0)
    extra = np.linalg.eigvalsh((ctrl.K_i + ctrl.K_i.T) / 2) if ctrl.integral == "passive" else np.zeros(0)
    allv = np.concatenate([ev, extra])
    pd = bool(allv.size == 0 or allv.min() > 1e-12 * max(float(np.max(np.abs(allv))), 1e-300))
    items.append(Certificate(
        "hessian", "pass" if pd else "fail", "leaf Hessian, states scaled by their typical magnitudes",
        (f"eigenvalues from {ev.min():.4g} to {ev.max():.4g} J" if ev.size else "no free coordinate")
        + (f" (integrator K_i: {extra.min():.4g})" if extra.size else "")
        + ("" if pd else " - NOT positive definite: x* is not a strict minimum of H_d on the leaf"),
        {"eigenvalues": ev, "integrator": extra}))
    # integrability of v on the leaf
    if ctrl.phi_implicit:
        asym = 0.0
        for xx in pts[: max(4, len(pts) // 3)] or [ctrl.x_star]:
            Tq = lf.tangent(xx)
            Dv = np.asarray(_jac_v(ctrl)(xx), dtype=float).reshape(n, n)
            B = Tq.T @ Dv @ Tq * num.scale[lf.free][None, :] * num.scale[lf.free][:, None]
            asym = max(asym, float(np.max(np.abs(B - B.T))) / max(float(np.max(np.abs(B))), 1e-300))
        items.append(Certificate("integrability", "pass" if asym <= 1e-8 else "fail", "sampled",
                                 f"v restricted to the leaf is closed: max |B - B^T| = {asym:.3g} of |B|, B = T^T dv/dx T; "
                                 "Phi exists and is integrated along the leaf", {"asymmetry": asym}))
    # linearization
    evl = closed_loop_modes(ctrl)
    stable = bool(evl.size == 0 or np.max(evl.real) < 0)
    slow = evl[np.argmax(evl.real)] if evl.size else 0.0
    fast = evl[np.argmin(evl.real)] if evl.size else 0.0
    items.append(Certificate(
        "linearization", "pass" if stable else "fail", f"Jacobian on the leaf ({len(evl)} modes)",
        f"slowest mode {slow:.4g} 1/s, fastest {fast:.4g} 1/s" + ("" if stable else " - UNSTABLE"),
        {"eigenvalues": [complex(v) for v in evl], "max_real": float(np.max(evl.real)) if evl.size else None}))
    # region of attraction and simulations
    reg, sims = _region(ctrl, rays, seed, simulations, horizon, evl)
    items += [reg, sims]
    return CertificateReport(ctrl, items, {"seconds": time.perf_counter() - wall, "seed": seed, "samples": samples,
                                           "rays": rays, "simulations": simulations})


def _jac_v(ctrl):
    import casadi as ca

    f = ctrl.__dict__.get("_jac_v")
    if f is None:
        X = ca.SX.sym("x", ctrl.num.n)
        f = ca.Function("jv", [X], [ca.jacobian(ctrl._fx["v"](X), X)])
        object.__setattr__(ctrl, "_jac_v", f)
    return f


def _dissipation(ctrl, pts, use_passivity) -> Certificate:
    fx, n = ctrl._fx, ctrl.num.n
    mins = []
    for x in pts or [ctrl.x_star]:
        Rd = np.asarray(fx["Rd"](x), dtype=float).reshape(n, n)
        sc = np.sqrt(np.maximum(np.abs(np.diag(Rd)), 1e-300))
        scaled = Rd / sc[:, None] / sc[None, :]
        on = np.abs(np.diag(Rd)) > 0
        if on.any():
            mins.append(float(np.linalg.eigvalsh(scaled[np.ix_(on, on)]).min()))
    local = min(mins) if mins else 0.0
    numbers = {"min_scaled_eigenvalue_on_leaf": local}
    method = f"sampled ({len(pts)} points of the leaf)"
    verdict = "pass" if local >= -1e-9 else "fail"
    text = f"smallest eigenvalue of R_d (diagonal-scaled) near x*: {local:.4g}"
    if use_passivity:
        try:
            from codegen import passivity  # the passivity certificates, when present
        except ImportError:
            passivity = None
        if passivity is not None:
            try:
                target = _target_system(ctrl)
                margin = passivity.dissipation_margin(target, samples=256)
                numbers["passivity_margin_over_box"] = margin
                method += " and codegen.passivity.dissipation_margin over the states' box"
                text += f"; scaled margin over the box {margin:.4g}"
                if not (np.isfinite(margin) and margin >= -1e-9):
                    verdict = "fail"
            except PHSError as exc:
                verdict = "fail"
                msg = " ".join(line.strip(" -") for line in str(exc).splitlines())
                text += f"; the target structure is refused: {msg[:400]}"
    return Certificate("dissipation", verdict, method, text, numbers)


def _target_system(ctrl):
    """The target as a PHSystem (J_d, R_d and the explicit part of H_d) for the structural certificates."""
    from phs.params import Condition
    from phs.system import PHSystem

    s = ctrl.system
    vals = {q.symbol: sp.Float(v) for q, v in zip(s.params, ctrl.num.p)}
    H = s.H.xreplace(vals) + ctrl.structure.H_a
    conds = [Condition(c.label, c.expr.xreplace(vals)) for c in s.conditions if not c.label.endswith(f"in {s.name}")
             and not (c.expr.xreplace(vals).free_symbols & set(s.u))]
    return PHSystem(f"{s.name}_target", s.states, H, ctrl.J_d, ctrl.R_d, conditions=conds,
                    description="IDA-PBC target (explicit part of H_d)")


def _region(ctrl, n_rays, seed, k, horizon, evl):
    """Sublevel-set estimate and the batch of runs inside it (the runs also shrink it, see below)."""
    data = _rays(ctrl, n_rays, seed)
    c_est, limit = math.inf, ""
    for _, rec, _why, _ in data:
        for _s, _, hd, bad in rec:
            if bad and hd < c_est:
                c_est, limit = hd, "; ".join(bad)
    mono = 0
    for _, rec, _, _ in data:
        hs = [hd for _, _, hd, bad in rec if not bad]
        mono += int(all(b >= a - 1e-12 * max(abs(a), 1e-300) for a, b in zip(hs, hs[1:])))
    if not np.isfinite(c_est):
        c_use = min(rec[-1][2] for _, rec, _, _ in data if rec) if any(rec for _, rec, _, _ in data) else 0.0
        text = f"no ray left the validity domain or the input ranges up to 3 typical scales (H_d - H_d* up to {c_use:.4g} J)"
    else:
        c_use = c_est
        text = f"the rays leave the domain or the input ranges at H_d - H_d(x*) = {c_est:.4g} J (limited by {limit})"
    # runs from states inside the set: one converging to another equilibrium shows a lower pass between the
    # basins; the set is then shrunk below its starting level and the runs repeated (at most three rounds)
    if horizon is None:
        slow = np.min(np.abs(evl.real)) if evl.size and np.all(evl.real < 0) else 1.0
        horizon = 20.0 / slow
    # a run that could not be finished within its budget (RUN_STEPS, RUN_SECONDS: a start against a steep wall,
    # where the closed loop is thousands of times faster than near x*) leaves its start unverified: the set is
    # shrunk to UNFINISHED_SHRINK of that start's level and the runs repeated
    other, unfinished = [], []
    for round_ in range(3):
        sims = _simulations(ctrl, data, c_use, k, horizon, seed + round_)
        if sims.numbers.get("elsewhere"):
            level, xe = min(sims.numbers["elsewhere"], key=lambda e: e[0])
            other.append((level, xe))
            c_use = 0.9 * level
        elif sims.numbers.get("unfinished"):
            level = min(sims.numbers["unfinished"])
            unfinished.append(level)
            c_use = UNFINISHED_SHRINK * level
        else:
            break
    if other:
        level, xe = min(other, key=lambda e: e[0])
        dev = (np.asarray(xe) - ctrl.x_star) / ctrl.num.scale
        i = int(np.argmax(np.abs(dev)))
        text += (f"; a run from H_d - H_d* = {level:.4g} J ended at another rest state ({ctrl.system.state_names[i]} = "
                 f"{xe[i]:.4g}): the set is shrunk below it")
    if unfinished:
        text += (f"; {len(unfinished)} run{'s' if len(unfinished) > 1 else ''} from H_d - H_d* = "
                 f"{', '.join(f'{lv:.4g}' for lv in unfinished)} J could not be finished within the runs' budget "
                 f"({RUN_STEPS} steps per output interval, {RUN_SECONDS:g} CPU s): the set is shrunk below "
                 f"{'them' if len(unfinished) > 1 else 'it'}")
    x0 = ctrl.x0
    try:
        h0 = ctrl.H_d(x0)
    except PHSError:
        h0 = float("nan")
    inside = bool(np.isfinite(h0) and h0 < c_use)
    head = (f"estimated region of attraction H_d - H_d(x*) < {c_use:.4g} J; " if c_use > 0 else
            f"EMPTY: H_d is {-c_use:.4g} J below H_d(x*) where the rays leave the domain or the input ranges, so no "
            "sublevel set around x* stays inside; ")
    text = (head + text
            + f"; H_d increases along {mono}/{n_rays} rays; x0 {'inside' if inside else 'outside'} "
              f"(H_d(x0) - H_d* = {h0:.4g} J)")
    numbers = {"c": c_use, "c_boundary": c_est if np.isfinite(c_est) else None, "rays": n_rays, "limit": limit,
               "monotone_rays": mono, "H_d_x0": h0, "x0_inside": inside,
               "other_equilibria": [{"level": lv, "state": dict(zip(ctrl.system.state_names, map(float, xe)))}
                                    for lv, xe in other]}
    ok = c_use > 0 and sims.verdict == "pass"
    verdict = "pass" if ok else "undecided" if c_use > 0 and sims.verdict == "undecided" else "fail"
    numbers["unfinished_levels"] = unfinished
    reg = Certificate("region", verdict, f"sampled ({n_rays} rays of the leaf, checked by the runs)", text, numbers)
    return reg, sims


def _simulations(ctrl, data, c, k, horizon, seed) -> Certificate:
    rng = np.random.default_rng(seed + 1)
    starts = []
    order = rng.permutation(len(data))
    for j in order:
        d, rec, _, _ = data[j]
        if len(starts) >= k:
            break
        frac = rng.uniform(0.3, 0.9)
        best = None
        for _s, x, hd, bad in rec:
            if bad or hd > frac * c:
                break
            best = (x, hd)
        if best is not None and best[1] > 0.05 * c:
            starts.append(best)
    if not starts:
        return Certificate("simulations", "undecided", "closed-loop CVODES runs", "no starting state found in the set")
    t = np.linspace(0.0, horizon, 401)
    worst_inc, worst_dist, fails, elsewhere, unfinished, why = 0.0, 0.0, [], [], [], []
    for x, hd in starts:
        try:
            res = simulate_closed_loop(ctrl, t, x0=x, rtol=1e-10, max_steps=RUN_STEPS, seconds=RUN_SECONDS)
        except PHSError as exc:
            if getattr(exc, "out_of_budget", False):  # not finished: its outcome is unknown, not a failure
                unfinished.append(hd)
                why.append(str(exc).splitlines()[0][:200])
            else:
                fails.append(str(exc).splitlines()[0][:200])
            continue
        h = res.H_cl
        inc = float(np.max(np.diff(h))) / max(h[0] - h[-1], 1e-300)
        worst_inc = max(worst_inc, inc)
        dist = float(np.max(np.abs(res.x[-1] - ctrl.x_star) / ctrl.num.scale))
        if dist > 1e-2 and h[-1] > 1e-6 * h[0]:  # settled away from x*, above its energy: another rest state
            elsewhere.append((hd, res.x[-1]))
        else:
            worst_dist = max(worst_dist, dist)
    ok = not fails and not elsewhere and not unfinished and worst_inc <= 1e-6 and worst_dist <= 1e-2
    done = len(starts) - len(unfinished)
    # only unfinished runs keep it from passing: undecided (every finished run reached x*, if any finished)
    undecided = bool(unfinished) and not fails and not elsewhere and worst_inc <= 1e-6 and worst_dist <= 1e-2
    text = (f"{done - len(fails) - len(elsewhere)}/{len(starts)} runs of {horizon:.3g} s from H_d - H_d* in "
            f"[{min(h for _, h in starts):.3g}, {max(h for _, h in starts):.3g}] J reached x* (final scaled distance "
            f"<= {worst_dist:.2g}); largest increase of H_d between samples {worst_inc:.2g} of its total decrease")
    if elsewhere:
        text += f"; {len(elsewhere)} ended at another rest state"
    if fails:
        text += "; failed: " + "; ".join(fails[:2])
    if unfinished:
        text += f"; {len(unfinished)} not finished within the runs' budget: " + "; ".join(why[:1])
    return Certificate("simulations", "pass" if ok else "undecided" if undecided else "fail",
                       "closed-loop CVODES runs (rtol 1e-10)", text,
                       {"runs": len(starts), "failed": len(fails), "max_relative_increase": worst_inc,
                        "final_scaled_distance": worst_dist, "horizon": horizon, "elsewhere": elsewhere,
                        "unfinished": unfinished})
