"""Matching equations of IDA-PBC and the two ways they are solved.

Plant ``x' = (J - R) dH/dx + f_fix + g u``; target ``x' = (J_d - R_d) dH_d/dx`` with
``J_d = J + J_a``, ``R_d = R + R_a``, ``H_d = H + H_a``.  The target is reachable by
``u = g^+ [(J_d - R_d) dH_d/dx - (J - R) dH/dx - f_fix]`` exactly when the matching
equations ``g_perp [(J_d - R_d) dH_d/dx - (J - R) dH/dx - f_fix] = 0`` hold.

``ansatz`` (the default for mechanical inputs)
    ``H_a = sum_k c_k phi_k(x)`` over a basis (linear and quadratic monomials of
    the deviations from the assigned equilibrium, or the user's expression with
    free coefficients), ``J_a``, ``R_a`` given.  The matching equations are linear
    in ``c``: equated monomial by monomial when they are polynomial in the states
    (exact), otherwise at collocation points (least squares, residual reported).
    Then ``dH_d/dx(x*)`` is put in the kernel of ``J_d - R_d`` (the assigned
    equilibrium is a critical point, up to conserved quantities) and requested
    stiffnesses fix quadratic coefficients; what is left is set to zero.

``electromechanical`` (inputs acting only on storages with quadratic energy, e.g. charges)
    With ``A`` the actuated storages (rows where ``g != 0``) and ``M`` the others, and
    ``(J - R)`` block-diagonal in ``(M, A)``: the constant input ``u*`` holds the
    actuated efforts at ``lambda(x_M) = -(J - R)_AA^-1 (g_A(x_M) u* + f_fix,A)`` for
    every configuration; ``H_a = -lambda(x_M)^T x_A + Phi(x_M)`` makes that the
    target's electrical rest manifold.  Where ``lambda`` depends on the
    configuration (the curling HASEL's input map ``gamma1 cos(gamma2 theta)``), the
    mechanical rows are matched by a momentum-charge coupling in ``J_d`` and ``R_d``,
    ``(J_a - R_a)_MA = L = (J - R)_MM (d lambda / d x_M)^T E^-1`` (E the actuated
    storages' stiffness), which leaves the actuated rows untouched, and ``Phi``
    solves ``(J - R)_MM (grad Phi - v) = 0`` with
    ``v = (d lambda / d x_M)^T E^-1 (lambda - h)``.  That equation is reduced to
    scalar first-order PDEs along the conserved quantities and handed to sympy's
    ``pdsolve`` when small; otherwise ``Phi`` is left implicit: only ``v`` enters the
    closed loop (``Phi`` never enters the control law), and ``Phi`` itself is
    integrated along the leaf when ``H_d`` is evaluated.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from phs.errors import InputDataError

PDE_SIZE_LIMIT = 120
"""Largest PDE (sympy operation count) handed to ``pdsolve``.  Only linear PDEs with constant coefficients are
handed over, with a time limit (:data:`PDE_SECONDS`); the others are integrated numerically along the leaf
(sympy's characteristic method on the curling HASEL's geometry does not finish in reasonable time)."""

ANSATZ_UNKNOWNS = 152
"""Largest number of unknown coefficients of ``H_a`` in the ansatz: the quadratic basis of n states has
n (n + 3) / 2, so 16 states (152).  Each unknown needs its gradient and a column of the matching equations
(sympy, n entries), and the collocation evaluates the n x K matrix at 4 K points: about 4 K**2 n entry
evaluations.  The six-actuator platform (12 states, 90 unknowns) designs in about 5 s; 16 states cost about 4
times that; the 8384 unknowns of a 128-state rod would take days.  Larger designs are refused in one line before
any symbolic work (:func:`codegen.idapbc.shaping.desired_structure`)."""

PDE_SECONDS = 10.0
"""Time allowed to ``pdsolve`` and the verification of its solution: seconds of this process's own CPU time
(enforced in the main thread), so that what the design solves how does not depend on the machine's load."""


class _Timeout(Exception):
    pass


