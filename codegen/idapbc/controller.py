"""The IDA-PBC controller (:class:`Controller`) and its design (:func:`design`).

:func:`design` checks the request, builds the design model (neglected storages
left out, :mod:`codegen.idapbc.model`), assigns the equilibrium on the leaf of
the conserved quantities (:mod:`codegen.idapbc.leaf`, :mod:`codegen.idapbc.target`),
solves the matching equations (:mod:`codegen.idapbc.shaping`) and returns a
:class:`Controller`.  The controller's law is generated in CasADi
(:mod:`codegen.idapbc.law`); its methods hand it to the modules below it:
certificates (:mod:`codegen.idapbc.certificates`), closed-loop simulation
(:mod:`codegen.idapbc.closed_loop`), C export (:mod:`codegen.idapbc.export`) and
the linear analysis that sets integral gains (:mod:`codegen.idapbc.linear`).
Those take the controller as an argument and never import this module.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np
import sympy as sp

import codegen.idapbc.certificates as certificates
import codegen.idapbc.closed_loop as closed_loop
import codegen.idapbc.export as export
from codegen.idapbc.law import functions
from codegen.idapbc.leaf import Leaf
from codegen.idapbc.linear import integral_gain
from codegen.idapbc.matching import Structure
from codegen.idapbc.model import Numeric, input_vector, match_names, neglect_states, state_vector
from codegen.idapbc.shaping import desired_structure
from codegen.idapbc.target import assign, resolve_targets
from phs.errors import InputDataError, ModelError
from phs.params import c_identifier
from phs.system import PHSystem

__all__ = ["design", "Controller"]

_STRUCTURES = ("auto", "ansatz", "electromechanical")
_INTEGRAL = (None, "passive", "output")


def _number(value, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputDataError(f"{what} must be a number, got {value!r}") from None
    if not (np.isfinite(v) and v >= 0):
        raise InputDataError(f"{what} must be a finite number >= 0, got {value!r}")
    return v


def design(system: PHSystem, target: dict, *, inputs=None, fixed_inputs: dict | None = None, x0=None,
           params: dict | None = None, neglect=(), structure: str = "auto", damping=0.0, stiffness: dict | None = None,
           H_a=None, unknowns=None, J_a=None, R_a=None, integral: str | None = None, integral_time: float | None = None,
           integral_gain=None) -> Controller:
    """Design an IDA-PBC controller that holds ``system`` at ``target``.

    Parameters
    ----------
    system : PHSystem
    target : dict
        ``{name: value}`` for states or measured outputs (``{"tip": 0.03}``); as many as controlled inputs.
    inputs : sequence of str, optional
        Controlled inputs (default: all inputs, when their number equals the number of targets).
    fixed_inputs : dict, optional
        Values of the other inputs (default 0), e.g. a load force.
    x0 : dict or array, optional
        A state on the leaf of the conserved quantities to regulate on (the curling HASEL at rest:
        ``{"seg1.l_p": 0.015, ...}``); default: each state at its declared rest (``StateInfo.initial``, the
        default initial state of :func:`codegen.simulate`).
    params : dict, optional
        Parameter values of the controller's model (overrides).
    neglect : sequence of str
        Storages left out of the design (names or globs such as ``"seg*.Q1"``; see the module docstring).
    structure : {"auto", "ansatz", "electromechanical"}
        How the matching equations are solved (see :mod:`codegen.idapbc.matching`).
    damping : float or dict
        Damping injection ``R_a += r g g^T``: the number ``r`` itself, or ``{state: d}`` for the dissipation ``d``
        added on that state's row at ``x*`` (``r = d / |g_state(x*)|**2``; e.g. ``{"p": 20.0}`` adds 20 kg/s to a
        mass driven through a state-dependent input map).
    stiffness : dict, optional
        ``{state: k}``: curvature of ``H_a`` along a state at ``x*`` (energy shaping; ansatz: any matched state,
        electromechanical: actuated storages whose shaping is matched).
    H_a : sympy expression, optional
        Your own ansatz, linear in the symbols ``unknowns`` (solved from the matching equations).
    unknowns : sequence of sympy symbols, optional
        The free coefficients of ``H_a`` (default: its symbols that are neither states nor parameters).
    J_a, R_a : sympy matrices, optional
        Added interconnection and dissipation (states and parameters allowed); the ansatz solves for ``H_a``.
    integral : {None, "passive", "output"}
        Integral action (see the module docstring).
    integral_time : float, optional
        Time constant of the integral action [s] (default: 5 times the slowest closed-loop time constant).
    integral_gain : float or array, optional
        The gain ``K_i`` itself (overrides ``integral_time``).

    Returns
    -------
    Controller

    Raises
    ------
    EquilibriumError
        When no admissible equilibrium meets the target (the message says why, with the numbers).
    InputDataError
        For unknown names, a target count that does not match the inputs, or shaping the matching forbids.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0})
    >>> ctrl.structure.kind, round(float(ctrl.structure.coefficients["(k.l - *)^2/2"]), 9)
    ('ansatz', 6.0)
    """
    if not isinstance(system, PHSystem):
        raise InputDataError(f"design: expected a PHSystem, got {type(system).__name__}")
    if structure not in _STRUCTURES:
        raise InputDataError(f"structure must be one of {', '.join(_STRUCTURES)}; got {structure!r}")
    if integral not in _INTEGRAL:
        raise InputDataError(f"integral must be None, 'passive' or 'output'; got {integral!r}")
    if isinstance(damping, dict):
        if len(damping) != 1:
            raise InputDataError("damping as a dict names one state: {state: added dissipation on its row at x*}")
        (d_state, d_value), = damping.items()
        r = _number(d_value, f"damping[{d_state!r}]")
    else:
        d_state, r = None, _number(damping, "damping")
    original = system
    removed: list[str] = []
    if neglect:
        removed = match_names(neglect, system.state_names, "state")
        system = neglect_states(system, removed)
    num = Numeric(system, params)
    targets = resolve_targets(system, target)
    if inputs is None:
        if len(system.inputs) != len(targets):
            raise InputDataError(f"system {system.name!r} has inputs {system.input_names} and {len(targets)} target(s): "
                                 "say which inputs the controller drives with inputs=[...]")
        ctrl = list(range(len(system.inputs)))
    else:
        names = [inputs] if isinstance(inputs, str) else list(inputs)
        for nm in names:
            if nm not in system.input_names:
                raise InputDataError(f"inputs: system {system.name!r} has no input {nm!r}; inputs: "
                                     f"{', '.join(system.input_names)}")
        ctrl = [system.input_names.index(nm) for nm in names]
    if len(ctrl) != len(targets):
        raise InputDataError(f"{len(targets)} target(s) ({', '.join(t.name for t in targets)}) for {len(ctrl)} "
                             "controlled input(s): give as many targets as controlled inputs")
    u_base = input_vector(system, fixed_inputs, "fixed_inputs")
    for j in ctrl:
        if fixed_inputs and system.input_names[j] in fixed_inputs:
            raise InputDataError(f"input {system.input_names[j]!r} is both controlled and fixed")
    xs0 = state_vector(system, x0, ignore=removed)
    bad = num.violated(xs0, u_base)
    if bad:
        raise InputDataError(f"x0 is outside the validity domain of {system.name!r}: {'; '.join(bad)} "
                             "(give a state on the leaf to regulate on, e.g. the actuator at rest)")
    leaf = Leaf(num.struct_function, num.scale, xs0)
    asg = assign(num, leaf, targets, ctrl, u_base, xs0)
    st, g, f_fix, r = desired_structure(system, num, asg, ctrl, u_base, structure=structure, damping=r,
                                        damping_state=d_state, stiffness=stiffness, H_a=H_a, unknowns=unknowns,
                                        J_a=J_a, R_a=R_a)
    out = Controller(original=original, system=system, neglected=tuple(removed), num=num, leaf=leaf,
                     targets=tuple(targets), ctrl=tuple(ctrl), u_base=u_base, x0=xs0, assignment=asg, structure=st,
                     damping=r, g=g, f_fix=f_fix, params=dict(params or {}), integral=None, K_i=np.zeros((0, 0)))
    if integral is not None:
        out = out.with_integral(integral, time=integral_time, gain=integral_gain)
    return out


@dataclass(frozen=True, eq=False)
class Controller:
    """An IDA-PBC controller: assigned equilibrium, desired structure, control law and its functions.

    Attributes
    ----------
    system : PHSystem
        The design model (``original`` without the ``neglected`` storages).
    x_star, u_star : numpy arrays
        Assigned equilibrium (design states) and the constant input holding it (all inputs).
    structure : Structure
        ``H_a``, ``J_a``, ``R_a`` (sympy, controller parameters substituted), how they were solved, notes.
    integral : None, "passive" or "output"
    K_i : numpy array
        Integral gain (controlled inputs x integrator states).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, damping=1.0)
    >>> ctrl.input_names, ctrl.law_function.name()
    (['F'], 'msd_law')
    """

    original: PHSystem
    system: PHSystem
    neglected: tuple
    num: Numeric
    leaf: Leaf
    targets: tuple
    ctrl: tuple
    u_base: np.ndarray
    x0: np.ndarray
    assignment: object
    structure: Structure
    damping: float
    g: sp.Matrix
    f_fix: sp.Matrix
    params: dict
    integral: str | None
    K_i: np.ndarray

    # -- basic facts --------------------------------------------------------------------------------
    @property
    def name(self) -> str:
        return c_identifier(self.system.name).replace("__", "_")

    @property
    def x_star(self) -> np.ndarray:
        return self.assignment.x

    @property
    def u_star(self) -> np.ndarray:
        return self.assignment.u[list(self.ctrl)]

    @property
    def input_names(self) -> list[str]:
        return [self.system.input_names[j] for j in self.ctrl]

    @property
    def target(self) -> dict:
        return {t.name: t.value for t in self.targets}

    @property
    def n_xi(self) -> int:
        return 0 if self.integral is None else len(self.ctrl)

    @property
    def J_d(self) -> sp.Matrix:
        vals = {q.symbol: sp.Float(v) for q, v in zip(self.system.params, self.num.p)}
        return self.system.J.xreplace(vals) + self.structure.J_a

    @property
    def R_d(self) -> sp.Matrix:
        vals = {q.symbol: sp.Float(v) for q, v in zip(self.system.params, self.num.p)}
        return self.system.R.xreplace(vals) + self.structure.R_a

    @property
    def phi_implicit(self) -> bool:
        """True when part of H_a (Phi) has no closed form and is integrated along the leaf."""
        return self.structure.v is not None

    # -- generated functions ------------------------------------------------------------------------
    @property
    def _fx(self) -> dict:
        cache = self.__dict__.get("_cache")
        if cache is None:
            cache = functions(self)
            object.__setattr__(self, "_cache", cache)
        return cache

    @property
    def law_function(self) -> ca.Function:
        """CasADi function ``{name}_law(x, xi) -> u`` (controlled inputs; ``xi`` empty without integral action)."""
        return self._fx["law"]

    def law(self, x, xi=None) -> np.ndarray:
        """The control law at design state ``x`` (and integrator state ``xi``).

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
        >>> round(float(ctrl.law([0.0, 0.7])[0]), 9)   # u = k q* - k_a (q - q*) - r p/m = 2 - 6 * 0.2
        0.8
        """
        xi = np.zeros(self.n_xi) if xi is None else np.asarray(xi, dtype=float)
        return np.asarray(self.law_function(np.asarray(x, dtype=float), xi), dtype=float).reshape(-1)

    def H_d(self, x) -> float:
        """Desired energy at design state ``x`` minus its value at ``x*`` (Phi integrated along the leaf if
        implicit; ``x`` must then lie on the leaf of ``x*``)."""
        x = np.asarray(x, dtype=float)
        val = float(self._fx["Hd"](x)) - float(self._fx["Hd"](self.x_star))
        if self.phi_implicit:
            val += self.phi(x)
        return val

    def phi(self, x) -> float:
        """``Phi(x) - Phi(x*)`` along the leaf (0 when Phi is explicit)."""
        if not self.phi_implicit:
            return 0.0
        fv = self._fx["v"]
        _, q = self.leaf.transport(self.x_star, np.asarray(x, dtype=float)[self.leaf.free],
                                   covector=fv)
        return q

    def law_expression(self) -> sp.Matrix:
        """The control law as a sympy matrix of the design states (controller parameters substituted).

        Raises
        ------
        ModelError
            When part of H_d has no closed form or integral action is on (the law is then only a CasADi function).

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
        >>> u = ctrl.law_expression()[0]          # k q* - k_a (q - q*) - r p/m
        >>> [float(u.coeff(v)) for v in ctrl.system.x], float(u.subs({v: 0 for v in ctrl.system.x}))
        ([-2.0, -6.0], 5.0)
        """
        if self.phi_implicit or self.integral is not None:
            raise ModelError("the law has no closed form here (implicit Phi or integral action); use law_function")
        x = self.system.x
        vals = {q.symbol: sp.Float(v) for q, v in zip(self.system.params, self.num.p)}
        H = self.system.H.xreplace(vals)
        Hd = H + self.structure.H_a
        dH = sp.Matrix([sp.diff(H, xi) for xi in x])
        dHd = sp.Matrix([sp.diff(Hd, xi) for xi in x])
        JR = (self.system.J - self.system.R).xreplace(vals)
        g = self.g
        rhs = (self.J_d - self.R_d) * dHd - JR * dH - self.f_fix
        return ((g.T * g).inv() * g.T * rhs).applyfunc(sp.expand)

    # -- variants -------------------------------------------------------------------------------------
    def with_integral(self, kind: str | None, *, time: float | None = None, gain=None) -> Controller:
        """The same design with integral action ``kind`` (``"passive"``, ``"output"`` or None).

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, damping=1.0).with_integral("output", time=2.0)
        >>> ctrl.integral, ctrl.n_xi, round(float(ctrl.K_i[0, 0]), 6)   # K_i = 1 / (tau * dq/dF) = 4 / 2
        ('output', 1, 2.0)
        """
        if kind not in _INTEGRAL:
            raise InputDataError(f"integral must be None, 'passive' or 'output'; got {kind!r}")
        base = replace(self, integral=None, K_i=np.zeros((0, 0)))
        base.__dict__.pop("_cache", None)
        if kind is None:
            return base
        m = len(self.ctrl)
        if gain is not None:
            K = np.atleast_2d(np.asarray(gain, dtype=float))
            if K.shape == (1, 1) and m > 1:
                K = K[0, 0] * np.eye(m)
            if K.shape != (m, m) or not np.all(np.isfinite(K)):
                raise InputDataError(f"integral_gain must be a number or a {m} x {m} matrix")
        else:
            K = integral_gain(base, kind, time)
        out = replace(base, integral=kind, K_i=K)
        out.__dict__.pop("_cache", None)
        return out

    # -- workflows ----------------------------------------------------------------------------------
    def certify(self, **kw) -> certificates.CertificateReport:
        """Certificates with numbers; see :func:`codegen.idapbc.certificates.certify`.

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
        >>> ctrl.certify(rays=8, simulations=2).passed
        True
        """
        return certificates.certify(self, **kw)

    def simulate(self, t, x0=None, **kw) -> closed_loop.ClosedLoopResult:
        """Closed-loop simulation; see :func:`codegen.idapbc.closed_loop.simulate_closed_loop`.

        Parameters
        ----------
        t : array
            Increasing output times.
        x0 : dict or array, optional
            Plant initial state, ``{state: value}`` (the other states as by default) or one value per plant
            state.  Default: where the plant rests before the controller acts, as ``phs control --t-end``
            (:func:`codegen.idapbc.closed_loop.start_state`): each state at its declared rest, the default
            of the open-loop :func:`codegen.simulate` (the design's ``x0`` if one was given), or, under a
            weight or preload that moves it, the equilibrium the plant settles at.
        **kw
            ``plant``, ``params``, ``xi0``, ``saturate``, ``rtol``, ``atol``, ``max_steps`` of
            :func:`~codegen.idapbc.closed_loop.simulate_closed_loop`.

        Raises
        ------
        InputDataError
            For an ``x0`` naming no state, a value that is not a finite number (the state named), or an
            array of the wrong length.

        Examples
        --------
        >>> import numpy as np
        >>> from systems.examples import mass_spring_damper
        >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
        >>> res = ctrl.simulate(np.linspace(0, 10, 101))          # from the declared rest: k.l = 0, m.p = 0
        >>> res.x[0].tolist(), round(float(res["position"][-1]), 4)
        ([0.0, 0.0], 0.5)
        >>> a = ctrl.simulate([0.0, 1.0], x0={"k.l": 0.2})         # by name ...
        >>> b = ctrl.simulate([0.0, 1.0], x0=[0.0, 0.2])           # ... or one value per state (m.p, k.l)
        >>> bool(np.array_equal(a.x, b.x))
        True
        >>> ctrl.simulate([0.0, 1.0], x0={"k.l": "far"})
        Traceback (most recent call last):
        ...
        phs.errors.InputDataError: x0: value 'far' of state 'k.l' is not a number
        """
        return closed_loop.simulate_closed_loop(self, t, x0=x0, **kw)

    def export_c(self, directory, name: str | None = None) -> list[str]:
        """Write the control law as a standalone C source and header; see :func:`codegen.idapbc.export.export_c`.

        Returns
        -------
        list of str
            The paths written (``.c`` then ``.h``).

        Examples
        --------
        >>> import tempfile, os
        >>> from systems.examples import mass_spring_damper
        >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, damping=1.0)
        >>> with tempfile.TemporaryDirectory() as d:
        ...     [os.path.basename(p) for p in ctrl.export_c(d)]
        ['msd_controller.c', 'msd_controller.h']
        """
        return export.export_c(self, directory, name)

    # -- reports --------------------------------------------------------------------------------------
    def summary(self) -> str:
        """A readable account of the design (equilibrium, structure, law)."""
        s, a = self.system, self.assignment
        lines = [f"IDA-PBC controller for {s.name!r}" + (f" (the model {self.original.name!r} without "
                 f"{', '.join(self.neglected)})" if self.neglected else "")]
        lines.append("  target: " + ", ".join(f"{t.name} = {t.value:g} {t.unit}".rstrip() for t in self.targets)
                     + "; equilibrium input " + ", ".join(f"{nm} = {v:.6g} {s.inputs[j].unit}"
                                                          for nm, v, j in zip(self.input_names, self.u_star, self.ctrl)))
        ol = a.open_loop_eigenvalues
        if ol.size:
            lines.append(f"  open loop at x*: slowest mode {ol[np.argmax(ol.real)]:.4g} 1/s; "
                         f"{'stable' if np.all(ol.real < 0) else 'UNSTABLE'}")
        lines.append(f"  structure: {self.structure.kind}")
        lines += [f"    - {t}" for t in self.structure.notes]
        for p in self.structure.pdes:
            lines.append(f"    - PDE in {', '.join(p['variables'])}: {p['method']}"
                         + (f" ({p['reason']})" if p.get("reason") else ""))
        for u in self.structure.unsolved:
            lines.append(f"    ! unsolved: {u}")
        if self.integral:
            lines.append(f"  integral action: {self.integral}, K_i = {np.array2string(self.K_i, precision=4)}")
        lines.append(f"  law: CasADi function {self.law_function.name()!r}(x[{s.name} states], xi[{self.n_xi}]) -> "
                     f"u[{', '.join(self.input_names)}]")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    def __repr__(self) -> str:
        return (f"Controller({self.system.name!r}, target={self.target}, u*={np.round(self.u_star, 6).tolist()}, "
                f"structure={self.structure.kind!r}, integral={self.integral!r})")

    def to_dict(self) -> dict:
        """JSON-ready description of the design."""
        s = self.system
        return {
            "system": s.name, "original": self.original.name, "neglected": list(self.neglected),
            "model_hash": s.model_hash(), "target": self.target,
            "inputs": self.input_names, "fixed_inputs": {s.input_names[j]: float(self.u_base[j])
                                                         for j in range(len(s.inputs)) if j not in self.ctrl},
            "u_star": dict(zip(self.input_names, map(float, self.u_star))),
            "x_star": dict(zip(s.state_names, map(float, self.x_star))),
            "structure": {"kind": self.structure.kind, "notes": list(self.structure.notes),
                          "unsolved": list(self.structure.unsolved), "pdes": list(self.structure.pdes),
                          "coupling": [list(c) for c in self.structure.coupling],
                          "coefficients": dict(self.structure.coefficients), "H_a": sp.sstr(self.structure.H_a)[:2000],
                          "phi_implicit": self.phi_implicit},
            "damping": self.damping, "integral": self.integral, "K_i": self.K_i.tolist(),
            "params": {k: float(v) for k, v in zip(s.param_names, self.num.p)},
        }
