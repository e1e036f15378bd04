"""The structural tests: interconnection (J, N skew), dissipation (D ⪰ 0 symbolically and over the box) and
feedthrough (N skew, S ⪰ 0, P in the range of S)."""

from __future__ import annotations

import numpy as np
import sympy as sp

from codegen.passivity._box import EIGENVALUE_TOL, _Box, _min_eig, _point, _reference, _Scale, _scaled, _valid
from codegen.passivity._model import _Model
from codegen.passivity._result import PassivityTest
from codegen.passivity._search import _closure, _minimise
from phs._budget import is_zero


def _interconnection(system, checks) -> PassivityTest:
    item = checks["J skew-symmetric"]
    nskew = all(is_zero(e) is not False for e in (system.N + system.N.T))  # None: sampled by the constructor
    verdict = "pass" if item.verdict == "pass" and nskew else "fail"
    return PassivityTest("interconnection", verdict, "symbolic",
                         "J(x) + J(x)^T and N + N^T simplify to zero: the interconnection is power-preserving"
                         if verdict == "pass" else f"{item.detail}; N skew: {nskew}")


# -- symbolic part ------------------------------------------------------------------------------------
def _sign_violations(system, box: _Box) -> list[str]:
    """Parameters declared positive whose value (or box lower bound) is not: the symbolic proofs do not apply."""
    out = []
    for k, q in enumerate(system.params):
        if not q.positive:
            continue
        v = box.p[k]
        if k in box.pindex:
            v = box.lo[len(system.states) + box.pindex.index(k)]
        if not v > 0:
            out.append(f"{q.name} = {v:g}")
    return out


def _symbolic_dissipation(system, checks, violations):
    """(True/False/None, how): D ⪰ 0 proved symbolically (principal minors of its blocks, or of each resistive
    element's form when they sum to D), refuted, or undecided."""
    from phs.checks import _symbolic_psd_why

    if violations:
        return None, f"symbolic proof not applicable: declared positive but {', '.join(violations)}"
    item = checks["R positive semidefinite"]
    if item.method == "symbolic":
        return (item.verdict == "pass"), "principal minors of every block are nonnegative for positive parameters"
    if not system.dissipators:
        return None, "undecided symbolically (blocks too large for principal minors)"
    D = system.dissipation_matrix
    total = sp.zeros(*D.shape)
    forms = []
    for label, entries in system.dissipators:
        idx = sorted({i for ij in entries for i in ij})
        M = sp.zeros(len(idx), len(idx))
        for (i, j), v in entries.items():
            a, b = idx.index(i), idx.index(j)
            M[a, b] = M[b, a] = v
            total[i, j] += v
            if i != j:
                total[j, i] += v
        forms.append((label, M))
    if any(is_zero(e) is not True for e in (total - D)):
        return None, "undecided symbolically (the resistive elements' forms do not sum to D, or are over the budget)"
    for label, M in forms:
        verdict, why = _symbolic_psd_why(M)
        if verdict is not True:
            return None, f"undecided symbolically (the form of {label!r} is not provably PSD{': ' + why if why else ''})"
    return True, f"D is the sum of {len(forms)} resistive elements' forms, each with nonnegative principal minors"


# -- over the box --------------------------------------------------------------------------------------
def _eig_search(model: _Model, box: _Box, V, Dk, valid, starts, seed, scale: _Scale, deps):
    """Smallest scaled eigenvalue over the sample and from ``nlpsol`` starts: (value, point, direction, sample
    values, optimised end points, runs, converged)."""
    lam, vec = _min_eig(Dk, scale)
    lam = np.where(valid, lam, np.nan)
    ends, ok, runs = _minimise(model, box, "eig", V, lam, starts, seed, deps, scale, vec)
    allV, allL, allW = V, lam, vec
    if len(ends):
        Xe, Pe = box.points(ends, model.nx)
        le, ve = _min_eig(model.D(Xe, Pe), scale)
        le = np.where(_valid(model, box, Xe, Pe), le, np.nan)
        allV, allL, allW = np.concatenate([V, ends]), np.concatenate([lam, le]), np.concatenate([vec, ve])
    if not np.any(np.isfinite(allL)):
        return float("nan"), None, None, lam, ends, runs, ok
    k = int(np.nanargmin(allL))
    return float(allL[k]), allV[k], allW[k], lam, ends, runs, ok


