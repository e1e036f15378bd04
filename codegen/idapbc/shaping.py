"""The desired structure of an IDA-PBC design: which construction solves the matching equations, and damping.

Given the assigned equilibrium, :func:`desired_structure` substitutes the
controller's parameter values, splits the input matrix into the controlled
columns ``g`` and the drift ``f_fix`` of the inputs held constant, chooses the
construction (``"auto"``: electromechanical when it applies and nothing was
given by hand, otherwise the ansatz; see :mod:`codegen.idapbc.matching`),
solves it, and adds the damping injection ``R_a += r g g^T``.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from codegen.idapbc.matching import (
    ANSATZ_UNKNOWNS,
    Structure,
    actuated_split,
    ansatz,
    electromechanical,
    electromechanical_applies,
    quadratic_basis,
)
from phs.errors import InputDataError


def _kernel_complement(M: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rows spanning the complement of the kernel of ``M diag(1/s)`` (scaled coordinates)."""
    Ms = (M / s[:, None]) / s[None, :]
    _, sv, Vt = np.linalg.svd(Ms)
    r = int(np.sum(sv > 1e-12 * (sv[0] if sv.size and sv[0] > 0 else 1.0)))
    return Vt[:r]


def _numeric_matrix(Msym: sp.Matrix, x, xv) -> np.ndarray:
    return np.array(Msym.xreplace(dict(zip(x, map(sp.Float, xv)))).evalf(), dtype=float)


def _check_matched_stiffness(g, JR, stiffness, system, x, xv, scale) -> str:
    """Stiffness on actuated storages is matched only if (J - R)_AA K stays in the span of g_A everywhere."""
    if not stiffness:
        return ""
    A, _ = actuated_split(g)
    names = system.state_names
    bad_not_a = [nm for nm in stiffness if names.index(nm) not in A]
    if bad_not_a:
        return (f"stiffness on {', '.join(map(repr, bad_not_a))}: the electromechanical construction shapes only the "
                f"actuated storages ({', '.join(names[i] for i in A)}); the others keep the plant's energy")
    K = np.zeros((len(A), len(A)))
    for nm, k in stiffness.items():
        K[A.index(names.index(nm)), A.index(names.index(nm))] = k
    JRAA = JR.extract(A, A)
    gA = g.extract(A, list(range(g.cols)))
    f = sp.lambdify([x], [JRAA, gA], "numpy")
    rng = np.random.default_rng(1)
    for _ in range(8):
        pt = np.asarray(xv) + 0.2 * scale * rng.uniform(-1, 1, len(x))
        with np.errstate(all="ignore"):
            Mv, gv = (np.asarray(a, dtype=float) for a in f(pt))
        if not (np.all(np.isfinite(Mv)) and np.all(np.isfinite(gv))):
            continue
        Q, _ = np.linalg.qr(gv.reshape(len(A), -1))
        resid = (np.eye(len(A)) - Q @ Q.T) @ Mv @ K
        if np.max(np.abs(resid)) > 1e-9 * max(np.max(np.abs(Mv @ K)), 1e-300):
            return (f"stiffness on {', '.join(map(repr, stiffness))} is not matched: with one input along g(x), "
                    "(J - R)_AA K (x_A - x_A*) leaves the span of g_A(x) as the configuration changes")
    return ""


def _check_ansatz_size(system, H_a, unknowns, why: str) -> None:
    """Refuse, in one line, an ansatz with more than :data:`ANSATZ_UNKNOWNS` unknown coefficients."""
    n = len(system.states)
    if H_a is None:
        k, what = n * (n + 3) // 2, f"the quadratic ansatz in its {n} states has"
    elif unknowns is not None:
        k, what = len(list(unknowns)), "your H_a has"
    else:
        return  # counted by the ansatz itself; a user's own H_a is small
    if k > ANSATZ_UNKNOWNS:
        raise InputDataError(
            f"{system.name!r} is too large for the symbolic IDA-PBC design: {what} {k} unknown coefficients "
            f"(symbolic matching equations of {k} x {n} entries), more than the {ANSATZ_UNKNOWNS} designed in bounded "
            f"time{f' (the electromechanical construction does not apply: {why})' if why else ''}; leave storages out "
            "with neglect=[...] (--neglect) or give H_a with few unknowns")


