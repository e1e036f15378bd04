"""Design models for IDA-PBC: neglected storages, the numeric functions the design evaluates, names.

:func:`neglect_states` builds the model a controller is designed on when some
storages are left out (a shorted capacitor: the curling HASEL's charge-retention
branch, whose slow charge the controller then treats as a disturbance).
:class:`Numeric` evaluates a system's generated CasADi functions at fixed
parameter values.  :func:`match_names`, :func:`input_vector` and
:func:`state_vector` turn the names a user gives into indices and vectors.
"""

from __future__ import annotations

import fnmatch

import casadi as ca
import numpy as np
import sympy as sp

from codegen.functions import generate
from phs.errors import InputDataError, ModelError
from phs.system import PHSystem


def match_names(patterns, names: list[str], what: str) -> list[str]:
    """Names matching any of ``patterns`` (exact names or ``fnmatch`` globs such as ``seg*.Q1``), in order.

    Raises
    ------
    InputDataError
        When a pattern matches nothing (naming it and the known names).

    Examples
    --------
    >>> match_names(["seg*.Q1"], ["seg1.Q1", "seg1.Q2", "seg2.Q1"], "state")
    ['seg1.Q1', 'seg2.Q1']
    """
    if isinstance(patterns, str):
        patterns = [patterns]
    out: list[str] = []
    for pat in patterns:
        hits = [n for n in names if n == pat or fnmatch.fnmatchcase(n, pat)]
        if not hits:
            raise InputDataError(f"no {what} matches {pat!r}; {what}s: {', '.join(names)}")
        out += [h for h in hits if h not in out]
    return [n for n in names if n in out]


def neglect_states(system: PHSystem, patterns) -> PHSystem:
    """The model without the storages ``patterns``: their rows and columns are removed and their states set to 0.

    A neglected storage must carry no effort at zero state (``dH/dx_i = 0`` at ``x_i = 0``, e.g. a capacitor's
    ``Q**2/(2 C)``): leaving it out is then shorting it (a capacitor) or removing its inertia (a mass).  The
    resulting model is validated again (J skew, R PSD).

    Raises
    ------
    ModelError
        When a neglected storage still has an effort at zero state, naming it.

    Examples
    --------
    >>> from systems.examples import rlc_circuit
    >>> neglect_states(rlc_circuit(), ["C.Q"]).state_names
    ['L.phi']
    """
    names = match_names(patterns, system.state_names, "state")
    drop = [system.state_names.index(n) for n in names]
    keep = [i for i in range(len(system.states)) if i not in drop]
    zero = {system.x[i]: sp.Integer(0) for i in drop}
    for i in drop:
        effort = sp.diff(system.H, system.x[i]).xreplace(zero)
        if sp.simplify(effort) != 0:
            raise ModelError(f"cannot neglect state {system.state_names[i]!r}: its effort dH/d{system.state_names[i]} "
                             f"is {effort} at zero state, not 0")
    nx, nu = len(system.states), len(system.inputs)
    zmap = {old: new for new, old in enumerate(keep)}
    zmap.update({nx + j: len(keep) + j for j in range(nu)})
    dissipators = []
    for label, entries in system.dissipators:
        kept = {(zmap[i], zmap[j]): v.xreplace(zero) for (i, j), v in entries.items() if i in zmap and j in zmap}
        if kept:
            dissipators.append((label, kept))
    sub = lambda M: M.extract(keep, keep).xreplace(zero)  # noqa: E731
    rows = lambda M: M.extract(keep, list(range(M.cols))).xreplace(zero) if M.cols else sp.zeros(len(keep), 0)  # noqa: E731
    from dataclasses import replace

    from phs.params import Condition, EnergyTerm

    terms = [EnergyTerm(t.label, t.expr.xreplace(zero)) for t in system.energy_terms]
    terms = [t for t in terms if t.expr != 0] or [EnergyTerm("H", sp.Integer(0))]
    conditions = [Condition(c.label, c.expr.xreplace(zero), c.description) for c in system.conditions
                  if not c.label.endswith(f"in {system.name}")]
    measured = [replace(m, expr=m.expr.xreplace(zero)) for m in system.measured]  # sympy objects: PHSystem refuses strings
    return PHSystem(
        f"{system.name}_design", [system.states[i] for i in keep], terms, sub(system.J), sub(system.R), rows(system.G),
        P=rows(system.P), S=system.S.xreplace(zero), N=system.N.xreplace(zero), inputs=system.inputs,
        params=system.params, measured=measured, conditions=conditions, dissipators=dissipators,
        definitions=[(d[0], sp.sympify(d[1]).xreplace(zero), *d[2:]) for d in system.definitions],
        description=f"{system.description} (design model without {', '.join(names)})", structure=system.structure,
    )


