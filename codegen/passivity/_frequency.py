"""Frequency-response passivity indices of a linear model and their Popov-Hamiltonian verification."""

from __future__ import annotations

import numpy as np
import scipy.optimize


def _frequency_response(A, B, C, D, w) -> np.ndarray:
    n = A.shape[0]
    if n == 0:
        return np.repeat(D[None, :, :].astype(complex), len(w), axis=0)
    M = 1j * np.asarray(w)[:, None, None] * np.eye(n)[None] - A[None]
    X = np.linalg.solve(M, np.repeat(B[None].astype(complex), len(w), axis=0))
    return C[None] @ X + D[None]


def _nu_of(G) -> np.ndarray:
    He = (G + np.conj(np.swapaxes(G, -1, -2))) / 2
    return np.linalg.eigvalsh(He)[..., 0]


def _rho_of(G, floor: float = 0.0) -> np.ndarray:
    """Largest ρ with ``He G - ρ G^H G ⪰ 0`` at each frequency: ``λ_min(Σ_r^-1 V_r^H He(G) V_r Σ_r^-1)`` on the
    range of ``G^H`` (SVD ``G = U Σ V^H``, rank r); -inf where He G couples the null space of G to the rest."""
    out = np.full(G.shape[0], np.inf)
    for k, Gk in enumerate(G):
        if not np.all(np.isfinite(Gk)):
            continue
        _, sv, Vh = np.linalg.svd(Gk)
        r = int(np.sum(sv > 1e-10 * sv[0])) if sv.size and sv[0] > floor else 0
        if r == 0:  # G(jω) = 0 (to rounding): no constraint on ρ at this frequency
            continue
        He = (Gk + Gk.conj().T) / 2
        V = Vh.conj().T
        if r < len(sv):
            Vn = V[:, r:]
            if np.max(np.abs(He @ Vn)) > 1e-9 * sv[0]:
                out[k] = -np.inf
                continue
        Vr = V[:, :r] / sv[:r][None, :]
        out[k] = np.linalg.eigvalsh(Vr.conj().T @ He @ Vr)[0]
    return out


def _hamiltonian_crossings(A, B, C, D, Mq) -> tuple[np.ndarray, dict]:
    """Frequencies where the Popov function ``[G; I]^H Mq [G; I]`` is singular: imaginary eigenvalues of its
    Hamiltonian matrix (Mq on (y, u); its (u, u) block must make the value at infinity positive definite)."""
    m = B.shape[1]
    Ch = np.vstack([C, np.zeros((m, C.shape[1]))])
    Dh = np.vstack([D, np.eye(m)])
    Qx, Sx, Rx = Ch.T @ Mq @ Ch, Ch.T @ Mq @ Dh, Dh.T @ Mq @ Dh
    Rx = (Rx + Rx.T) / 2
    Ri = np.linalg.inv(Rx)
    F = A - B @ Ri @ Sx.T
    Hm = np.block([[F, -B @ Ri @ B.T], [-Qx + Sx @ Ri @ Sx.T, -F.T]])
    lam = np.linalg.eigvals(Hm)
    # on the axis: a real part within 1e-8 of the eigenvalue's own size, or within the rounding of the eigenvalue
    # problem (1e3 eps |H|); relative to its own size, a slow mode of a stiff model is not mistaken for a crossing
    floor = 1e3 * np.finfo(float).eps * max(float(np.linalg.norm(Hm, 1)), 1e-300)
    on_axis = np.abs(lam.real) <= 1e-8 * np.abs(lam) + floor
    dist = np.abs(lam.real) / np.maximum(np.abs(lam), floor)
    crossings = np.unique(np.abs(lam.imag[on_axis]))
    return crossings, {"cond_Rx": float(np.linalg.cond(Rx)), "axis_distance": float(np.min(dist)) if dist.size else 1.0}


def _index_sweep(fun, A, B, C, D, w):
    """Infimum of ``fun(G(jω))`` over the grid ``w`` (and ω = ∞, and ω = 0), refined around the lowest points."""
    vals = fun(_frequency_response(A, B, C, D, w))
    best_w, best = float(w[int(np.argmin(vals))]), float(np.min(vals))
    for i in np.argsort(vals)[:3]:
        a, b = w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)]
        if not (0 < a < b):
            continue
        r = scipy.optimize.minimize_scalar(lambda lw: float(fun(_frequency_response(A, B, C, D, np.array([np.exp(lw)])))[0]),
                                           bounds=(np.log(a), np.log(b)), method="bounded", options={"xatol": 1e-6})
        if r.fun < best:
            best, best_w = float(r.fun), float(np.exp(r.x))
    vinf = float(fun(D[None].astype(complex))[0]) if np.all(np.isfinite(D)) else np.inf
    if vinf < best:
        best, best_w = vinf, np.inf
    return best, best_w, vals
