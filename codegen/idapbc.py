"""IDA-PBC: interconnection and damping assignment passivity-based control of a PHSystem.

``ctrl = idapbc.design(sys, target={"tip": 0.03})`` assigns the equilibrium at
which the target holds, chooses the desired structure ``J_d = J + J_a``,
``R_d = R + R_a`` and energy ``H_d = H + H_a``, solves the matching equations
(Ortega, van der Schaft, Maschke, Escobar, Automatica 2002)::

    g_perp(x) [ (J_d - R_d) dH_d/dx - (J - R) dH/dx ] = 0

and returns the control law ``u = g^+ [(J_d - R_d) dH_d/dx - (J - R) dH/dx]`` as a
CasADi function (exportable to C), optionally with integral action, together
with its certificates (:meth:`Controller.certify`) and closed-loop simulation
with plant/controller mismatch (:meth:`Controller.simulate`).

Steps
-----
1. *Equilibrium assignment* (:mod:`codegen._idapbc_target`): the state ``x*``
   and constant input ``u*`` at rest with the targets met, on the leaf of the
   conserved quantities through ``x0``, or an :class:`~phs.errors.EquilibriumError`
   saying why none exists (an input beyond its declared range, the validity
   domain, a fold of the branch).
2. *Structure and matching* (:mod:`codegen._idapbc_match`): ``"ansatz"``
   (polynomial basis reduced to linear equations) for inputs acting on
   momenta; ``"electromechanical"`` when the inputs reach only storages with
   quadratic energy (charges): the actuated efforts are held where ``u*`` would
   hold them for every configuration, and a momentum-charge coupling in ``J_d``
   and ``R_d`` matches the mechanical rows when that depends on the
   configuration.  Damping injection ``R_a += r g g^T`` is always matched.
3. *Integral action* (optional): ``"passive"`` integrates the passive output
   ``y_d = g^T dH_d/dx`` (``u -= K_i xi``; the closed loop stays port-Hamiltonian
   with ``H_d + xi^T K_i xi / 2``; rejects disturbances entering through the
   input, such as the retained charge of a neglected drift branch);
   ``"output"`` integrates the target error (``u += K_i xi``; removes any
   steady-state error, including unmatched parameter mismatch, certified by
   its linearisation).

Storages can be left out of the design (``neglect=["seg*.Q1"]``: the curling
HASEL's charge-retention capacitor shorted); the controller then ignores them
and the plant keeps them.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
>>> float(ctrl.u_star[0]), [round(float(v), 6) for v in ctrl.law([0.0, 0.5])]   # at rest at x*: u = u* = k q*
(2.0, [2.0])
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np
import sympy as sp

from codegen._idapbc_leaf import Leaf
from codegen._idapbc_match import Structure, ansatz, electromechanical, electromechanical_applies, quadratic_basis
from codegen._idapbc_model import Numeric, input_vector, match_names, neglect_states
from codegen._idapbc_target import assign, resolve_targets
from codegen.translate import Translator
from phs.errors import InputDataError, ModelError
from phs.io import write_atomic
from phs.params import c_identifier
from phs.system import PHSystem

__all__ = ["design", "Controller"]

_STRUCTURES = ("auto", "ansatz", "electromechanical")
_INTEGRAL = (None, "passive", "output")


def _state_vector(system, x0, what="x0", ignore=()) -> np.ndarray:
    base = np.array([min(max(0.0, st.range[0]), st.range[1]) for st in system.states])
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
                base[system.state_names.index(k)] = float(v)
            except (TypeError, ValueError):
                raise InputDataError(f"{what}: value {v!r} of state {k!r} is not a number") from None
        if not np.all(np.isfinite(base)):
            raise InputDataError(f"{what}: a value is not finite")
        return base
    arr = np.asarray(x0, dtype=float).reshape(-1)
    if arr.shape != base.shape or not np.all(np.isfinite(arr)):
        raise InputDataError(f"{what}: expected {base.size} finite values for {system.name!r}, got {arr.size}")
    return arr


def _number(value, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputDataError(f"{what} must be a number, got {value!r}") from None
    if not (np.isfinite(v) and v >= 0):
        raise InputDataError(f"{what} must be a finite number >= 0, got {value!r}")
    return v


def _kernel_complement(M: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rows spanning the complement of the kernel of ``M diag(1/s)`` (scaled coordinates)."""
    Ms = (M / s[:, None]) / s[None, :]
    _, sv, Vt = np.linalg.svd(Ms)
    r = int(np.sum(sv > 1e-12 * (sv[0] if sv.size and sv[0] > 0 else 1.0)))
    return Vt[:r]


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
        ``{"seg1.l_p": 0.015, ...}``); default zero clipped into the states' ranges.
    params : dict, optional
        Parameter values of the controller's model (overrides).
    neglect : sequence of str
        Storages left out of the design (names or globs such as ``"seg*.Q1"``; see the module docstring).
    structure : {"auto", "ansatz", "electromechanical"}
        How the matching equations are solved (see :mod:`codegen._idapbc_match`).
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
    xs0 = _state_vector(system, x0, ignore=removed)
    bad = num.violated(xs0, u_base)
    if bad:
        raise InputDataError(f"x0 is outside the validity domain of {system.name!r}: {'; '.join(bad)} "
                             "(give a state on the leaf to regulate on, e.g. the actuator at rest)")
    leaf = Leaf(num.struct_function, num.scale, xs0)
    asg = assign(num, leaf, targets, ctrl, u_base, xs0)
    if d_state is not None:  # added dissipation on one row at x*: r g_i(x*)^2 = value
        if d_state not in system.state_names:
            raise InputDataError(f"damping: system {system.name!r} has no state {d_state!r}")
        i = system.state_names.index(d_state)
        gi = np.asarray(_numeric_matrix((system.G - system.P).xreplace(
            {q.symbol: sp.Float(v) for q, v in zip(system.params, num.p)}), system.x, asg.x), dtype=float)[i, ctrl]
        if not np.any(gi):
            raise InputDataError(f"damping on {d_state!r}: the controlled inputs do not act on its row")
        r = r / float(gi @ gi)
    return _build(original, system, removed, num, leaf, targets, ctrl, u_base, xs0, asg, structure, r,
                  dict(stiffness or {}), H_a, unknowns, J_a, R_a, integral, integral_time, integral_gain, params)