class Numeric:
    """A system's generated functions evaluated at fixed parameter values (numpy in, numpy out).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> num = Numeric(mass_spring_damper(), {})
    >>> num.rate([0.0, 0.5], [0.0])        # p' = -k l = -2
    array([-2.,  0.])
    """

    def __init__(self, system: PHSystem, params: dict | None):
        self.system = system
        self.fn = generate(system)
        self.p = system.param_vector(params)
        self.n, self.m = len(system.states), len(system.inputs)
        self.scale = np.array([st.typical for st in system.states], dtype=float)
        sx = self.fn.sx
        self._struct = ca.Function("struct", [sx["x"], sx["p"]], [ca.horzcat(sx["J"] - sx["R"], sx["G"] - sx["P"])])
        X = ca.SX.sym("x", self.n)
        #: ``[J - R, G - P]`` at these parameter values as a CasADi function of the state
        self.struct_function = ca.Function("struct_x", [X], [self._struct(X, ca.DM(self.p))])
        y = sx["measured"]
        self._meas_jac = ca.Function("measured_jac", [sx["x"], sx["u"], sx["p"]],
                                     [y, ca.jacobian(y, sx["x"]), ca.jacobian(y, sx["u"])])

    def rate(self, x, u) -> np.ndarray:
        return np.asarray(self.fn.rhs(x, u, self.p), dtype=float).reshape(-1)

    def jac(self, x, u) -> tuple[np.ndarray, np.ndarray]:
        A, B = self.fn.jac_rhs(x, u, self.p)
        return np.asarray(A, dtype=float).reshape(self.n, self.n), np.asarray(B, dtype=float).reshape(self.n, self.m)

    def struct(self, x) -> np.ndarray:
        return np.asarray(self._struct(x, self.p), dtype=float).reshape(self.n, self.n + self.m)

    def measured(self, x, u) -> np.ndarray:
        return np.asarray(self.fn.measured(x, u, self.p), dtype=float).reshape(-1)

    def measured_jac(self, x, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        y, yx, yu = self._meas_jac(x, u, self.p)
        k = len(self.system.measured)
        return (np.asarray(y, dtype=float).reshape(-1), np.asarray(yx, dtype=float).reshape(k, self.n),
                np.asarray(yu, dtype=float).reshape(k, self.m))

    def conditions(self, x, u) -> np.ndarray:
        if not self.system.conditions:
            return np.zeros(0)
        with np.errstate(all="ignore"):
            return np.asarray(self.fn.conditions(x, u, self.p), dtype=float).reshape(-1)

    def violated(self, x, u, tol: float = 1e-12) -> list[str]:
        """Labels of the validity conditions violated (or not finite) at ``(x, u)``."""
        g = self.conditions(x, u)
        bad = (g < -tol) | ~np.isfinite(g)
        return [c.label for c, b in zip(self.system.conditions, bad) if b]

    def H(self, x) -> float:
        return float(self.fn.hamiltonian(x, np.zeros(self.m), self.p))


def input_vector(system: PHSystem, values: dict | None, what: str) -> np.ndarray:
    """Full input vector from ``{name: value}`` (missing inputs 0), checked.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> input_vector(rc_circuit(), {"U": 2.0}, "fixed_inputs")
    array([2.])
    """
    u = np.zeros(len(system.inputs))
    for k, v in (values or {}).items():
        if k not in system.input_names:
            raise InputDataError(f"{what}: system {system.name!r} has no input {k!r}; inputs: {', '.join(system.input_names)}")
        try:
            u[system.input_names.index(k)] = float(v)
        except (TypeError, ValueError):
            raise InputDataError(f"{what}: value {v!r} for input {k!r} is not a number") from None
        if not np.isfinite(u[system.input_names.index(k)]):
            raise InputDataError(f"{what}: value {v!r} for input {k!r} is not finite")
    return u


def state_vector(system: PHSystem, x0=None, what: str = "x0", ignore=()) -> np.ndarray:
    """Full state vector from ``{name: value}`` or an array, checked; missing states at their declared rest.

    The declared rest (:attr:`phs.params.StateInfo.initial`: a component's rest value, else 0 moved into the
    state's range) is also the default initial state of :func:`codegen.simulate`.

    Parameters
    ----------
    system : PHSystem
    x0 : dict, array or None
        ``{state: value}`` (names in ``ignore`` are skipped), or one value per state; None gives the declared rest.
    what : str
        How the value is named in error messages.
    ignore : sequence of str
        Names accepted and skipped (states the design left out).

    Raises
    ------
    InputDataError
        For an unknown state, a value that is not a finite number, or an array of the wrong length.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> state_vector(mass_spring_damper(), {"k.l": 0.5})
    array([0. , 0.5])
    """
    base = np.array([st.initial for st in system.states])
    if x0 is None:
        return base
    if isinstance(x0, dict):
        for k, v in x0.items():
            if k in ignore:
                continue
            if k not in system.state_names:
                raise InputDataError(f"{what}: system {system.name!r} has no state {k!r}; states: "
                                     f"{', '.join(system.state_names)}")
            try:
                value = float(v)
            except (TypeError, ValueError):
                raise InputDataError(f"{what}: value {v!r} of state {k!r} is not a number") from None
            if not np.isfinite(value):
                raise InputDataError(f"{what}: value {v!r} of state {k!r} is not a finite number")
            base[system.state_names.index(k)] = value
        return base
    try:
        arr = np.asarray(x0, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputDataError(f"{what}: expected a dict by state name or {base.size} numbers for {system.name!r}, "
                             f"got {type(x0).__name__}") from None
    if arr.shape != base.shape:
        raise InputDataError(f"{what}: expected {base.size} values for {system.name!r} "
                             f"({', '.join(system.state_names[:6])}{', ...' if base.size > 6 else ''}), got {arr.size}")
    if not np.all(np.isfinite(arr)):
        k = int(np.argmin(np.isfinite(arr)))
        raise InputDataError(f"{what}: value {float(arr[k])!r} of state {system.state_names[k]!r} is not a finite number")
    return arr
