"""Drive candidates: elements between the recorded command and the model's input.

The amplifier or the actuator's drive may saturate (:class:`InputSaturation`), limit the rate of
change (:class:`SlewRateLimit`) or delay the command (:class:`TimeDelay`).  These act on the input
signal outside the port-Hamiltonian part (:class:`~components.candidates.elements.InputElement`): the
model is unchanged and each element's :meth:`transform` maps the sampled command to what the model
receives; diagnosis fits their parameters by a bounded search on the simulated output.

Examples
--------
>>> import numpy as np
>>> t = np.arange(5) * 0.1
>>> TimeDelay().transform(t, np.array([0.0, 1.0, 1.0, 1.0, 1.0]), [0.05]).tolist()
[0.0, 0.5, 1.0, 1.0, 1.0]
"""

from __future__ import annotations

import math

import numpy as np

from components.candidates.elements import InputElement


class TimeDelay(InputElement):
    """A transport delay ``u(t − tau_d)`` (linear interpolation; the input holds its first value before 0)."""

    effect = "time_delay"
    summary = "a delay between the commanded input and the response"
    component = "delay u(t − tau_d)"

    def parameters(self, t, u) -> list[tuple[str, float, float, float]]:
        T = float(t[-1] - t[0])
        dt = float(np.median(np.diff(t)))
        return [("tau_d", 5 * dt, 0.0, min(0.2 * T, 200 * dt))]

    def transform(self, t, u, theta) -> np.ndarray:
        return np.interp(t - float(theta[0]), t, u)

    def course(self, t, u, theta) -> tuple | None:
        """The command's samples ``tau_d`` later, its first value held before them (exact for any delay,
        not only whole samples: the kinks of a stepping command move between the samples).  The held first
        value takes samples a sampling step apart before the first, back to the recording's start: the
        course stays evenly sampled, as the command was, and the simulator reads it as it reads the command
        itself (a smooth stretch through the spline of its own samples, :func:`codegen._grid.local_samples`),
        so that a delay tending to zero gives the undelayed command's response.

        Examples
        --------
        >>> times, values = TimeDelay().course(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 1.0]), [0.25])
        >>> times.tolist(), values.tolist()
        ([-0.75, 0.25, 1.25, 2.25], [0.0, 0.0, 1.0, 1.0])
        """
        tau = float(theta[0])
        if not tau > 0:
            return None
        t, u = np.asarray(t, float), np.asarray(u, float)
        dt = float(t[1] - t[0]) if len(t) > 1 else tau
        held = t[0] + tau - dt * np.arange(max(1, math.ceil(tau / dt - 1e-9)), 0, -1)  # back to the recording's start
        return np.concatenate([held, t + tau]), np.concatenate([np.full(len(held), u[0]), u])

    def neutral(self, t, u) -> list[float]:
        return [0.0]


