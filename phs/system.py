"""The model object: an immutable input-state-output port-Hamiltonian system.

    x' = (J(x) - R(x)) dH/dx + (G(x) - P(x)) u
    y  = (G(x) + P(x))^T dH/dx + (S(x) + N(x)) u

with J skew-symmetric, [[R, P], [P^T, S]] symmetric positive semidefinite and
N skew-symmetric, so that dH/dt = -z^T [[R, P], [P^T, S]] z + y^T u <= y^T u
with z = [dH/dx; u] (van der Schaft).  Measured outputs are any named
functions of state and input.
"""

from __future__ import annotations

import contextvars
import hashlib
from contextlib import contextmanager
from dataclasses import replace
from functools import cached_property
from numbers import Real
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from phs._frozen import FROZEN, FrozenDict, frozen, frozen_matrix
from phs._parts import _as_matrix, _domain_conditions, _replaced, _strict
from phs._sparse import nonzero_entries, srepr_matrix
from phs.errors import ModelError, ParameterError
from phs.io import load_system, save_system
from phs.params import EnergyTerm, InputInfo, Measured, Param, StateInfo, check_name
from phs.structure_units import construction_problems

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from typing import Any

    from phs.checks import CheckReport

_ASSEMBLING = contextvars.ContextVar("phs_assembling", default=False)


@contextmanager
def assembling() -> Iterator[None]:
    """Within it, a :class:`PHSystem` is built without its structure checks (J and N skew, the dissipation
    sampled for ``R ⪰ 0``, the units of the structure; its symbols are still checked) and without the
    validity conditions its expressions imply (square roots, logarithms): for a model put
    together one part at a time, whose parts are not models anyone runs.  The model assembled must be
    built again outside (``PHSystem(...)`` or a rebuild), where it is checked whole, once.

    Examples
    --------
    >>> import sympy as sp
    >>> q = sp.Symbol("q", real=True)
    >>> with assembling():
    ...     part = PHSystem("p", ["q"], q**2 / 2, [[0]], [[-1]])   # R < 0: not checked while assembling
    >>> try:
    ...     PHSystem("p", ["q"], part.H, part.J, part.R)
    ... except ModelError as e:
    ...     print(str(e).splitlines()[1].split(":")[0])
      - R is not positive semidefinite
    """
    token = _ASSEMBLING.set(True)
    try:
        yield
    finally:
        _ASSEMBLING.reset(token)


_NUMERIC_MODULES = [{"erf": __import__("scipy.special", fromlist=["erf"]).erf}, "numpy"]


