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
        not only whole samples: the kinks of a stepping command move between the samples).

        Examples
        --------
        >>> times, values = TimeDelay().course(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 1.0]), [0.25])
        >>> times.tolist(), values.tolist()
        ([0.0, 0.25, 1.25, 2.25], [0.0, 0.0, 1.0, 1.0])
        """
        tau = float(theta[0])
        if not tau > 0:
            return None
        t, u = np.asarray(t, float), np.asarray(u, float)
        return np.concatenate([[t[0]], t + tau]), np.concatenate([[u[0]], u])

    def neutral(self, t, u) -> list[float]:
        return [0.0]


class InputSaturation(InputElement):
    """A saturation of the input at ``U_hi`` above and ``-U_lo`` below (possibly asymmetric), with
    corners rounded over 5 % of the input's peak: ``u − sp(u − U_hi) + sp(−u − U_lo)``, ``sp`` the
    softplus, shifted to pass through zero.  The limits are searched below the recorded peaks (a limit above them has no effect)."""

    effect = "input_saturation"
    summary = "the input saturating at large amplitude (drive or actuator limit)"
    component = "soft clip of u to [-U_lo, U_hi]"

    def parameters(self, t, u) -> list[tuple[str, float, float, float]]:
        hi = float(np.max(u)) if np.max(u) > 0 else float(np.max(np.abs(u))) or 1.0
        lo = float(-np.min(u)) if np.min(u) < 0 else float(np.max(np.abs(u))) or 1.0
        return [("U_hi", 1.05 * hi, 0.2 * hi, 1.05 * hi), ("U_lo", 1.05 * lo, 0.2 * lo, 1.05 * lo)]

    def neutral(self, t, u) -> list[float]:
        # limits far above the peaks: the softplus corners underflow to exactly zero
        peak = float(np.max(np.abs(u))) or 1.0
        return [1e3 * peak, 1e3 * peak]

    def transform(self, t, u, theta) -> np.ndarray:
        u = np.asarray(u, float)
        w = 0.05 * (float(np.max(np.abs(u))) or 1.0)

        def sp_(x):
            return w * np.logaddexp(0.0, x / w)

        hi, lo = float(theta[0]), float(theta[1])
        # minus its value at zero: the rounded corners must not turn a zero input into a small constant one
        return u - sp_(u - hi) + sp_(-u - lo) + sp_(-hi) - sp_(-lo)


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