class InputSaturation(InputElement):
    """A saturation of the input, gradual or hard, possibly asymmetric: above zero
    ``u / (1 + (u / U_hi)^p)^(1/p)``, below zero the same with ``U_lo``; it tends to ``U_hi`` (``-U_lo``)
    for large inputs, and its sharpness ``p`` spans a gradual compression (``p`` near 2: a drive or an
    actuator that yields smoothly, as ``tanh`` or an algebraic sigmoid does) to a hard clip (``p = 20``:
    within 3.4 % of the limit at the corner).  Searched as the compression ``c_hi`` (``c_lo``) of the
    recorded peak ``ref_hi`` (``ref_lo``), held at that peak, and the sharpness: at a given compression of
    the peak, the sharpness changes only where below it the saturation sets in, so the two are searched
    one after the other without a valley between them (in the limits and the sharpness, a hard clip's
    limit and a gradual one's differ by twice the peak).  The limits are :meth:`limits`; a side the
    command never reaches has no compression to search.  On the concealed ``tanh`` saturation
    (``examples.concealed_effects``, seed 1, 3 s) the hard clip this law replaced explained 31-36 % of the
    mismatch (0.6 and 1 times its strength), this law 77-88 %, the ``tanh`` itself 78-89 %."""

    effect = "input_saturation"
    summary = "the input saturating at large amplitude (drive or actuator limit)"
    component = "saturation u / (1 + |u/U|^p)^(1/p) to [-U_lo, U_hi]"

    @staticmethod
    def _peaks(u) -> tuple[float, float]:
        u = np.asarray(u, float)
        return max(float(np.max(u)), 0.0), max(float(-np.min(u)), 0.0)

    def parameters(self, t, u) -> list[tuple[str, float, float, float]]:
        hi, lo = self._peaks(u)
        return [("c_hi", 0.0, 0.0, 0.8 if hi > 0 else 0.0), ("c_lo", 0.0, 0.0, 0.8 if lo > 0 else 0.0), ("p", 20.0, 1.5, 20.0),
                ("ref_hi", hi or 1.0, hi or 1.0, hi or 1.0), ("ref_lo", lo or 1.0, lo or 1.0, lo or 1.0)]

    def neutral(self, t, u) -> list[float]:
        hi, lo = self._peaks(u)
        return [0.0, 0.0, 20.0, hi or 1.0, lo or 1.0]

    @staticmethod
    def limits(theta) -> tuple[float, float]:
        """``(U_hi, U_lo)``: the levels the saturation tends to, from ``(c_hi, c_lo, p, ref_hi, ref_lo)``
        (infinite for no compression).

        Examples
        --------
        >>> InputSaturation.limits([0.1, 0.0, 20.0, 10.0, 1.0])[0] > 9.0, InputSaturation.limits([0.1, 0.0, 20.0, 10.0, 1.0])[1]
        (True, inf)
        """
        c_hi, c_lo, p, ref_hi, ref_lo = (float(v) for v in theta)

        def level(c, ref):  # (1 - c)^-p - 1 without cancellation for a small compression
            grow = math.expm1(-p * math.log1p(-c)) if c > 0 else 0.0
            return ref / grow ** (1.0 / p) if grow > 0 else math.inf

        return level(c_hi, ref_hi), level(c_lo, ref_lo)

    def derived(self, theta) -> dict:
        """The limits ``U_hi`` and ``U_lo`` (:meth:`limits`) a saturation with parameters ``theta`` tends to.

        Examples
        --------
        >>> {k: round(v, 6) for k, v in InputSaturation().derived([0.1, 0.0, 20.0, 10.0, 1.0]).items()}
        {'U_hi': 9.058521, 'U_lo': inf}
        """
        return dict(zip(("U_hi", "U_lo"), self.limits(theta), strict=True))

    def at_limits(self, t, u, U_hi: float, U_lo: float = math.inf, p: float = 20.0) -> list[float]:
        """The parameters (:meth:`parameters`' order) of the saturation that tends to ``U_hi`` above and
        ``-U_lo`` below with sharpness ``p``, on the command ``u`` (inverse of :meth:`limits`).

        Examples
        --------
        >>> u = np.linspace(-4.0, 10.0, 15)
        >>> th = InputSaturation().at_limits(None, u, 6.0)
        >>> [round(v, 9) for v in InputSaturation.limits(th)], InputSaturation().transform(None, u, th)[[10, 14]].round(2).tolist()
        ([6.0, inf], [5.8, 6.0])
        """
        hi, lo = self._peaks(u)
        hi, lo = hi or 1.0, lo or 1.0

        def compression(level, ref):  # 1 - (1 + (ref / level)^p)^(-1/p), accurate for a level far above the peak
            return -math.expm1(-math.log1p((ref / level) ** p) / p) if math.isfinite(level) else 0.0

        return [compression(U_hi, hi), compression(U_lo, lo), float(p), hi, lo]

    def transform(self, t, u, theta) -> np.ndarray:
        u = np.asarray(u, float)
        p = float(theta[2])
        out = u.copy()
        for side, level in zip((u > 0, u < 0), self.limits(theta), strict=True):
            if math.isfinite(level):  # beyond the limit in the form that cannot overflow
                r = np.abs(u[side]) / level
                with np.errstate(divide="ignore"):
                    out[side] = np.where(r <= 1.0, u[side] / (1.0 + np.minimum(r, 1.0) ** p) ** (1.0 / p),
                                         np.sign(u[side]) * level / (1.0 + np.maximum(r, 1.0) ** -p) ** (1.0 / p))
        return out


class SlewRateLimit(InputElement):
    """A limit ``r`` on the rate of change of the input (amplifier slew rate): the model's input
    follows the command at most at ``r`` units per second.  Searched between the rate that would
    take the whole recording to cross the input's span and the command's own steepest slope."""

    effect = "slew_rate_limit"
    summary = "the input rising no faster than a maximum rate (amplifier slew-rate limit)"
    component = "rate limiter |du/dt| <= r"

    def parameters(self, t, u) -> list[tuple[str, float, float, float]]:
        span = float(np.ptp(u)) or 1.0
        steepest = float(np.max(np.abs(np.diff(u) / np.diff(t)))) or span / float(t[-1] - t[0])
        lo = min(span / float(t[-1] - t[0]), 0.5 * steepest)
        return [("r", steepest, lo, steepest)]

    def neutral(self, t, u) -> list[float]:
        # twice the command's steepest slope: the limiter never acts
        return [2 * self.parameters(t, u)[0][3]]

    def transform(self, t, u, theta) -> np.ndarray:
        r = float(theta[0])
        out = np.empty_like(np.asarray(u, float))
        out[0] = u[0]
        dts = np.diff(t) * r
        cur = float(u[0])
        for k in range(1, len(u)):
            step = u[k] - cur
            lim = dts[k - 1]
            cur += step if -lim <= step <= lim else (lim if step > 0 else -lim)
            out[k] = cur
        return out
