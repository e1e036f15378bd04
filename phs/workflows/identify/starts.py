"""Starting values for an output-error fit from a linear least-squares (ARX) fit of the recording."""

from __future__ import annotations

import numpy as np

from phs.errors import InputDataError


def second_order_start(y, u, fs: float) -> dict[str, float]:
    """Mass, stiffness and damping of a mass-spring-damper from a second-order ARX fit
    ``y[n] = a1 y[n-1] + a2 y[n-2] + b1 u[n-1] + b2 u[n-2]`` of its displacement ``y`` under the force
    ``u``, sampled at ``fs`` [Hz]: the discrete pole gives ``f_n`` and ``zeta``, the static gain
    ``k = (1 - a1 - a2) / (b1 + b2)``, then ``m = k / wn²`` and ``b = 2 zeta k / wn``.  A start for
    :func:`phs.workflows.identify.identify`, not an estimate: the ARX fit is biased by noise.

    Returns
    -------
    dict
        ``m``, ``k``, ``b``, ``f_n`` [Hz] and ``zeta``.

    Raises
    ------
    InputDataError
        When the fitted poles are not an underdamped pair (no oscillation to read).

    Examples
    --------
    >>> from codegen import simulate
    >>> from systems.examples import mass_spring_damper
    >>> t = np.arange(2000) / 1000.0
    >>> u = np.sin(2 * np.pi * 3 * t) + np.sin(2 * np.pi * 11 * t)
    >>> y = simulate(mass_spring_damper(m=0.5, k=800.0, b=2.0), t, u={"F": u})["position"]
    >>> s = second_order_start(y, u, 1000.0)
    >>> round(s["f_n"], 1), round(s["k"] / 800.0, 2)       # f_n = sqrt(800 / 0.5) / 2 pi = 6.4 Hz
    (6.4, 1.0)
    """
    y, u = np.asarray(y, float), np.asarray(u, float)
    A = np.column_stack([y[1:-1], y[:-2], u[1:-1], u[:-2]])
    a1, a2, b1, b2 = np.linalg.lstsq(A, y[2:], rcond=None)[0]
    z = np.roots([1.0, -a1, -a2])[0]
    if abs(complex(z).imag) == 0 or abs(z) >= 1:
        raise InputDataError(f"second_order_start: the ARX poles {np.roots([1.0, -a1, -a2])} are not a stable oscillating pair")
    s = np.log(complex(z)) * fs
    wn, zeta = abs(s), -s.real / abs(s)
    k = (1 - a1 - a2) / (b1 + b2)
    return {"m": float(k / wn**2), "k": float(k), "b": float(2 * zeta * k / wn), "f_n": float(wn / 2 / np.pi), "zeta": float(zeta)}