class PHSystem:
    """An immutable port-Hamiltonian system with named states, inputs and parameters.

    Usually built by :func:`phs.interconnect` from components; it can also be
    given directly by its matrices.

    Parameters
    ----------
    name : str
        Name used for generated functions.
    states : sequence of StateInfo or str
        The state vector in order.
    H : sympy expression or sequence of EnergyTerm
        The Hamiltonian (a sum of labelled terms when given as a sequence).
    J, R : matrix (n x n)
        Interconnection (skew) and dissipation (symmetric PSD) matrices.
    G, P : matrix (n x m), optional
        Input matrix and its resistive cross term.
    S, N : matrix (m x m), optional
        Symmetric (resistive) and skew feedthrough.
    inputs : sequence of InputInfo or str
        Inputs in order; each names its power-conjugate output.
    params : sequence of Param
        Every parameter used in the expressions, with its value.
    measured : sequence of Measured
        Named functions of state and input recorded by sensors.
    conditions : sequence of Condition
        Validity domain as ``expr >= 0``; arcsin/arccos/sqrt/log arguments are
        added automatically.
    dissipators : sequence of (label, {(i, j): expr})
        Per-element dissipation forms on z = [dH/dx; u] (upper triangle).

    Raises
    ------
    ModelError
        Listing every problem found: shapes, unknown symbols, parameters
        without value, J not skew-symmetric, R not symmetric, a dissipation
        matrix with a negative eigenvalue at a sampled point.

    Examples
    --------
    >>> q, p = sp.symbols("q p", real=True)
    >>> k = Param("k", 2.0, "N/m"); m = Param("m", 1.0, "kg")
    >>> osc = PHSystem("osc", [StateInfo("q", "m"), StateInfo("p", "kg*m/s", kind="I")],
    ...                H=k.symbol * q**2 / 2 + p**2 / (2 * m.symbol),
    ...                J=[[0, 1], [-1, 0]], R=sp.zeros(2, 2), params=[k, m])
    >>> osc.dynamics.T
    Matrix([[p/m, -k*q]])

    A model is a value: nothing in it can be changed in place (a change builds a new one)

    >>> osc.R[0, 0] = 1
    Traceback (most recent call last):
    ...
    TypeError: Cannot set values of <class 'sympy.matrices.immutable.ImmutableDenseMatrix'>
    >>> osc.with_params(k=3.0).param("k").value, osc.param("k").value
    (3.0, 2.0)
    """

    def __init__(
        self,
        name: str,
        states,
        H,
        J,
        R,
        G=None,
        *,
        P=None,
        S=None,
        N=None,
        inputs=(),
        params=(),
        measured=(),
        conditions=(),
        dissipators=(),
        definitions=(),
        description: str = "",
        structure: dict | None = None,
    ):
        problems: list[str] = []
        check_name(name, "system")
        self.name = name
        self.states = tuple(s if isinstance(s, StateInfo) else StateInfo(check_name(s, "state")) for s in states)
        self.inputs = tuple(
            u if isinstance(u, InputInfo) else InputInfo(check_name(u, "input"), output=f"{u}.y") for u in inputs
        )
        if isinstance(H, (list, tuple)):
            self.energy_terms = tuple(H)
        else:
            self.energy_terms = (EnergyTerm("H", _strict(H, "H", problems)),)
        self.H = sp.Add(*[t.expr for t in self.energy_terms])
        n, m = len(self.states), len(self.inputs)
        self.J = _as_matrix(J, n, n, "J", problems)
        self.R = _as_matrix(R, n, n, "R", problems)
        self.G = _as_matrix(G, n, m, "G", problems)
        self.P = _as_matrix(P, n, m, "P", problems)
        self.S = _as_matrix(S, m, m, "S", problems)
        self.N = _as_matrix(N, m, m, "N", problems)
        self.params = tuple(params)
        self.measured = tuple(m if isinstance(m.expr, sp.Basic)
                              else replace(m, expr=_strict(m.expr, f"measured output {m.name!r}", problems)) for m in measured)
        self.dissipators = tuple((label, FrozenDict(entries)) for label, entries in dissipators)
        self.definitions = tuple(frozen(d) for d in definitions)
        self.description = description
        self.structure = frozen(dict(structure or {}))
        names = [s.name for s in self.states] + [u.name for u in self.inputs]
        dup = {x for x in names if names.count(x) > 1}
        if dup:
            problems.append(f"names used twice among states and inputs: {sorted(dup)}")
        pnames = [p.name for p in self.params]
        dupp = {x for x in pnames if pnames.count(x) > 1}
        if dupp:
            problems.append(f"parameters declared twice: {sorted(dupp)}")
        for p in self.params:
            if not isinstance(p, Param):
                problems.append(f"{p!r} is not a Param")
            elif p.value is None:
                problems.append(f"parameter {p.name!r} has no value")
        auto = [] if _ASSEMBLING.get() else _domain_conditions(
            [t.expr for t in self.energy_terms] + [v for M in (self.J, self.R, self.G) for _, _, v in nonzero_entries(M)]
            + [mo.expr for mo in self.measured],
            name,
        )
        self.conditions = tuple(conditions) + tuple(c for c in auto if c.expr not in {k.expr for k in conditions})
        self._sampled_structure = FrozenDict()
        self._check_symbols(problems)
        if not problems and not _ASSEMBLING.get():
            self._check_structure(problems)
        if problems:
            raise ModelError(f"invalid port-Hamiltonian system {name!r}", problems)
        self._frozen = True

    # -- immutability: matrices are ImmutableDenseMatrix, sequences tuples, mappings FrozenDict -----------
    def __setattr__(self, key, value):
        if getattr(self, "_frozen", False):
            raise AttributeError(f"PHSystem is immutable ({FROZEN}); tried to set {key!r}")
        object.__setattr__(self, key, value)

    def __delattr__(self, key):
        raise AttributeError(f"PHSystem is immutable ({FROZEN}); tried to delete {key!r}")

    # -- symbols --------------------------------------------------------------------
    @property
    def x(self) -> list[sp.Symbol]:
        """State symbols in order."""
        return [s.symbol for s in self.states]

    @property
    def u(self) -> list[sp.Symbol]:
        """Input symbols in order."""
        return [i.symbol for i in self.inputs]

    @property
    def p(self) -> list[sp.Symbol]:
        """Parameter symbols in order."""
        return [q.symbol for q in self.params]

    @property
    def state_names(self) -> list[str]:
        return [s.name for s in self.states]

    @property
    def input_names(self) -> list[str]:
        return [i.name for i in self.inputs]

    @property
    def output_names(self) -> list[str]:
        """Names of the power-conjugate port outputs."""
        return [i.output for i in self.inputs]

    @property
    def measured_names(self) -> list[str]:
        return [mo.name for mo in self.measured]

    @property
    def param_names(self) -> list[str]:
        return [q.name for q in self.params]

    def param_values(self) -> dict[str, float]:
        """Current parameter values by name."""
        return {q.name: q.value for q in self.params}

    def param(self, name: str) -> Param:
        """The parameter called ``name`` (raises ParameterError naming it if unknown)."""
        for q in self.params:
            if q.name == name:
                return q
        raise ParameterError(f"system {self.name!r} has no parameter {name!r}; known: {', '.join(self.param_names)}")

    def param_vector(self, overrides: dict | None = None, *, signs: bool = True) -> np.ndarray:
        """Parameter values in order, with ``overrides`` by name applied and checked.

        An override must name a parameter and be a finite number of the declared sign
        (:meth:`Param.checked`: a value outside the declared range warns).  ``signs=False``
        lets a value of the wrong sign through: only for analyses that report what it does
        (the passivity certificate's what-if), never for a simulation.

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> rc_circuit().param_vector({"R.R": 2e3}).tolist()
        [2000.0, 1e-06]
        >>> rc_circuit().param_vector({"C.C": -1e-6})
        Traceback (most recent call last):
        ...
        phs.errors.ParameterError: parameter 'C.C' [F] is declared positive; value -1e-06 refused
        """
        vals = self.param_values()
        by_name = {q.name: q for q in self.params}
        for k, v in (overrides or {}).items():
            if k not in vals:
                raise ParameterError(f"system {self.name!r} has no parameter {k!r}; known: {', '.join(self.param_names)}")
            if not isinstance(v, Real) or not np.isfinite(v):
                raise ParameterError(f"parameter {k!r}: value {v!r} is not a finite number")
            vals[k] = by_name[k].checked(v) if signs else float(v)
        return np.array([vals[q] for q in self.param_names], dtype=float)

    def with_params(self, values: dict | None = None, **kw) -> PHSystem:
        """New system with some parameter values changed.

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> rc_circuit().with_params({"C.C": 2e-6}).param("C.C").value
        2e-06
        """
        values = {**(values or {}), **kw}
        known = set(self.param_names)
        bad = [k for k in values if k not in known]
        if bad:
            raise ParameterError(f"system {self.name!r} has no parameter {', '.join(map(repr, bad))}; known: {', '.join(self.param_names)}")
        params = [q.with_value(values[q.name]) if q.name in values else q for q in self.params]
        return self._replace(params=params)

    def _replace(self, **changes) -> PHSystem:
        kw = dict(
            states=self.states, H=list(self.energy_terms), J=self.J, R=self.R, G=self.G, P=self.P, S=self.S, N=self.N,
            inputs=self.inputs, params=self.params, measured=self.measured,
            conditions=[c for c in self.conditions if not c.label.endswith(f"in {self.name}")],
            dissipators=self.dissipators, definitions=self.definitions, description=self.description,
            structure=self.structure,
        )
        kw.update(changes)
        name = kw.pop("name", self.name)
        return PHSystem(name, **kw)

    def with_measured(self, *measured: Measured) -> PHSystem:
        """New system with extra measured outputs (names must be new).

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> s = rc_circuit()
        >>> from phs.component import symbol_of_output
        >>> s.with_measured(Measured("i", 1e3 * symbol_of_output("U.i"), "mA")).measured_names
        ['v_C', 'i']
        """
        clash = [m.name for m in measured if m.name in self.measured_names]
        if clash:
            raise ModelError(f"system {self.name!r} already has measured output(s) {clash}")
        return self._replace(measured=self.measured + tuple(measured))

    def renamed(self, name: str) -> PHSystem:
        """Same system under another name."""
        return self._replace(name=name)

    # -- derived quantities (cached) -------------------------------------------------
    @cached_property
    def grad_H(self) -> sp.ImmutableDenseMatrix:
        """Gradient dH/dx as a column matrix."""
        return sp.ImmutableMatrix(len(self.x), 1, [sp.diff(self.H, xi) for xi in self.x])

    @cached_property
    def dynamics(self) -> sp.ImmutableDenseMatrix:
        """Right-hand side x' as a column matrix."""
        u = sp.Matrix(len(self.u), 1, self.u)
        return frozen_matrix((self.J - self.R) * self.grad_H + (self.G - self.P) * u)

    @cached_property
    def dynamics_jacobian(self) -> sp.ImmutableDenseMatrix:
        """Jacobian of the right-hand side with respect to the states (symbolic)."""
        return frozen_matrix(self.dynamics.jacobian(self.x))

    @cached_property
    def port_output(self) -> sp.ImmutableDenseMatrix:
        """Power-conjugate outputs y."""
        u = sp.Matrix(len(self.u), 1, self.u)
        return frozen_matrix((self.G + self.P).T * self.grad_H + (self.S + self.N) * u)

    @cached_property
    def measured_expressions(self) -> tuple[sp.Expr, ...]:
        """Measured outputs as expressions of state and input (port outputs they refer to substituted)."""
        outs = {sp.Symbol(i.output, real=True): k for k, i in enumerate(self.inputs)}
        exprs = []
        for mo in self.measured:
            e = sp.sympify(mo.expr)
            used = e.free_symbols & outs.keys()
            if used:
                e = e.xreplace({o: self.port_output[outs[o]] for o in used})
            exprs.append(e)
        return tuple(exprs)

    @cached_property
    def dissipation_matrix(self) -> sp.ImmutableDenseMatrix:
        """[[R, P], [P^T, S]], the quadratic form of dissipated power in z = [dH/dx; u]."""
        return frozen_matrix(sp.Matrix.vstack(sp.Matrix.hstack(self.R, self.P), sp.Matrix.hstack(self.P.T, self.S)))

    @cached_property
    def power_balance(self) -> dict[str, sp.Expr]:
        """Symbolic power terms: ``dHdt``, ``dissipated``, ``supplied`` (y^T u).

        ``dHdt == supplied - dissipated`` holds identically.
        """
        z = sp.Matrix(len(self.x) + len(self.u), 1, list(self.grad_H) + list(self.u))
        dissipated = (z.T * self.dissipation_matrix * z)[0, 0] if len(z) else sp.Integer(0)
        supplied = (self.port_output.T * sp.Matrix(len(self.u), 1, self.u))[0, 0] if self.inputs else sp.Integer(0)
        dHdt = (self.grad_H.T * self.dynamics)[0, 0] if self.states else sp.Integer(0)
        return FrozenDict({"dHdt": dHdt, "dissipated": dissipated, "supplied": supplied})

    def dissipator_powers(self) -> dict[str, sp.Expr]:
        """Power dissipated by each resistive element, as expressions of state and input."""
        z = list(self.grad_H) + list(self.u)
        out = {}
        for label, entries in self.dissipators:
            tot = sp.Integer(0)
            for (i, j), v in entries.items():
                tot += (1 if i == j else 2) * v * z[i] * z[j]
            out[label] = tot
        return out

    # -- numeric evaluation ----------------------------------------------------------
    def lambdify(self, expr, with_u: bool = True) -> Callable[..., Any]:
        """Numpy function ``f(x, u, p)`` of a sympy expression or matrix of this system.

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> s = rc_circuit()
        >>> float(s.lambdify(s.H)([1e-6], [0.0], s.param_vector()))   # Q**2 / (2 C)
        5e-07
        """
        return self._lambdify(expr, with_u, plain_names=False)

    def _lambdify(self, expr, with_u: bool, plain_names: bool) -> Callable[..., Any]:
        """:meth:`lambdify`; with ``plain_names`` the symbols are first renamed to Python identifiers.

        Names like ``"rod.ux1"`` are no Python identifiers: sympy replaces them one argument at a
        time, each a pass over the whole expression (quadratic in the size of the model); one
        replacement by plain names does it at once.  The function is the same, but the generated
        code may order the terms of a sum differently (results can differ in the last bits), so
        only the model's own construction checks use it.
        """
        args = self.x + (self.u if with_u else []) + self.p
        if plain_names:
            plain = {a: sp.Symbol(f"_a{k}", **a.assumptions0) for k, a in enumerate(args)}
            args, expr = list(plain.values()), _replaced(expr, plain)
        f = sp.lambdify(args, expr, modules=_NUMERIC_MODULES, cse=True)
        nx, nu = len(self.x), len(self.u)

        def call(x, u=(), p=None):
            p = self.param_vector() if p is None else p
            x = np.asarray(x, dtype=float)
            return f(*x, *(np.asarray(u, dtype=float).reshape(-1)[:nu] if with_u else []), *p)

        call.nx = nx
        return call

    def sample_box(self, k: int, seed: int = 0, params: bool = False) -> np.ndarray:
        """``k`` points drawn uniformly from the states' (and optionally parameters') ranges."""
        rng = np.random.default_rng(seed)
        lo = [s.range[0] for s in self.states] + ([q.range[0] for q in self.params] if params else [])
        hi = [s.range[1] for s in self.states] + ([q.range[1] for q in self.params] if params else [])
        return rng.uniform(lo, hi, size=(k, len(lo)))

    # -- checks -----------------------------------------------------------------------
    def _check_symbols(self, problems: list[str]) -> None:
        known = set(self.x) | set(self.p)
        known_u = known | set(self.u)
        by_name = {s.name: s for s in known_u}

        def look(expr, where, allowed):
            for s in expr.free_symbols:
                if s not in allowed:
                    hint = ""
                    if s.name in by_name:
                        hint = " (a symbol of that name exists with other assumptions: build it with Param.symbol / symbol_of_state)"
                    problems.append(f"unknown symbol {s.name!r} in {where}{hint}")

        for t in self.energy_terms:
            look(t.expr, f"energy term {t.label!r}", known)
        for nm, M in (("J", self.J), ("R", self.R), ("G", self.G), ("P", self.P), ("S", self.S), ("N", self.N)):
            look(M, nm, known)
        outs = {sp.Symbol(i.output, real=True) for i in self.inputs}
        for mo in self.measured:
            look(sp.sympify(mo.expr), f"measured output {mo.name!r}", known_u | outs)
        for c in self.conditions:
            look(c.expr, f"condition {c.label!r}", known_u)

    def _check_structure(self, problems: list[str]) -> None:
        """J, N skew and D symmetric (symbolic within the budget of :mod:`phs._budget`, else sampled); D not
        negative (nor undefined) at sampled points of the declared ranges; the units of the structure where
        the declared units decide them (:func:`phs.structure_units.construction_problems`)."""
        from phs.checks import structure_problems  # local import: checks uses PHSystem

        self._sampled_structure = FrozenDict(structure_problems(self, problems))
        problems += construction_problems(self)  # units of J, R, G, P, S, N, ports, measured outputs, where decided

    def _psd_culprits(self, block_names) -> str:
        """The resistive elements acting on a block, and their parameters with negative values."""
        names = self.state_names + self.input_names
        idx = {names.index(n) for n in block_names if n in names}
        labels, negative = [], set()
        for label, entries in self.dissipators:
            touched = [v for (i, j), v in entries.items() if i in idx or j in idx]
            if touched:
                labels.append(label)
                for v in touched:
                    for sym in v.free_symbols:
                        for q in self.params:
                            if q.symbol == sym and q.value is not None and q.value < 0:
                                negative.add(f"{q.name}={q.value:g}")
        out = f" (resistive elements: {', '.join(labels)})" if labels else ""
        if negative:
            out += f"; negative parameter values: {', '.join(sorted(negative))}"
        return out

    def check(self, samples: int = 200, seed: int = 0) -> CheckReport:
        """Structural report: skew J, PSD R (symbolic or sampled), H bounded below, units.

        Returns
        -------
        phs.checks.CheckReport

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> rc_circuit().check().ok
        True
        """
        from phs.checks import check_system

        return check_system(self, samples=samples, seed=seed)

    # -- identity, display --------------------------------------------------------------
    def model_hash(self) -> str:
        """Hash of the model's structure and parameter names (not values): keys caches."""
        h = hashlib.sha256()
        for part in (
            self.name, [s.name for s in self.states], [i.name for i in self.inputs], self.param_names,
            [i.output for i in self.inputs],  # measured outputs refer to port outputs by these names
            [sp.srepr(t.expr) for t in self.energy_terms], *(srepr_matrix(M) for M in (self.J, self.R, self.G, self.P,
                                                                                      self.S, self.N)),
            [(m.name, sp.srepr(m.expr)) for m in self.measured],
            [(c.label, sp.srepr(c.expr)) for c in self.conditions],
            [(label, sorted((k, sp.srepr(v)) for k, v in entries.items())) for label, entries in self.dissipators],
        ):
            h.update(repr(part).encode())
        return h.hexdigest()[:16]

    def __repr__(self) -> str:
        return (f"PHSystem({self.name!r}, states={len(self.states)}, inputs={len(self.inputs)}, "
                f"params={len(self.params)}, measured={len(self.measured)})")

    def __str__(self) -> str:
        from phs.display import summary

        return summary(self)

    def _repr_latex_(self) -> str:
        from phs.display import latex

        return latex(self)

    def save(self, path) -> None:
        """Save definition and parameter values to a JSON file (atomically); see :mod:`phs.io`."""
        save_system(self, path)

    @classmethod
    def load(cls, path) -> PHSystem:
        """Load a system saved with :meth:`save`; the file is read as data, never run (see :mod:`phs.io`)."""
        return load_system(path, cls)
