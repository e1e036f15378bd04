"""The validity domain along a trajectory, and the states named in simulation errors.

A model's validity conditions (an arcsin argument at most 1, a zipped length inside its range) are
evaluated at every output point of a run in one mapped call; the first violation raises a
:class:`~phs.errors.DomainError` naming the time, the condition and the state.  When the integrator
itself gives up, explicit-Euler predictions over the failed step tell whether the trajectory was
leaving the domain (a right-hand side turning NaN there is what stops CVODES).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from phs.errors import DomainError

TOLERANCE = 1e-12
"""A condition is violated below ``-TOLERANCE`` (at output points and inside the integrator alike)."""


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


def gated(expr, conditions, x):
    """``expr`` (a column of right-hand sides in the states ``x``) made NaN where one of ``conditions`` fails.

    Integrated as a right-hand side, this stops CVODES within a few steps of leaving the validity
    domain (a NaN right-hand side makes it give up; the failure is then reported as the
    :class:`~phs.errors.DomainError` it is) instead of integrating on outside it, where the model is
    meaningless and often stiff (a step of 10 MV on the curling HASEL took 24 s of CPU time there before
    the check at the output points saw it).

    Each condition gates the rows that already depend on every state it depends on, so the Jacobian
    keeps its sparsity and, inside the domain, the values and the Jacobian are ``expr``'s own and the
    integration takes the same steps, bit for bit; a condition no row covers gates the row that covers
    most of its states.

    Examples
    --------
    >>> x = ca.SX.sym("x", 2)
    >>> f = ca.Function("f", [x], [gated(ca.vertcat(x[1], -x[0]), ca.vertcat(1 - x[0]), x)])
    >>> f([0.5, 1.0]).full().ravel().tolist(), f([2.0, 1.0]).full().ravel().tolist()
    ([1.0, -0.5], [1.0, nan])
    """
    if conditions.numel() == 0:
        return expr
    rows = ca.jacobian_sparsity(expr, x)
    needs = ca.jacobian_sparsity(conditions, x)
    row_cols = _columns(rows)
    gates: list[list] = [[] for _ in range(expr.numel())]
    for k, cols in enumerate(_columns(needs)):
        covering = [i for i, have in enumerate(row_cols) if cols <= have]
        if not covering:  # the row that depends on most of its states: the Jacobian gains the fewest entries
            covering = [max(range(len(row_cols)), key=lambda i: len(cols & row_cols[i]))]
        for i in covering:
            gates[i].append(conditions[k])
    out = []
    for i in range(expr.numel()):
        if gates[i]:
            inside = ca.mmin(ca.vertcat(*gates[i])) >= -TOLERANCE
            out.append(ca.if_else(inside, expr[i], ca.SX.nan()))
        else:
            out.append(expr[i])
    return ca.vertcat(*out)


def _columns(sparsity) -> list[set]:
    """The columns of each row of a CasADi sparsity pattern."""
    cols: list[set] = [set() for _ in range(sparsity.size1())]
    for r, c in zip(sparsity.row(), sparsity.get_col(), strict=True):
        cols[r].add(c)
    return cols


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
        bad = (g < -TOLERANCE) | ~np.isfinite(g)
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
            bad = (g < -TOLERANCE) | ~np.isfinite(g)
            if np.any(bad):
                c = s.conditions[int(np.argmax(bad))]
                raise DomainError(
                    f"simulation of {s.name!r} left the validity domain between t={tk:.6g} and "
                    f"t={tk + frac * h:.6g}: {_condition(c)}; last state inside: " + fmt_state(s, x)
                )