def desired_structure(system, num, asg, ctrl, u_base, *, structure: str = "auto", damping: float = 0.0,
                      damping_state: str | None = None, stiffness: dict | None = None, H_a=None, unknowns=None,
                      J_a=None, R_a=None) -> tuple[Structure, sp.Matrix, sp.Matrix, float]:
    """Solve the matching equations at the assignment ``asg`` and add the damping injection.

    Parameters
    ----------
    system : PHSystem
        The design model.
    num : Numeric
        Its functions at the controller's parameter values (:class:`codegen.idapbc.model.Numeric`).
    asg : Assignment
        The assigned equilibrium (:func:`codegen.idapbc.target.assign`).
    ctrl : list of int
        Indices of the controlled inputs.
    u_base : array
        The full input vector (fixed inputs at their values).
    structure, stiffness, H_a, unknowns, J_a, R_a
        As in :func:`codegen.idapbc.design`.
    damping : float
        ``r`` of ``R_a += r g g^T``, or with ``damping_state`` the dissipation added on that state's row at ``x*``.
    damping_state : str, optional
        The state whose row gets ``damping`` (``r = damping / |g_state(x*)|**2``).

    Returns
    -------
    structure : Structure
    g : sympy Matrix
        The controlled columns of ``G - P`` (parameters substituted).
    f_fix : sympy Matrix
        The drift ``(G - P) u`` of the fixed inputs.
    r : float
        The damping injection gain.

    Raises
    ------
    InputDataError
        For unknown states, shaping the matching forbids, or a construction that does not apply.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen.idapbc.leaf import Leaf
    >>> from codegen.idapbc.model import Numeric
    >>> from codegen.idapbc.target import assign, resolve_targets
    >>> from systems.examples import mass_spring_damper
    >>> msd = mass_spring_damper()
    >>> num = Numeric(msd, {})
    >>> leaf = Leaf(num.struct_function, num.scale, np.zeros(2))
    >>> asg = assign(num, leaf, resolve_targets(msd, {"position": 0.5}), [0], np.zeros(1), np.zeros(2))
    >>> st, g, f_fix, r = desired_structure(msd, num, asg, [0], np.zeros(1), stiffness={"k.l": 6.0}, damping=2.0)
    >>> st.kind, st.coefficients["(k.l - *)^2/2"], r
    ('ansatz', 6.0, 2.0)
    """
    r = damping
    stiffness = dict(stiffness or {})
    n = num.n
    vals = {q.symbol: sp.Float(v) for q, v in zip(system.params, num.p)}
    x = system.x
    JR = (system.J - system.R).xreplace(vals)
    Gm = (system.G - system.P).xreplace(vals)
    if damping_state is not None:  # added dissipation on one row at x*: r g_i(x*)^2 = value
        if damping_state not in system.state_names:
            raise InputDataError(f"damping: system {system.name!r} has no state {damping_state!r}")
        i = system.state_names.index(damping_state)
        gi = np.asarray(_numeric_matrix(Gm, x, asg.x), dtype=float)[i, ctrl]
        if not np.any(gi):
            raise InputDataError(f"damping on {damping_state!r}: the controlled inputs do not act on its row")
        r = r / float(gi @ gi)
    g = Gm.extract(list(range(n)), ctrl)
    fixed = [j for j in range(len(system.inputs)) if j not in ctrl]
    f_fix = (Gm.extract(list(range(n)), fixed) * sp.Matrix([sp.Float(u_base[j]) for j in fixed])) if fixed \
        else sp.zeros(n, 1)
    for nm in stiffness:
        if nm not in system.state_names:
            raise InputDataError(f"stiffness: system {system.name!r} has no state {nm!r}")
    Ja = sp.zeros(n, n) if J_a is None else sp.Matrix(J_a).xreplace(vals)
    Ra = sp.zeros(n, n) if R_a is None else sp.Matrix(R_a).xreplace(vals)
    if Ja.shape != (n, n) or Ra.shape != (n, n):
        raise InputDataError(f"J_a and R_a must be {n} x {n} matrices")
    H = sp.Add(*[t.expr for t in system.energy_terms]).xreplace(vals)
    kind = structure
    why = ""
    if structure in ("auto", "electromechanical"):
        ok, why = electromechanical_applies(JR, g, H, x)
        if structure == "electromechanical" and not ok:
            raise InputDataError(f"the electromechanical construction does not apply to {system.name!r}: {why}")
        if H_a is not None or J_a is not None or R_a is not None:
            ok = False
            why = "an explicit H_a, J_a or R_a was given"
        kind = "electromechanical" if ok else "ansatz"
    if kind == "electromechanical":
        unmatched = _check_matched_stiffness(g, JR, stiffness, system, x, asg.x, num.scale)
        if unmatched:
            raise InputDataError(unmatched)
        st = electromechanical(JR, g, f_fix, H, x, asg.x, list(asg.u[ctrl]), stiffness, system.state_names)
    else:
        _check_ansatz_size(system, H_a, unknowns, why if structure == "auto" else "")
        Jd = system.J.xreplace(vals) + Ja
        Rd = system.R.xreplace(vals) + Ra
        Mx = _numeric_matrix(Jd - Rd - r * g * g.T, x, asg.x)
        P = _kernel_complement(Mx, num.scale)
        basis = labels = None
        if H_a is None:
            basis, labels = quadratic_basis(x, asg.x, system.state_names)
        user = None
        if H_a is not None:
            user = sp.sympify(H_a).xreplace(vals)
            if unknowns is None:  # the symbols that are neither states nor parameters
                unknowns = sorted(user.free_symbols - set(x), key=str)
        st = ansatz(Jd, Rd, Ja, Ra, g, f_fix, H, x, asg.x, num.scale, system.state_names, basis=basis, labels=labels,
                    user_Ha=user, unknowns=unknowns, stiffness=stiffness, kernel=P,
                    grad_H_star=np.asarray(num.fn.grad_hamiltonian(asg.x, np.zeros(num.m), num.p), dtype=float).reshape(n))
        if why and structure == "auto":
            st.notes.insert(0, f"ansatz (electromechanical construction not applicable: {why})")
    if r:
        st.R_a = st.R_a + r * g * g.T
        st.notes.append(f"damping injection R_a += r g g^T with r = {r:g}")
    return st, g, f_fix, r