def _dissipation(model: _Model, box: _Box, V, X, P, valid, starts, seed, symbolic, p_own):
    """The dissipation and feedthrough tests and the margin (scaled at the system's own parameter values ``p_own``)."""
    system = model.system
    sym, how = symbolic
    if not model.support:
        t = PassivityTest("dissipation", "pass", "symbolic", "lossless: R = P = S = 0", {"margin": 0.0})
        return t, _feedthrough(model, box, None, None, None), 0.0
    sD, sR = _reference(model, box, p_own)
    Dk = model.D(X, P)
    lamD, worstD, wD, lam, ends, runs, ok = _eig_search(model, box, V, Dk, valid, starts, seed, sD, model.D_deps)
    if worstD is None:
        t = PassivityTest("dissipation", "undecided", "sampled", f"D is not finite at any valid point of the box (floating point); {how}",
                          {"samples": int(len(V)), "valid_samples": int(np.sum(valid))})
        return t, _feedthrough(model, box, None, None, None), float("nan")
    negative = lamD < -EIGENVALUE_TOL or sym is False
    margin, worst, w, scale = lamD, worstD, wD, sD
    if not negative:
        margin = 0.0  # no dissipative state direction: all dissipation is at the ports
        if sR.Q.shape[1]:
            mR, pR, wR, *_ = _eig_search(model, box, V, Dk, valid, starts, seed, sR, model.R_deps)
            if pR is not None:
                margin, worst, w, scale = mR, pR, wR, sR
    Xw, Pw = box.points(worst[None, :], model.nx)
    Dw = model.D(Xw, Pw)[0]
    q = scale.Q @ w                             # direction in scaled support coordinates
    vz = np.zeros(model.nx + model.nu)
    vz[model.support] = q / np.sqrt(scale.d)    # the same direction in z = [dH/dx; u]
    shares = _shares(model, Xw, Pw, vz)
    coords = [model.znames[model.support[i]] for i in np.argsort(-np.abs(q)) if abs(q[i]) >= 0.3 * np.max(np.abs(q))]
    constant = not _closure(model, box, *model.D_deps)[0]
    numbers = {"margin": margin, "full_form_min_eigenvalue": lamD, "full_form_point": _point(box, worstD),
               "min_eigenvalue_unscaled": float(np.linalg.eigvalsh(Dw)[0]),
               "samples": int(len(V)), "valid_samples": int(np.sum(valid)), "sample_minimum": float(np.nanmin(lam)),
               "nlp_starts": runs, "nlp_converged": ok, "structural_null_directions": sD.null,
               "direction": coords, "shares": shares, "unattributed_share": float(float(w @ _scaled(Dw[None], scale)[0] @ w)
                                                                                 - sum(shares.values())),
               "symbolic": {True: "proved", False: "refuted", None: "undecided"}[sym]}
    method = f"{how}; " + (f"D is constant over the box ({len(V)} valid sample points)" if constant else
                           f"sampled {len(V)} valid points of the box and minimised with nlpsol (IPOPT) from {runs} starts")
    series = {"lambda": lam, "V": V, "names": box.names, "ends": ends}
    if negative:
        neg = {k: v for k, v in shares.items() if v < 0}
        element = ", ".join(sorted(neg, key=neg.get)) if neg else "R as given (no resistive element declared for it)"
        bad = _sign_violations(system, box)
        if bad:
            element += f" (declared positive but {', '.join(bad)})"
        summary = (f"[[R, P], [P^T, S]] has a negative eigenvalue: {lamD:.4g} (scaled; unscaled "
                   f"{numbers['min_eigenvalue_unscaled']:.4g}) in the direction of {', '.join(coords)}")
        test = PassivityTest("dissipation", "fail", method, summary, numbers, _point(box, worst), element, series)
    else:
        r_constant = scale is sR and not _closure(model, box, *model.R_deps)[0]
        summary = ("[[R, P], [P^T, S]] ⪰ 0 over the box" + (" (proved symbolically)" if sym else "")
                   + f" (smallest scaled eigenvalue {lamD:.3g}); margin {margin:.4g}: weakest dissipation of R in the "
                   f"direction of {', '.join(coords)}" + (" (R is constant over the box)" if r_constant else ""))
        test = PassivityTest("dissipation", "pass", method, summary, numbers, {} if r_constant else _point(box, worst), "",
                             series)
    return test, _feedthrough(model, box, Dk, valid, sD), margin


