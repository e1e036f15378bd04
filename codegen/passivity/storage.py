"""The storage test: H bounded below on the box, with its minimum and argmin."""

from __future__ import annotations

import numpy as np

from codegen.passivity._box import _Box, _point, _valid
from codegen.passivity._model import _Model
from codegen.passivity._result import PassivityTest
from codegen.passivity._search import _minimise
from phs.storage_bound import follow_outward


def _outward(model: _Model, box: _Box, argmin: np.ndarray, hmin: float):
    """:func:`phs.storage_bound.follow_outward` in the state coordinates, the parameters at the argmin's."""
    nx = model.nx

    def evaluate(Z):
        Vz = np.repeat(argmin[None, :], len(Z), axis=0)
        Vz[:, :nx] = Z
        Xz, Pz = box.points(Vz, nx)
        with np.errstate(all="ignore"):
            h = np.where(_valid(model, box, Xz, Pz), model.H(Xz, Pz), np.nan)
        return np.where(np.isfinite(h), h, np.nan)

    on_face, beyond, h_far, x_far = follow_outward(evaluate, argmin[:nx], hmin, box.lo[:nx], box.hi[:nx])
    return on_face, beyond, h_far, np.concatenate([x_far, argmin[nx:]])


def _storage(model: _Model, box: _Box, V, X, P, valid, starts, seed, checks) -> PassivityTest:
    """H bounded below on the box: its minimum over the sample and from ``nlpsol`` starts, with the argmin."""
    system = model.system
    Hs = np.where(valid, model.H(X, P), np.nan)
    units = checks["units"]
    note = "" if units.verdict == "pass" else f"; units: {units.detail}"
    broken = np.flatnonzero(valid & ((Hs == -np.inf) | np.isnan(Hs)))
    finite = np.isfinite(Hs)
    numbers = {"samples": int(len(V)), "valid_samples": int(np.sum(valid))}
    if len(broken) or not np.any(finite):
        at = V[broken[0]] if len(broken) else V[0]
        Xw, Pw = box.points(at[None, :], model.nx)
        terms = model.batch(model.generated.energy_terms, Xw, np.zeros((1, model.nu)), Pw)[0].reshape(-1)
        culprits = [t.label for t, v in zip(system.energy_terms, terms) if not np.isfinite(v) or v == -np.inf]
        return PassivityTest("storage", "fail", f"sampled {len(V)} valid points of the box",
                             f"H is not finite (or -inf) at {len(broken)} valid point(s) of the box{note}", numbers,
                             _point(box, at), "energy term(s) " + ", ".join(culprits or [t.label for t in system.energy_terms]))
    ref = float(np.min(Hs[finite]))
    # objective scale: the spread of the lower quarter of the sample (a stiff wall's energy elsewhere in the box,
    # 2e4 J for the MSD HASEL, would otherwise flatten the objective below IPOPT's tolerance)
    spread = float(np.quantile(Hs[finite] - ref, 0.25))
    hscale = spread if spread > 0 else max(float(np.max(Hs[finite]) - ref), abs(ref), 1e-300)
    ends, ok, runs = _minimise(model, box, "H", V, Hs, starts, seed, model.H_deps, ref=(ref, hscale))
    allV, allH = V[finite], Hs[finite]
    if len(ends):
        Xe, Pe = box.points(ends, model.nx)
        He = np.where(_valid(model, box, Xe, Pe), model.H(Xe, Pe), np.nan)
        keep = np.isfinite(He)
        allV, allH = np.concatenate([allV, ends[keep]]), np.concatenate([allH, He[keep]])
    k = int(np.argmin(allH))
    hmin, argmin = float(allH[k]), allV[k]
    width = box.hi - box.lo
    on_edge = [n for n, v, a, b, w in zip(box.names, argmin, box.lo, box.hi, width) if w > 0 and min(v - a, b - v) <= 1e-6 * w]
    Xw, Pw = box.points(argmin[None, :], model.nx)
    terms = model.batch(model.generated.energy_terms, Xw, np.zeros((1, model.nu)), Pw)[0].reshape(-1)
    numbers.update({"H_min": hmin, "H_max_sampled": float(np.max(Hs[finite])), "nlp_starts": runs, "nlp_converged": ok,
                    "argmin_on_boundary": on_edge,
                    "energy_terms_at_argmin": {t.label: float(v) for t, v in zip(system.energy_terms, terms)}})
    method = f"sampled {len(V)} valid points of the box and minimised with nlpsol (IPOPT) from {runs} starts"
    on_face, beyond, h_far, x_far = _outward(model, box, argmin, hmin)
    numbers["H_far"] = h_far
    if on_face or beyond:
        far = ", ".join(f"{n} = {v:.4g}" for n, v, a in zip(box.names, x_far, argmin) if v != a)
        why = (f"H is unbounded below: its minimum {hmin:.6g} J on the box lies on the box's face and H keeps falling "
               f"outward ({h_far:.6g} J at {far})" if on_face else
               f"bounded on the stated box only: minimum {hmin:.6g} J inside it, but H is unbounded below outside it "
               f"({h_far:.6g} J at {far})")
        return PassivityTest("storage", "fail" if on_face else "undecided", method + ", followed outward", why + note,
                             numbers, _point(box, argmin), "energy term(s) " + ", ".join(t.label for t in system.energy_terms),
                             {"H": Hs, "V": V, "names": box.names, "ends": ends})
    edge = (f"; the minimum lies on the box boundary in {', '.join(on_edge)}, where H levels off or the model ends"
            if on_edge else "")
    return PassivityTest("storage", "pass", method,
                         f"H ≥ H_min = {hmin:.6g} J on the box, so H − H_min is a nonnegative storage function{edge}{note}",
                         numbers, _point(box, argmin), "", {"H": Hs, "V": V, "names": box.names, "ends": ends})
