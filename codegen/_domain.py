"""The validity domain along a trajectory, and the states named in simulation errors.

A model's validity conditions (an arcsin argument at most 1, a zipped length inside its range) are
evaluated at every output point of a run in one mapped call; the first violation raises a
:class:`~phs.errors.DomainError` naming the time, the condition and the state.  When the integrator
itself gives up, explicit-Euler predictions over the failed step tell whether the trajectory was
leaving the domain (a right-hand side turning NaN there is what stops CVODES).
"""

from __future__ import annotations

import numpy as np

from phs.errors import DomainError


def fmt_state(system, x) -> str:
    """``name=value`` of every state, as simulation errors print it.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> fmt_state(mass_spring_damper(), [0.5, 1e-7])
    'm.p=0.5, k.l=1e-07'
    """
    return ", ".join(f"{n}={v:.6g}" for n, v in zip(system.state_names, x))


def predicted_states(f_rhs, x, u, p, h):
    """Explicit-Euler predictions of the state over a failed step (fractions 1/8 .. 1 of it)."""
    xdot = np.asarray(f_rhs(x, u, p), dtype=float).reshape(-1)
    return [(frac, x + frac * h * xdot) for frac in (0.125, 0.25, 0.5, 1.0)]


def _condition(condition) -> str:
    return condition.label + (f" ({condition.description})" if condition.description else "")


class DomainCheck:
    """The validity conditions of ``system`` checked along trajectories (mapped calls cached by length).

    Examples
    --------
    >>> from codegen.functions import generate
    >>> from systems.examples import rc_circuit
    >>> rc = rc_circuit()
    >>> DomainCheck(rc, generate(rc))(np.zeros((3, 1)), np.arange(3.0), rc.param_vector(), np.zeros((3, 1)))
    """

    def __init__(self, system, functions):
        self.system = system
        self.functions = functions
        self._maps: dict = {}

    def __call__(self, xs, times, p, uu) -> None:
        """Raise a :class:`DomainError` at the first of ``times`` where a condition fails for the states ``xs``
        (rows) and inputs ``uu`` (rows)."""
        s = self.system
        if not s.conditions:
            return
        n = len(times)
        fm = self._maps.get(n)
        if fm is None:
            fm = self._maps[n] = self.functions.conditions.map(n)
        buf, trigger = fm.buffer()
        X = np.ascontiguousarray(xs, dtype=float)  # (n, nx) C-order = (nx, n) column-major
        Uu = np.ascontiguousarray(uu, dtype=float)
        Pp = np.ascontiguousarray(np.broadcast_to(p, (n, len(p))), dtype=float)
        gT = np.empty((n, len(s.conditions)))
        buf.set_arg(0, memoryview(X))
        buf.set_arg(1, memoryview(Uu))
        buf.set_arg(2, memoryview(Pp))
        buf.set_res(0, memoryview(gT))
        trigger()
        g = gT.T
        bad = (g < -1e-12) | ~np.isfinite(g)
        if np.any(bad):
            k = int(np.argmax(np.any(bad, axis=0)))
            c = s.conditions[int(np.argmax(bad[:, k]))]
            raise DomainError(
                f"simulation of {s.name!r} left the validity domain at t={times[k]:.6g}: {_condition(c)}"
                + f", value {g[:, k][int(np.argmax(bad[:, k]))]:.4g}; " + "state: " + fmt_state(s, xs[k])
            )

    def predicted(self, x, tk, h, p, uk) -> None:
        """The integrator failed in [tk, tk + h] from a state inside the domain: when the predicted
        trajectory crosses a validity condition (an arcsin argument passing 1 makes the right-hand
        side NaN and CVODES give up), report that as the domain error it is."""
        s = self.system
        if not s.conditions:
            return
        for frac, xp in predicted_states(self.functions.rhs, x, uk[0], p, h):
            g = np.asarray(self.functions.conditions(xp, uk[0], p), dtype=float).reshape(-1)
            bad = (g < -1e-12) | ~np.isfinite(g)
            if np.any(bad):
                c = s.conditions[int(np.argmax(bad))]
                raise DomainError(
                    f"simulation of {s.name!r} left the validity domain between t={tk:.6g} and "
                    f"t={tk + frac * h:.6g}: {_condition(c)}; last state inside: " + fmt_state(s, x)
                )