def _shares(model: _Model, X, P, vz) -> dict[str, float]:
    """Each resistive element's share ``v^T D_k v`` of the quadratic form in the direction ``vz``."""
    system = model.system
    if not system.dissipators:
        return {}
    vals = np.asarray(model.fdiss(X[0], P[0]), dtype=float).reshape(-1)
    out = {label: 0.0 for label, _ in system.dissipators}
    for (k, i, j), v in zip(model.diss_entries, vals):
        out[system.dissipators[k][0]] += (1.0 if i == j else 2.0) * v * vz[i] * vz[j]
    return out


def _feedthrough(model: _Model, box: _Box, Dk, valid, scale) -> PassivityTest:
    system = model.system
    nx = model.nx
    zero = all(M.is_zero_matrix for M in (system.P, system.S, system.N))
    if zero:
        return PassivityTest("feedthrough", "pass", "symbolic", "no feedthrough (P = S = N = 0): the full-form "
                             "condition reduces to R ⪰ 0", {})
    nskew = all(is_zero(e) is not False for e in (system.N + system.N.T))
    numbers: dict = {"N_skew": bool(nskew)}
    s_idx = [a for a, i in enumerate(model.support) if i >= nx]
    r_idx = [a for a, i in enumerate(model.support) if i < nx]
    s_min = range_res = float("nan")
    if Dk is not None and s_idx:
        w = 1 / np.sqrt(scale.d)
        M = (Dk * np.outer(w, w))[valid]
        M = M[np.all(np.isfinite(M), axis=(1, 2))]
        if len(M):
            Sb = M[:, s_idx][:, :, s_idx]
            s_min = float(np.min(np.linalg.eigvalsh(Sb)[:, 0]))
            if r_idx:
                Pb = M[:, r_idx][:, :, s_idx]
                proj = np.eye(len(s_idx)) - Sb @ np.linalg.pinv(Sb, rcond=1e-10, hermitian=True)
                range_res = float(np.max(np.abs(Pb @ proj)))
    elif not s_idx and any(system.P):
        range_res = float("inf")  # P != 0 with S = 0: [[R, P], [P^T, 0]] is indefinite wherever P is nonzero
    numbers.update({"S_min_scaled_eigenvalue": s_min, "P_range_residual": range_res})
    fails = []
    if not nskew:
        fails.append("N is not skew-symmetric")
    if s_min < -EIGENVALUE_TOL:
        fails.append(f"S has a negative eigenvalue ({s_min:.4g}, scaled)")
    if range_res > 1e-6:
        fails.append(f"P is not in the range of S (residual {range_res:.3g}): [[R, P], [P^T, S]] cannot be PSD")
    if fails:
        return PassivityTest("feedthrough", "fail", "symbolic (N) and sampled (S, P)", "; ".join(fails), numbers,
                             element="feedthrough of " + ", ".join(system.input_names))
    if np.isnan(s_min):
        return PassivityTest("feedthrough", "undecided", "sampled", "S could not be evaluated at a valid point", numbers)
    return PassivityTest("feedthrough", "pass", "symbolic (N) and sampled (S, P)",
                         f"N skew-symmetric, S ⪰ 0 (smallest scaled eigenvalue {s_min:.4g}), P in the range of S "
                         f"(residual {range_res:.2g}); the Schur-complement condition is the dissipation test's", numbers)