def _limited(fn, seconds: float):
    """``fn()`` with a limit on the process's user CPU time (SIGVTALRM in the main thread; elsewhere without a
    limit): sympy's work is pure Python, which the virtual timer counts while other processes' load does not."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        return fn()

    def handler(signum, frame):
        raise _Timeout()

    old = signal.signal(signal.SIGVTALRM, handler)
    signal.setitimer(signal.ITIMER_VIRTUAL, seconds)
    try:
        return fn()
    finally:
        signal.setitimer(signal.ITIMER_VIRTUAL, 0)
        signal.signal(signal.SIGVTALRM, old)


@dataclass
class Structure:
    """The solved design: added energy, added interconnection/dissipation and what was solved how."""

    kind: str
    H_a: sp.Expr
    J_a: sp.Matrix
    R_a: sp.Matrix
    v: sp.Matrix | None = None
    notes: list = field(default_factory=list)
    unsolved: list = field(default_factory=list)
    pdes: list = field(default_factory=list)
    symbolic: bool = False
    coupling: list = field(default_factory=list)
    coefficients: dict = field(default_factory=dict)


def _inv(M: sp.Matrix) -> sp.Matrix:
    """Inverse, entry by entry for a diagonal matrix (sympy's general inverse is slow on large entries)."""
    if M.is_diagonal():
        return sp.diag(*[1 / M[i, i] for i in range(M.rows)])
    return M.inv()


def _zero(e) -> bool:
    if e == 0:
        return True
    e = sp.sympify(e)
    if e.is_number:
        return abs(complex(e)) == 0
    return False


def actuated_split(g: sp.Matrix) -> tuple[list[int], list[int]]:
    """Rows reached by the controlled inputs (A) and the others (M)."""
    A = [i for i in range(g.rows) if any(not _zero(g[i, j]) for j in range(g.cols))]
    return A, [i for i in range(g.rows) if i not in A]


def electromechanical_applies(JR: sp.Matrix, g: sp.Matrix, H: sp.Expr, x: list) -> tuple[bool, str]:
    """Whether the electromechanical construction applies, and if not, why (one sentence)."""
    A, M = actuated_split(g)
    if not A or not M:
        return False, "every state is actuated" if not M else "no state is actuated"
    for i in M:
        for j in A:
            if not (_zero(JR[i, j]) and _zero(JR[j, i])):
                return False, "J - R couples the actuated and the other states directly"
    xa = [x[i] for i in A]
    for a in xa:
        d = sp.diff(H, a)
        for b in xa:
            if set(sp.diff(d, b).free_symbols) & set(xa):
                return False, "H is not quadratic in the actuated states"
    return True, ""


def electromechanical(JR, g, f_fix, H, x, x_star, u_star_c, stiffness: dict, names: list[str]) -> Structure:
    """The construction of the module docstring (numeric parameter values already substituted)."""
    n = len(x)
    A, M = actuated_split(g)
    xa, xm = [x[i] for i in A], [x[i] for i in M]
    for i in M:
        if not _zero(f_fix[i]):
            raise InputDataError(f"the fixed inputs act on the unactuated state {names[i]!r}: the electromechanical "
                                 "construction needs them on the actuated storages only (give structure='ansatz')")
    dHa = sp.Matrix([sp.diff(H, a) for a in xa])
    E = dHa.jacobian(xa)
    h = dHa.xreplace({a: 0 for a in xa})
    JRAA, JRMM = JR.extract(A, A), JR.extract(M, M)
    gA = g.extract(A, list(range(g.cols)))
    inv = _inv(JRAA)
    lam = -inv * (gA * sp.Matrix(u_star_c) + f_fix.extract(A, [0]))
    K = sp.zeros(len(A), len(A))
    for name, k in stiffness.items():
        K[A.index(names.index(name)), A.index(names.index(name))] = sp.Float(k)
    Et = E + K
    xa_star = sp.Matrix([sp.Float(x_star[i]) for i in A])
    dlam = lam.jacobian(xm)
    notes = [f"actuated storages: {', '.join(names[i] for i in A)}; lambda(x_M) = -(J - R)_AA^-1 (g_A u* + f_fix,A) "
             "holds them where the constant input u* would"]
    L = sp.zeros(len(M), len(A))
    coupling = []
    if any(not _zero(e) for e in dlam):
        L = JRMM * dlam.T * _inv(Et)
        for (a, i), (b, j) in itertools.product(enumerate(M), enumerate(A)):
            if not _zero(L[a, b]):
                coupling.append((names[i], names[j]))
        notes.append("lambda depends on the configuration: momentum-charge coupling in J_d and R_d, "
                     f"(J_a - R_a)_MA = (J - R)_MM (dlambda/dx_M)^T E^-1 on {len(coupling)} pair(s) "
                     f"({', '.join(f'{p}-{q}' for p, q in coupling[:4])}{', ...' if len(coupling) > 4 else ''})")
    vM = dlam.T * _inv(Et) * (lam - h + K * xa_star)
    J_a, R_a = sp.zeros(n, n), sp.zeros(n, n)
    for (a, i), (b, j) in itertools.product(enumerate(M), enumerate(A)):
        if not _zero(L[a, b]):
            J_a[i, j], J_a[j, i] = L[a, b] / 2, -L[a, b] / 2
            R_a[i, j] = R_a[j, i] = -L[a, b] / 2
    dxa = sp.Matrix(xa) - xa_star
    H_a = -(lam.T * sp.Matrix(xa))[0, 0] + (dxa.T * K * dxa)[0, 0] / 2
    st = Structure("electromechanical", H_a, J_a, R_a, notes=notes, coupling=coupling)
    if all(_zero(e) for e in vM):
        st.notes.append("Phi = 0 (lambda is constant)")
        st.symbolic = True
        return st
    phi, pdes, implicit = potential(JRMM, vM, xm, [names[i] for i in M], x_star=[x_star[i] for i in M])
    st.pdes = pdes
    if implicit:
        v = sp.zeros(n, 1)
        for a, i in enumerate(M):
            v[i] = vM[a]
        st.v = v
        st.notes.append("Phi has no closed form here: it enters the closed loop only through v = (dlambda/dx_M)^T "
                        "E^-1 (lambda - h) and is integrated along the leaf when H_d is evaluated")
    else:
        st.H_a = st.H_a + phi
        st.symbolic = True
        st.notes.append("Phi solved in closed form")
    return st


def potential(JRMM: sp.Matrix, v: sp.Matrix, xm: list, names: list[str], x_star) -> tuple[sp.Expr, list[dict], bool]:
    """Solve ``(J - R)_MM (grad Phi - v) = 0`` for Phi(x_M): scalar first-order PDEs along the conserved
    quantities, each given to ``pdsolve`` when small.  Returns ``(Phi, pdes, implicit)``."""
    rows = [i for i in range(JRMM.rows) if any(not _zero(e) for e in JRMM.row(i))]
    free_vars = set(range(len(xm)))
    # rows touching a single variable fix Phi's dependence on it: d Phi/dx_j = v_j
    for i in rows:
        cols = [j for j in range(len(xm)) if not _zero(JRMM[i, j])]
        if len(cols) == 1 and _zero(v[cols[0]]):
            free_vars.discard(cols[0])  # Phi does not depend on x_j (a momentum)
    indep = set(range(len(xm))) - free_vars
    eqs = []
    for i in rows:
        cols = [j for j in range(len(xm)) if not _zero(JRMM[i, j]) and j in free_vars]
        if cols:
            eqs.append((i, cols))
    # group variables coupled by an equation
    groups: list[set] = []
    for _, cols in eqs:
        hit = [gq for gq in groups if gq & set(cols)]
        merged = set(cols).union(*hit) if hit else set(cols)
        groups = [gq for gq in groups if gq not in hit] + [merged]
    pdes, phi, implicit = [], sp.Integer(0), False
    for grp in groups:
        cols = sorted(grp)
        grp_rows = [i for i, c in eqs if set(c) <= grp]
        Msub = JRMM.extract(grp_rows, cols)
        # numeric rank at a point near the equilibrium decides whether it is one scalar PDE
        pt = {xm[j]: sp.Float(x_star[j]) for j in range(len(xm))}
        try:
            Mn = np.array(Msub.xreplace(pt).evalf(), dtype=float)
            rank = np.linalg.matrix_rank(Mn, tol=1e-10 * max(1.0, np.abs(Mn).max()))
        except (TypeError, ValueError):
            rank = -1
        desc = {"variables": [names[j] for j in cols]}
        if rank != 1:
            desc.update(method="leaf quadrature", reason=f"{len(grp_rows)} coupled equations of rank {rank}")
            pdes.append(desc)
            implicit = True
            continue
        row = grp_rows[int(np.argmax(np.abs(Mn).sum(axis=1)))]
        coeff = [JRMM[row, j] for j in cols]
        rhs = sum((c * v[j] for c, j in zip(coeff, cols)), sp.Integer(0))
        F = sp.Function("Phi")(*[xm[j] for j in cols])
        eq = sp.Add(*[c * sp.diff(F, xm[j]) for c, j in zip(coeff, cols)]) - rhs
        desc["equation"] = " + ".join(f"({sp.sstr(c)}) dPhi/d{names[j]}" for c, j in zip(coeff, cols)) + " = rhs"
        size = sp.count_ops(eq)
        constant = all(sp.sympify(c).is_number for c in coeff)
        sol = None
        if size <= PDE_SIZE_LIMIT and constant:
            def attempt(eq=eq, F=F, rhs=rhs, cols=cols):
                res = sp.pdsolve(eq, F)
                cand = res.rhs
                # drop the arbitrary function of the characteristic variable (a conserved quantity: any will do)
                arb = [f for f in cand.atoms(sp.Function) if f.func != F.func
                       and isinstance(f, sp.core.function.AppliedUndef)]
                cand = cand.xreplace({f: 0 for f in arb})
                return cand, _verify(eq.subs(F, cand).doit(), rhs, [xm[j] for j in cols],
                                     [x_star[j] for j in cols])

            try:
                cand, check = _limited(attempt, PDE_SECONDS)
                if check:
                    sol = cand
                    desc.update(method="sympy pdsolve", solution=sp.sstr(cand))
                else:
                    desc.update(method="leaf quadrature", reason="pdsolve's solution did not verify")
            except _Timeout:
                desc.update(method="leaf quadrature", reason=f"pdsolve did not finish in {PDE_SECONDS:g} s")
            except (NotImplementedError, ValueError, TypeError, AttributeError) as exc:
                desc.update(method="leaf quadrature", reason=f"pdsolve: {type(exc).__name__}: {str(exc)[:120]}")
        elif not constant:
            desc.update(method="leaf quadrature", reason="coefficients depend on the state (no closed-form "
                                                         "characteristics)")
        else:
            desc.update(method="leaf quadrature", reason=f"equation of {size} operations (limit {PDE_SIZE_LIMIT})")
        if sol is None:
            implicit = True
        else:
            phi += sol
        pdes.append(desc)
    if indep:
        for j in indep:
            pdes.append({"variables": [names[j]], "method": "Phi independent of it", "equation": f"dPhi/d{names[j]} = 0"})
    return phi, pdes, implicit


def _verify(residual, rhs, variables, center) -> bool:
    """The PDE residual vanishes: symbolically, or to 1e-10 of the right-hand side at points around ``center``
    (floating-point coefficients leave ``sin(2 x) - sin(2.0 x)``-like remainders that ``simplify`` keeps)."""
    if sp.simplify(residual) == 0:
        return True
    f = sp.lambdify(variables, [residual, rhs], "numpy")
    rng = np.random.default_rng(0)
    worst, ref = 0.0, 0.0
    for _ in range(8):
        pt = [c + 0.1 * (abs(c) + 1e-3) * rng.standard_normal() for c in center]
        with np.errstate(all="ignore"):
            r, b = (complex(v) for v in f(*pt))
        if not (np.isfinite(r) and np.isfinite(b)):
            continue
        worst, ref = max(worst, abs(r)), max(ref, abs(b))
    return ref > 0 and worst <= 1e-10 * ref


# -- the polynomial / user ansatz ----------------------------------------------------------------
def quadratic_basis(x, x_star, names) -> tuple[list[sp.Expr], list[tuple]]:
    """Linear and quadratic monomials of the deviations ``x - x*`` with their labels."""
    d = [xi - sp.Float(v) for xi, v in zip(x, x_star)]
    basis, labels = [], []
    for i in range(len(x)):
        basis.append(d[i])
        labels.append(("lin", i))
    for i in range(len(x)):
        basis.append(d[i] ** 2 / 2)
        labels.append(("sq", i))
    for i, j in itertools.combinations(range(len(x)), 2):
        basis.append(d[i] * d[j])
        labels.append(("cross", i, j))
    return basis, labels


def _nullspace(M: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    if M.size == 0:
        return np.eye(M.shape[1])
    if M.shape[0] >= M.shape[1]:  # the thin SVD has every right singular vector (no m x m U of a tall matrix)
        _, sv, Vt = np.linalg.svd(M, full_matrices=False)
    else:
        _, sv, Vt = np.linalg.svd(M)
    r = int(np.sum(sv > rtol * (sv[0] if sv.size else 1.0)))
    return Vt[r:].T


def ansatz(Jd, Rd_match, J_a, R_a, g, f_fix, H, x, x_star, scale, names, *, basis=None, labels=None, user_Ha=None,
           unknowns=None, stiffness=None, collocation: int = 0, seed: int = 0, kernel=None, grad_H_star=None) -> Structure:
    """Solve the linear matching equations for the coefficients of ``H_a``; see the module docstring.

    ``kernel`` holds rows (scaled coordinates) spanning the complement of the kernel of ``J_d - R_d`` at ``x*``:
    they must annihilate ``grad H_d(x*)``.  ``Rd_match`` is ``R + R_a`` without the damping injection along
    ``g`` (matched by construction); ``f_fix`` the drift of the inputs held constant, which the target must
    reproduce in the unactuated rows.  ``grad_H_star``, when given, is ``dH/dx`` at ``x*`` computed elsewhere (the
    generated functions: a symbolic derivative of a large ``H`` such as an inverse inertia form takes seconds).
    """
    n = len(x)
    A, M = actuated_split(g)
    notes, unsolved = [], []
    if user_Ha is not None:
        c_syms = list(unknowns)
        offset = user_Ha.xreplace({c: 0 for c in c_syms})
        basis = [sp.diff(user_Ha, c) for c in c_syms]
        for b in basis:
            if set(b.free_symbols) & set(c_syms):
                raise InputDataError("H_a must be linear in its unknown coefficients "
                                     f"({', '.join(map(str, c_syms))})")
        labels = [("user", str(c)) for c in c_syms]
    else:
        offset = sp.Integer(0)
    K = len(basis)
    # matching rows: the unactuated rows when the actuated block of g is square and invertible, else g_perp numerically
    square = len(A) == g.cols and (g.extract(A, list(range(g.cols))).det() != 0)
    grads = [sp.Matrix([sp.diff(b, xi) for xi in x]) for b in basis]
    off_grad = sp.Matrix([sp.diff(offset, xi) for xi in x])
    dH = None  # gradient of H is needed only when J_a or R_a is nonzero
    extra = sp.zeros(n, 1)
    if any(not _zero(e) for e in (J_a - R_a)):
        dH = sp.Matrix([sp.diff(H, xi) for xi in x])
        extra = (J_a - R_a) * dH
    Mcols = [(Jd - Rd_match) * gk for gk in grads]
    b_vec = (Jd - Rd_match) * off_grad + extra - f_fix
    symbolic = False
    if square:
        rows = M
        exprs = [[sp.expand(Mcols[k][i]) for k in range(K)] + [sp.expand(b_vec[i])] for i in rows]
        polys_ok = all(e == 0 or e.is_polynomial(*x) for row in exprs for e in row)
        if polys_ok:
            symbolic = True
            eqs_M, eqs_b = [], []
            for row in exprs:
                monos: dict = {}
                for k, e in enumerate(row):
                    if e == 0:
                        continue
                    for mono, coef in sp.Poly(e, *x).terms():
                        monos.setdefault(mono, np.zeros(K + 1))[k] += float(coef)
                for vec in monos.values():
                    eqs_M.append(vec[:K])
                    eqs_b.append(vec[K])
            Mnum = np.array(eqs_M).reshape(-1, K)
            bnum = np.array(eqs_b)
            notes.append(f"matching equations polynomial in the states: {len(bnum)} coefficient equations in {K} "
                         "unknowns (exact)")
    if not symbolic:
        rng = np.random.default_rng(seed)
        npts = collocation or max(4 * K, 40)
        f_cols = sp.lambdify([x], sp.Matrix.hstack(*Mcols), "numpy") if K else None  # one function: n x K
        f_b = sp.lambdify([x], b_vec, "numpy")
        f_g = sp.lambdify([x], g, "numpy")
        eqs_M, eqs_b = [], []
        for _ in range(npts):
            pt = np.asarray(x_star) + 0.3 * scale * rng.uniform(-1, 1, n)
            with np.errstate(all="ignore"):
                gv = np.asarray(f_g(pt), dtype=float).reshape(n, -1)
                U, sv, _ = np.linalg.svd(gv)
                perp = U[:, int(np.sum(sv > 1e-12 * max(sv[0], 1e-300))):].T
                cols = np.asarray(f_cols(pt), dtype=float).reshape(n, K) if K else np.zeros((n, 0))
                bv = np.asarray(f_b(pt), dtype=float).reshape(n)
            if not (np.all(np.isfinite(cols)) and np.all(np.isfinite(bv))):
                continue
            w = 1 / scale  # rows in units of scaled rates
            eqs_M.append(perp @ (cols * w[:, None]))
            eqs_b.append(perp @ (bv * w))
        Mnum, bnum = np.vstack(eqs_M), np.concatenate(eqs_b)
        notes.append(f"matching equations solved at {len(eqs_M)} collocation points (least squares)")
    c0 = np.linalg.lstsq(Mnum, -bnum, rcond=None)[0] if K else np.zeros(0)
    res = Mnum @ c0 + bnum if K else bnum
    size = max(np.max(np.abs(bnum)) if bnum.size else 0.0, np.max(np.abs(Mnum)) if Mnum.size else 0.0, 1e-300)
    rel = float(np.max(np.abs(res)) / size) if res.size else 0.0
    if rel > 1e-9:
        unsolved.append(f"the matching equations have no solution in this ansatz (relative residual {rel:.3g}): "
                        "enlarge the basis or change J_a / R_a")
    Z = _nullspace(Mnum, 1e-10) if K else np.zeros((0, 0))
    # equilibrium: grad H_d(x*) in the kernel of J_d - R_d (scaled coordinates)
    P = kernel  # rows spanning the complement of the kernel (scaled)
    Gs = np.column_stack([np.asarray(sp.Matrix(gk).xreplace(dict(zip(x, map(sp.Float, x_star)))).evalf(),
                                     dtype=float).reshape(n) for gk in grads]) * scale[:, None] if K else np.zeros((n, 0))
    at_star = dict(zip(x, map(sp.Float, x_star)))
    if grad_H_star is None:
        gH = np.asarray(sp.Matrix([sp.diff(H + offset, xi) for xi in x]).xreplace(at_star).evalf(), dtype=float)
    else:
        gH = np.asarray(grad_H_star, dtype=float) + np.asarray(
            sp.Matrix([sp.diff(offset, xi) for xi in x]).xreplace(at_star).evalf(), dtype=float).reshape(n)
    gH = gH.reshape(n) * scale
    c = c0.copy()
    if K and P.shape[0]:
        Aeq = P @ Gs @ Z
        beq = -(P @ (gH + Gs @ c0))
        a = np.linalg.lstsq(Aeq, beq, rcond=None)[0] if Aeq.size else np.zeros(Z.shape[1])
        r_eq = Aeq @ a - beq if Aeq.size else beq
        if np.max(np.abs(r_eq), initial=0.0) > 1e-9 * max(np.max(np.abs(gH)), 1e-300):
            unsolved.append("the ansatz cannot make the assigned equilibrium a critical point of H_d "
                            f"(residual {np.max(np.abs(r_eq)):.3g} of {np.max(np.abs(gH)):.3g}, scaled)")
        c = c0 + Z @ a
        Z = Z @ _nullspace(Aeq, 1e-10) if Aeq.size else Z
    # requested stiffnesses fix the quadratic coefficients
    stiffness = stiffness or {}
    if stiffness:
        if labels is None or user_Ha is not None:
            raise InputDataError("stiffness= applies to the default quadratic ansatz; with your own H_a put the "
                                 "curvature in it")
        rows_s, vals = [], []
        for name, kval in stiffness.items():
            i = names.index(name)
            k = labels.index(("sq", i))
            e = np.zeros(K)
            e[k] = 1.0
            rows_s.append(e)
            vals.append(float(kval))
        Es = np.array(rows_s)
        if Z.shape[1] == 0 and np.max(np.abs(Es @ c - vals)) > 1e-9 * max(1.0, np.max(np.abs(vals))):
            bad = [nm for nm, e, vv in zip(stiffness, Es, vals) if abs(e @ c - vv) > 1e-9 * max(1.0, abs(vv))]
            raise InputDataError(f"stiffness on {', '.join(map(repr, bad))} is not compatible with the matching "
                                 "equations: H_a cannot have that curvature (the input does not reach those rows)")
        if Z.shape[1]:
            b = np.linalg.lstsq(Es @ Z, np.array(vals) - Es @ c, rcond=None)[0]
            c_new = c + Z @ b
            miss = np.abs(Es @ c_new - vals)
            if np.max(miss) > 1e-9 * max(1.0, np.max(np.abs(vals))):
                bad = [nm for nm, m_ in zip(stiffness, miss) if m_ > 1e-9 * max(1.0, abs(stiffness[nm]))]
                raise InputDataError(f"stiffness on {', '.join(map(repr, bad))} is not compatible with the matching "
                                     "equations: H_a cannot have that curvature (the input does not reach those rows)")
            c = c_new
    # clean rounding: coefficients far below the others are zero
    mag = np.abs(c) * np.array([_magnitude(b, x, x_star, scale) for b in basis]) if K else np.zeros(0)
    if K and mag.max() > 0:
        c[mag < 1e-12 * mag.max()] = 0.0
    H_a = offset + sp.Add(*[sp.Float(ck) * b for ck, b in zip(c, basis) if ck != 0])
    coefficients = dict(zip([_label(lb, names) for lb in labels], map(float, c))) if labels else {}
    return Structure("ansatz", H_a, J_a, R_a, notes=notes, unsolved=unsolved, symbolic=symbolic and not unsolved,
                     coefficients=coefficients)


def _magnitude(expr, x, x_star, scale) -> float:
    """Size of a basis function at one typical deviation (used to drop rounding-level coefficients)."""
    pt = {xi: sp.Float(v + s) for xi, v, s in zip(x, x_star, scale)}
    try:
        return abs(float(expr.xreplace(pt).evalf())) or 1.0
    except (TypeError, ValueError):
        return 1.0


def _label(lb, names) -> str:
    if lb[0] == "lin":
        return f"({names[lb[1]]} - *)"
    if lb[0] == "sq":
        return f"({names[lb[1]]} - *)^2/2"
    if lb[0] == "cross":
        return f"({names[lb[1]]} - *)({names[lb[2]]} - *)"
    return lb[1]