def _build(original, system, removed, num, leaf, targets, ctrl, u_base, xs0, asg, structure, r, stiffness, H_a,
           unknowns, J_a, R_a, integral, integral_time, integral_gain, params) -> Controller:
    n = num.n
    vals = {q.symbol: sp.Float(v) for q, v in zip(system.params, num.p)}
    x = system.x
    JR = (system.J - system.R).xreplace(vals)
    Gm = (system.G - system.P).xreplace(vals)
    g = Gm.extract(list(range(n)), ctrl)
    fixed = [j for j in range(len(system.inputs)) if j not in ctrl]
    f_fix = (Gm.extract(list(range(n)), fixed) * sp.Matrix([sp.Float(u_base[j]) for j in fixed])) if fixed \
        else sp.zeros(n, 1)
    for nm in stiffness:
        if nm not in system.state_names:
            raise InputDataError(f"stiffness: system {system.name!r} has no state {nm!r}")
    Ja = sp.zeros(n, n) if J_a is None else sp.Matrix(J_a).xreplace(vals)
    Ra = sp.zeros(n, n) if R_a is None else sp.Matrix(R_a).xreplace(vals)
    if Ja.shape != (n, n) or Ra.shape != (n, n):
        raise InputDataError(f"J_a and R_a must be {n} x {n} matrices")
    H = sp.Add(*[t.expr for t in system.energy_terms]).xreplace(vals)
    kind = structure
    why = ""
    if structure in ("auto", "electromechanical"):
        ok, why = electromechanical_applies(JR, g, H, x)
        if structure == "electromechanical" and not ok:
            raise InputDataError(f"the electromechanical construction does not apply to {system.name!r}: {why}")
        if H_a is not None or J_a is not None or R_a is not None:
            ok = False
            why = "an explicit H_a, J_a or R_a was given"
        kind = "electromechanical" if ok else "ansatz"
    if kind == "electromechanical":
        unmatched = _check_matched_stiffness(g, JR, stiffness, system, x, asg.x, num.scale)
        if unmatched:
            raise InputDataError(unmatched)
        st = electromechanical(JR, g, f_fix, H, x, asg.x, list(asg.u[ctrl]), stiffness, system.state_names)
    else:
        Jd = system.J.xreplace(vals) + Ja
        Rd = system.R.xreplace(vals) + Ra
        Mx = _numeric_matrix(Jd - Rd - r * g * g.T, x, asg.x)
        P = _kernel_complement(Mx, num.scale)
        basis = labels = None
        if H_a is None:
            basis, labels = quadratic_basis(x, asg.x, system.state_names)
        user = None
        if H_a is not None:
            user = sp.sympify(H_a).xreplace(vals)
            if unknowns is None:  # the symbols that are neither states nor parameters
                unknowns = sorted(user.free_symbols - set(x), key=str)
        st = ansatz(Jd, Rd, Ja, Ra, g, f_fix, H, x, asg.x, num.scale, system.state_names, basis=basis, labels=labels,
                    user_Ha=user, unknowns=unknowns, stiffness=stiffness, kernel=P)
        if why and structure == "auto":
            st.notes.insert(0, f"ansatz (electromechanical construction not applicable: {why})")
    if r:
        st.R_a = st.R_a + r * g * g.T
        st.notes.append(f"damping injection R_a += r g g^T with r = {r:g}")
    ctrl_obj = Controller(original=original, system=system, neglected=tuple(removed), num=num, leaf=leaf,
                          targets=tuple(targets), ctrl=tuple(ctrl), u_base=u_base, x0=xs0, assignment=asg,
                          structure=st, damping=r, g=g, f_fix=f_fix, params=dict(params or {}), integral=None,
                          K_i=np.zeros((0, 0)))
    if integral is not None:
        ctrl_obj = ctrl_obj.with_integral(integral, time=integral_time, gain=integral_gain)
    return ctrl_obj


def _numeric_matrix(Msym: sp.Matrix, x, xv) -> np.ndarray:
    return np.array(Msym.xreplace(dict(zip(x, map(sp.Float, xv)))).evalf(), dtype=float)


def _check_matched_stiffness(g, JR, stiffness, system, x, xv, scale) -> str:
    """Stiffness on actuated storages is matched only if (J - R)_AA K stays in the span of g_A everywhere."""
    if not stiffness:
        return ""
    from codegen._idapbc_match import actuated_split

    A, _ = actuated_split(g)
    names = system.state_names
    bad_not_a = [nm for nm in stiffness if names.index(nm) not in A]
    if bad_not_a:
        return (f"stiffness on {', '.join(map(repr, bad_not_a))}: the electromechanical construction shapes only the "
                f"actuated storages ({', '.join(names[i] for i in A)}); the others keep the plant's energy")
    K = np.zeros((len(A), len(A)))
    for nm, k in stiffness.items():
        K[A.index(names.index(nm)), A.index(names.index(nm))] = k
    JRAA = JR.extract(A, A)
    gA = g.extract(A, list(range(g.cols)))
    f = sp.lambdify([x], [JRAA, gA], "numpy")
    rng = np.random.default_rng(1)
    for _ in range(8):
        pt = np.asarray(xv) + 0.2 * scale * rng.uniform(-1, 1, len(x))
        with np.errstate(all="ignore"):
            Mv, gv = (np.asarray(a, dtype=float) for a in f(pt))
        if not (np.all(np.isfinite(Mv)) and np.all(np.isfinite(gv))):
            continue
        Q, _ = np.linalg.qr(gv.reshape(len(A), -1))
        resid = (np.eye(len(A)) - Q @ Q.T) @ Mv @ K
        if np.max(np.abs(resid)) > 1e-9 * max(np.max(np.abs(Mv @ K)), 1e-300):
            return (f"stiffness on {', '.join(map(repr, stiffness))} is not matched: with one input along g(x), "
                    "(J - R)_AA K (x_A - x_A*) leaves the span of g_A(x) as the configuration changes")
    return ""


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
            cache = _functions(self)
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
        >>> round(float(ctrl.law([1.0, 0.5])[0]), 9)   # u = k q* - k_a (q - q*) - r p/m
        0.0
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
            from codegen._idapbc_cert import closed_loop_modes, static_gain

            if time is None:
                ev = closed_loop_modes(base)
                slow = np.min(np.abs(ev.real)) if ev.size and np.all(ev.real < 0) else 1.0
                time = 5.0 / slow
            if not (np.isfinite(time) and time > 0):
                raise InputDataError(f"integral_time must be a positive number, got {time!r}")
            if kind == "output":
                sens = np.atleast_2d(self.assignment.sensitivity)
                K = np.linalg.pinv(sens) / time
            else:
                Gdc, ref = static_gain(base, with_reference=True)
                if not np.all(np.isfinite(Gdc)) or np.min(np.abs(np.linalg.svd(Gdc, compute_uv=False))) <= 1e-8 * ref:
                    raise InputDataError("the passive output does not respond statically to the input here "
                                         "(no dissipation along g at x*): give integral_gain")
                K = np.linalg.inv(Gdc) / time
        out = replace(base, integral=kind, K_i=K)
        out.__dict__.pop("_cache", None)
        return out

    # -- workflows ----------------------------------------------------------------------------------
    def certify(self, **kw):
        """Certificates with numbers; see :func:`codegen._idapbc_cert.certify`.

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
        >>> ctrl.certify(rays=8, simulations=2).passed
        True
        """
        from codegen._idapbc_cert import certify

        return certify(self, **kw)

    def simulate(self, t, **kw):
        """Closed-loop simulation; see :func:`codegen._idapbc_sim.simulate_closed_loop`.

        Examples
        --------
        >>> import numpy as np
        >>> from systems.examples import mass_spring_damper
        >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
        >>> res = ctrl.simulate(np.linspace(0, 10, 101))
        >>> round(float(res["position"][-1]), 4)
        0.5
        """
        from codegen._idapbc_sim import simulate_closed_loop

        return simulate_closed_loop(self, t, **kw)

    def export_c(self, directory, name: str | None = None) -> list[str]:
        """Write the control law as a standalone C source and header (CasADi code generation).

        The files define ``{name}_law`` (inputs ``x`` and ``xi``, output ``u``, the controller's parameters
        compiled in) with CasADi's calling convention and work-size functions, plus
        ``{name}_passive_output`` and ``{name}_hd``; nothing but ``<math.h>`` is needed to compile them.

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
        directory = os.fspath(directory)
        if not os.path.isdir(directory):
            parent = os.path.dirname(os.path.abspath(directory))
            if not os.path.isdir(parent):
                raise InputDataError(f"cannot export into {directory!r}: directory {parent!r} does not exist")
            os.makedirs(directory, exist_ok=True)
        base = name or f"{self.name}_controller"
        fx = self._fx
        with tempfile.TemporaryDirectory() as tmp:
            cg = ca.CodeGenerator(f"{base}.c", {"with_header": True, "casadi_real": "double", "casadi_int": "long long int"})
            cg.add(fx["law"])
            cg.add(fx["yd_xi"])
            cg.add(fx["Hd_export"])
            cg.generate(tmp + os.sep)
            paths = []
            head = self._c_comment()
            for ext in (".c", ".h"):
                with open(os.path.join(tmp, base + ext), encoding="utf-8") as fh:
                    text = head + fh.read()
                path = os.path.join(directory, base + ext)
                paths.append((path, text))
        for path, text in paths:
            write_atomic(path, text)
        return [p for p, _ in paths]

    def _c_comment(self) -> str:
        s = self.system
        lines = [f"IDA-PBC control law for {s.name} (model hash {s.model_hash()}), generated by phs.",
                 "",
                 f"{self.name}_law(arg, res, iw, w, mem): arg[0] = x[{len(s.states)}], arg[1] = xi[{self.n_xi}], "
                 f"res[0] = u[{len(self.ctrl)}]",
                 "  x:  " + ", ".join(f"{nm} [{st.unit}]" for nm, st in zip(s.state_names, s.states)),
                 "  u:  " + ", ".join(f"{nm} [{s.inputs[j].unit}]" for nm, j in zip(self.input_names, self.ctrl)),
                 "  target: " + ", ".join(f"{t.name} = {t.value:.17g} {t.unit}" for t in self.targets)]
        if self.integral == "passive":
            lines.append(f"  xi: integral of {self.name}_passive_output(x) (xi' = y_d); u = u_IDA(x) - K_i xi")
        elif self.integral == "output":
            lines.append("  xi: integral of the target error (xi' = target - y(x)); u = u_IDA(x) + K_i xi")
        lines.append(f"{self.name}_passive_output(x) -> y_d = g(x)^T dH_d/dx;  {self.name}_hd(x) -> explicit part of H_d")
        lines.append("Controller parameters are compiled in: " + ", ".join(
            f"{k}={v:.17g}" for k, v in zip(s.param_names, self.num.p)))
        body = "\n".join(" * " + ln if ln else " *" for ln in lines)
        return "/*\n" + body + "\n */\n"

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


def _functions(ctrl: Controller) -> dict:
    """CasADi functions of the controller: law, passive output, H_d (explicit part), v, closed-loop rhs."""
    s, num = ctrl.system, ctrl.num
    fn = num.fn
    sx = fn.sx
    n = num.n
    X = ca.SX.sym("x", n)
    P = ca.DM(num.p)
    sub = lambda e: ca.substitute(ca.substitute(e, sx["p"], P), sx["x"], X)  # noqa: E731
    u_fix = ca.DM(ctrl.u_base)
    H = sub(sx["H"])
    dH = sub(sx["dH"])
    J, R, G, Pm = (sub(sx[k]) for k in ("J", "R", "G", "P"))
    Gm = G - Pm
    ctrl_idx = list(ctrl.ctrl)
    fixed = [j for j in range(num.m) if j not in ctrl_idx]
    g = Gm[:, ctrl_idx]
    f0 = ca.mtimes(J - R, dH) + (ca.mtimes(Gm[:, fixed], u_fix[fixed]) if fixed else 0)
    tr = Translator({xi: X[i] for i, xi in enumerate(s.x)})
    st = ctrl.structure
    Ha = tr(st.H_a) if st.H_a != 0 else ca.SX(0)
    v = tr(st.v) if st.v is not None else ca.SX.zeros(n, 1)
    dHd = dH + ca.gradient(Ha, X) + v
    Jd = J + tr(st.J_a)
    Rd = R + tr(st.R_a)
    target = ca.mtimes(Jd - Rd, dHd)
    u_c = ca.solve(ca.mtimes(g.T, g), ca.mtimes(g.T, target - f0))
    yd = ca.mtimes(g.T, dHd)
    nxi = ctrl.n_xi
    Xi = ca.SX.sym("xi", nxi)
    ystar = ca.DM([t.value for t in ctrl.targets])
    if ctrl.integral == "passive":
        u_law = u_c - ca.mtimes(ca.DM(ctrl.K_i), Xi)
        xi_rate = yd
    elif ctrl.integral == "output":
        u_law = u_c + ca.mtimes(ca.DM(ctrl.K_i), Xi)
        xi_rate = ystar - _target_sx(ctrl, X, _full_u(num.m, ctrl_idx, u_law, u_fix), sub)
    else:
        u_law = u_c
        xi_rate = ca.SX(0, 1)
    u_full = _full_u(num.m, ctrl_idx, u_law, u_fix)
    xdot = ca.substitute(ca.substitute(sx["xdot"], sx["p"], P), ca.vertcat(sx["x"], sx["u"]), ca.vertcat(X, u_full))
    name = ctrl.name
    out = {
        "law": ca.Function(f"{name}_law", [X, Xi], [u_law], ["x", "xi"], ["u"]),
        "u_full": ca.Function("u_full", [X, Xi], [u_full]),
        "yd": ca.Function("yd", [X], [yd]),
        "yd_xi": ca.Function(f"{name}_passive_output", [X], [yd], ["x"], ["y_d"]),
        "xi_rate": ca.Function("xi_rate", [X, Xi], [xi_rate]),
        "Hd": ca.Function("Hd", [X], [H + Ha]),
        "Hd_export": ca.Function(f"{name}_hd", [X], [H + Ha], ["x"], ["H_d_explicit"]),
        "dHd": ca.Function("dHd", [X], [dHd]),
        "v": ca.Function("v", [X], [v]),
        "target": ca.Function("target", [X], [target]),
        "plant": ca.Function("plant", [X, Xi], [xdot]),
        "Rd": ca.Function("Rd", [X], [Rd]),
        "Jd": ca.Function("Jd", [X], [Jd]),
        "g": ca.Function("g", [X], [g]),
        "f0": ca.Function("f0", [X], [f0]),
        "u_c": ca.Function("u_c", [X], [u_c]),
    }
    aug = ca.vertcat(xdot, xi_rate)
    Z = ca.vertcat(X, Xi)
    out["cl_jac"] = ca.Function("cl_jac", [X, Xi], [ca.jacobian(aug, Z)])
    out["hess"] = ca.Function("hessian_hd", [X], [ca.jacobian(dHd, X)])
    out["yd_jac"] = ca.Function("yd_jac", [X], [ca.jacobian(yd, X)])
    return out


def _full_u(m, ctrl_idx, u_c, u_fix):
    parts = []
    k = 0
    for j in range(m):
        if j in ctrl_idx:
            parts.append(u_c[ctrl_idx.index(j)])
            k += 1
        else:
            parts.append(u_fix[j])
    return ca.vertcat(*parts) if parts else ca.SX(0, 1)


def _target_sx(ctrl, X, u, sub):
    """The targets as SX of the design state (and input, for measured outputs that use it)."""
    sx = ctrl.num.fn.sx
    meas = ca.substitute(ca.substitute(sx["measured"], sx["p"], ca.DM(ctrl.num.p)), ca.vertcat(sx["x"], sx["u"]),
                         ca.vertcat(X, u)) if ctrl.system.measured else ca.SX(0, 1)
    parts = [X[t.index] if t.kind == "state" else meas[t.index] for t in ctrl.targets]
    return ca.vertcat(*parts)
