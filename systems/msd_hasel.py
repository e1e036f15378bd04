"""Expanding folded HASEL as a nonlinear mass-spring-damper, and platforms of several of them.

Source: Hainsworth, Schmidt, Sundaram, Whiting, Keplinger, MacCurdy, "Simulating
electrohydraulic soft actuator assemblies via reduced order modeling" (eqs. 3-12,
Figs. 2-9).  Built only from :mod:`components` and :func:`phs.interconnect`.

Symbols (paper -> model): ``x`` actuator displacement from rest (state ``x`` [m],
positive = extension), ``m`` moving mass (``m``), ``b`` damping (``b``), ``tau``
torsional restoring constant (``tau``), ``V`` applied voltage (input ``V`` [V]),
``l_material`` material force (eq. 8), ``l_volt`` voltage force (eq. 10), ``f_b``
body force (gravity ``g``), ``f_s`` surface force (input ``F_load``).  The
coefficients of the two fits have no printed symbols; they are named
``A_m{i}, c_m{i}, s_m{i}`` (amplitude, centre, width of Gaussian i of eq. 8) and
``a_v{i}, f_v{i}, c_v{i}, s_v{i}`` (voltage slope, offset, centre, width of eq. 10).

Equations as implemented (single actuator, :func:`msd_hasel`), with ``X = 100 x``
the displacement in cm (``X = 1000 x`` in mm with ``fit_length="mm"``) and
``U = V / 1000`` the voltage in kV (the units of the printed fits; forces in N)::

    l_material(x) = sum_i A_m{i} exp(-((X - c_m{i}) / s_m{i})**2)            (eq. 8)
    l_volt(x, V)  = sum_i (a_v{i} U + f_v{i}) exp(-((X - c_v{i}) / s_v{i})**2) (eq. 10)
                  = F_0(x) + beta(x) V,   beta(x) = sum_i a_v{i} exp(...) / 1000  [N/V]
    H = p**2/(2 m) - int_0^x l_material - int_0^x F_0 + m g x                 (erf terms)
    x' = p/m
    p' = l_material(x) + F_0(x) - m g - b p/m + beta(x) V - F_load             (eqs. 3, 4, 6)

Port-Hamiltonian form of the voltage force: ``l_volt`` is affine in V, so it splits
into a conservative part ``F_0(x) = l_volt(x, 0)`` (an energy term, like the
material spring) and an input map ``g(x) = beta(x)``: a modulated transformer of
modulus ``-beta(x)`` between the actuator's velocity port and a voltage source.
The force on the mass is ``beta(x) V`` and the source's conjugate output is the
current ``V.i = beta(x) x'`` [A], so ``V * V.i`` is exactly the mechanical power of
the voltage force (an ideal electromechanical transducer without electrical
storage; the paper neglects the electrical dynamics, Fig. 7).  Energy balance:
``dH/dt = -b (p/m)**2 + V V.i + F_load F_load.v``.

Deviations and choices (each discussed in ``docs/systems/msd_hasel.md``):

* Units: eqs. 8 and 10 take V in kV and give N; the unit of x is not printed and is an
  option, ``fit_length="cm"`` (default, chosen by the scale of the platform's motion and
  Fig. 7's rise) or ``"mm"`` (the literal reading of the paper's other lengths).  States and
  inputs are SI (``x`` in m, ``p`` in kg*m/s, ``V`` in volts); the expressions convert with
  ``X = 100 x`` (``1000 x`` in mm) and ``U = V/1000``.  The fit coefficients keep the printed values in
  the printed units (``N/kV``, ``N``, and ``fit_length`` for the centres and widths).
* Eq. 10 prints ``e^{+((x-0.11)/0.11)^2}`` and ``e^{+((x-2.5)/0.2)^2}``: the minus
  signs of the Gaussians are restored (the surface of Fig. 6 is bounded).  The third
  term is subtracted in print; here it is written with ``a_v3 = -1.80`` N/kV and
  ``f_v3 = -4.60`` N so that the three terms have one form.
* Signs: eq. 4 writes the restoring forces with a plus sign; here the material force
  pushes the actuator open (``l_material > 0``, the measured compressive load) and
  gravity and ``F_load`` (a compressive force, positive pushing down) close it.
* Load: ``l_material`` is positive everywhere (1.66 N at x = 0, a wall of centre
  -0.69 mm that reaches 4.4 N, the paper's safe compressive load, near x = -0.02 mm),
  so a load is part of the model: the default mass ``m = 0.05 kg`` is the share of
  the reference platform's two 75 g plates carried by one bottom-stage actuator (the
  paper gives neither the actuator's nor the platform's mass) and weighs 0.49 N.
  With it the static displacement grows monotonically from 0.29 mm at 0 kV to
  9.0 mm at 5 kV (fits read in cm; a tenth of that in mm), with a single equilibrium
  up to 6 kV (steepest near 0.25 kV);
  loads above about 0.65 N make the quasi-static curve fold (two stable
  equilibria, snap-through) between 0.4 and 1 kV.
* Validity: the input map ``beta(x)`` changes sign at x = 1.785 fit units (17.85 mm in
  cm; beyond it the fit says the voltage pulls the actuator closed: the third Gaussian,
  centred at 2.5 units, acts as a stroke limit); the condition ``beta(x) >= 0`` is checked
  at run time, as is ``X >= c_m1`` (the centre of the compression wall, -0.69 units,
  beyond which the fitted force decreases again).
* Damping: ``b = 1 kg/s`` as printed (tuned by the authors for simulation speed).  With
  the 50 g load the actuator is underdamped (damping ratio 0.06-0.2 in cm, 0.02-0.06 in
  mm); a voltage step of more than about 3 kV (2 kV in mm) from rest overshoots past the
  input map's zero and the simulation stops with a :class:`phs.DomainError`; 1 kV
  staircases stay inside, as does a 5 kV step with ``b = 10 kg/s``.  Fig. 7's unloaded
  first-order rise (about 17 ms): with the printed b and the few grams of an unloaded
  actuator (``m = 0.002``) the cm reading rises without overshoot, in 54 to 7.6 ms
  (10-90 %) from 1 to 5 kV; in mm no mass gives a first-order rise slower than a few
  milliseconds (docs, "Damping and Fig. 7").
* ``tau``: eq. 4's ``tau theta`` is a Hookean torsional spring on the angular
  displacement ``theta`` of the actuator from rest.  A single actuator loaded along
  its axis does not rotate, so ``theta = 0`` and the term vanishes here; it acts in
  :func:`hasel_platform`, where ``theta`` is the bending of an actuator between its
  two tilting end plates.  The printed unit kg*m/s**2 lacks the metre of a torque per
  radian: ``tau`` is taken as 1 N*m/rad about each horizontal axis.
* The paper's actuator dynamics (eq. 6) have no inertia of their own: the moving mass
  is the carried platform (Fig. 2's two point masses are the attachment points).
* The conservative part ``F_0`` of eq. 10 has no storage of its own; it is the energy
  term of a stateless component (:class:`components.Potential`), not part of the material
  spring, so that the material spring is exactly eq. 8.
* Scale of motion: with x in mm, one actuator's 0 -> 5 kV stroke is at most 0.97 mm for
  any load up to 4.4 N, and the platform's end effector rises by 1.788 mm with all six
  actuators at 5 kV (at most 1.94 mm anywhere in the box of strokes for the chosen
  geometry), below the paper's 6.24 mm tracking error itself; in cm (the default) every
  static displacement is exactly 10 times larger (17.88 mm heave).  Fig. 7's first-order rise
  (about 17 ms, no load) is reachable with the printed b = 1 kg/s only in cm (section
  "Scale of motion" and "Damping" of the docs); the paper never prints the unit.

The platform (:func:`hasel_platform`) is described in its docstring.
"""

from __future__ import annotations

import functools

import sympy as sp

from components import (
    ConfigurationInertia,
    Damper,
    ForceSource,
    Geometry,
    Gravity,
    Mass,
    NonlinearSpring,
    Potential,
    Transformer,
    VoltageSource,
    geometric_symbol,
)
from phs import (
    Condition,
    Measured,
    Param,
    PHSystem,
    bond,
    interconnect,
    parallel,
    series,
    symbol_of_input,
    symbol_of_state,
)
from phs.errors import ModelError

MM_PER_M = sp.Integer(1000)
"""Conversion of the state x [m] to millimetres (the unit of the state ranges and scales)."""
FIT_LENGTHS = {"mm": 1000, "cm": 100}
"""Readings of the unit of x in the printed fits (eqs. 8 and 10), each with its number of units per metre."""
KV_PER_V = sp.Rational(1, 1000)
"""Conversion of the input V [V] to the printed fits' voltage U = V / 1000 [kV]."""

_MATERIAL = ((2.02e9, -0.69, 0.15), (0.12, -0.05, 0.61), (0.36, -0.39, 0.61))  # (A [N], c [mm], s [mm]), eq. 8
_VOLTAGE = ((0.49, 0.04, 0.11, 0.11), (0.66, -0.14, 0.31, 0.43), (-1.80, -4.60, 2.5, 0.2))  # (a, f, c, s), eq. 10
_FIT = [f"{k}_m{i}" for i in (1, 2, 3) for k in "Acs"] + [f"{k}_v{i}" for i in (1, 2, 3) for k in "afcs"]


def _check_fit_length(fit_length, who: str) -> str:
    if not isinstance(fit_length, str) or fit_length not in FIT_LENGTHS:
        raise ModelError(f"{who}: fit_length must be one of {sorted(FIT_LENGTHS)} (the unit of x in the printed "
                         f"fits, eqs. 8 and 10), got {fit_length!r}")
    return fit_length


def default_parameters(fit_length: str = "cm") -> dict[str, Param]:
    """The MSD HASEL's parameters: eqs. 8, 10-12 of the paper and the documented choices.

    Fit coefficients keep the printed values in the printed units (kV, N and the
    length unit ``fit_length`` of x: the centres and widths ``c_m{i}``, ``s_m{i}``,
    ``c_v{i}``, ``s_v{i}`` carry it as their unit); the others are SI.  Platform
    geometry is not printed in the paper and is chosen.

    Parameters
    ----------
    fit_length : {"cm", "mm"}
        The unit in which the printed fits read x (the paper does not print it; see
        "Scale of motion" in ``docs/systems/msd_hasel.md``).  ``"mm"`` gives the same
        force laws at a tenth of the displacements.

    Returns
    -------
    dict of str -> Param

    Raises
    ------
    ModelError
        For a ``fit_length`` other than ``"mm"`` or ``"cm"``.

    Examples
    --------
    >>> P = default_parameters()
    >>> P["A_m1"].value, P["A_m1"].unit, P["b"].value
    (2020000000.0, 'N', 1.0)
    >>> P["c_m1"].value, P["c_m1"].unit
    (-0.69, 'cm')
    >>> default_parameters("mm")["c_m1"].unit
    'mm'
    """
    unit = _check_fit_length(fit_length, "default_parameters")
    P = []
    for i, (a, c, s) in enumerate(_MATERIAL, 1):
        P += [Param(f"A_m{i}", a, "N", f"amplitude of Gaussian {i} of the material force (eq. 8)"),
              Param(f"c_m{i}", c, unit, f"centre of Gaussian {i} of the material force (eq. 8, printed x + {-c})"),
              Param(f"s_m{i}", s, unit, f"width of Gaussian {i} of the material force (eq. 8)")]
    for i, (a, f, c, s) in enumerate(_VOLTAGE, 1):
        P += [Param(f"a_v{i}", a, "N/kV", f"voltage slope of the amplitude of Gaussian {i} of the voltage force "
                                          f"(eq. 10{'; printed 1.80 with the term subtracted' if i == 3 else ''})"),
              Param(f"f_v{i}", f, "N", f"zero-voltage amplitude of Gaussian {i} of the voltage force "
                                       f"(eq. 10{'; printed 4.60 with the term subtracted' if i == 3 else ''})"),
              Param(f"c_v{i}", c, unit, f"centre of Gaussian {i} of the voltage force (eq. 10)"),
              Param(f"s_v{i}", s, unit, f"width of Gaussian {i} of the voltage force (eq. 10)")]
    P += [
        Param("m", 0.05, "kg", "moving mass of one actuator: its share of the platform (2 plates / 3 actuators)",
              (0.0002, 0.5)),
        Param("b", 1.0, "kg/s", "damping coefficient (eq. 11)", (0.1, 10.0)),
        Param("tau", 1.0, "N*m/rad", "torsional restoring constant of one actuator per tilt axis "
                                     "(eq. 12, printed kg*m/s**2)", (0.1, 10.0)),
        Param("g", 9.81, "m/s**2", "gravitational acceleration", (9.7, 9.9)),
        Param("m_p", 0.075, "kg", "mass of one platform plate (chosen; not printed)", (0.01, 0.5)),
        Param("r_p", 0.05, "m", "radius of a platform plate, a uniform disc (chosen; not printed)", (0.02, 0.1)),
        Param("r_a", 0.035, "m", "radius of the circle of actuator attachment points (chosen)", (0.01, 0.08)),
        Param("h_s", 0.03, "m", "height of one stage: distance between plate centres at rest (chosen)", (0.01, 0.1)),
    ]
    return {p.name: p for p in P}


def _gaussian(X, c, s):
    return sp.exp(-(((X - c) / s) ** 2))


def _per_metre(params: dict[str, Param]) -> sp.Integer:
    """Fit length units per metre, from the unit the centres and widths of eqs. 8 and 10 carry (one for all)."""
    units = {params[k].unit for k in _FIT if k[0] in "cs"}
    if len(units) != 1 or not units <= FIT_LENGTHS.keys():
        raise ModelError(f"the centres and widths of eqs. 8 and 10 must share one unit of {sorted(FIT_LENGTHS)}, "
                         f"got {sorted(units)}")
    return sp.Integer(FIT_LENGTHS[units.pop()])


def material_force(x, params: dict[str, Param]) -> sp.Expr:
    """Eq. 8: the material's restoring force [N] (pushing the actuator open) at displacement ``x`` [m].

    The fit reads x in the unit of the centres and widths in ``params`` (mm or cm,
    see :func:`default_parameters`).

    Examples
    --------
    >>> x = sp.Symbol("x", real=True)
    >>> f = material_force(x, default_parameters())
    >>> P = {p.symbol: p.value for p in default_parameters().values()}
    >>> round(float(f.subs(P).subs(x, 0)), 4)
    1.6636
    """
    S = {k: p.symbol for k, p in params.items()}
    X = _per_metre(params) * x
    return sp.Add(*[S[f"A_m{i}"] * _gaussian(X, S[f"c_m{i}"], S[f"s_m{i}"]) for i in (1, 2, 3)])


def voltage_force_terms(x, params: dict[str, Param]) -> tuple[sp.Expr, sp.Expr]:
    """Eq. 10 split as ``l_volt(x, V) = F_0(x) + beta(x) V``: returns ``(F_0 [N], beta [N/V])`` at ``x`` [m].

    The fit reads x in the unit of the centres and widths in ``params`` (as :func:`material_force`).

    Examples
    --------
    >>> x = sp.Symbol("x", real=True)
    >>> F0, beta = voltage_force_terms(x, default_parameters())
    >>> P = {p.symbol: p.value for p in default_parameters().values()}
    >>> round(float((F0 + 5000 * beta).subs(P).subs(x, 0)), 4)    # 5 kV at rest
    2.7952
    """
    S = {k: p.symbol for k, p in params.items()}
    X = _per_metre(params) * x
    gs = [_gaussian(X, S[f"c_v{i}"], S[f"s_v{i}"]) for i in (1, 2, 3)]
    F0 = sp.Add(*[S[f"f_v{i}"] * g for i, g in zip((1, 2, 3), gs, strict=True)])
    beta = KV_PER_V * sp.Add(*[S[f"a_v{i}"] * g for i, g in zip((1, 2, 3), gs, strict=True)])
    return F0, beta


def _fixed(value) -> sp.Expr:
    """A fixed modulus for :class:`components.Transformer` (a geometric constant, not a parameter).

    A plain number would become a fittable local parameter ``{name}.n``; an
    unevaluated product is an expression, so none is declared.
    """
    return sp.Mul(sp.sympify(value), 1, evaluate=False)


@functools.lru_cache(maxsize=16)
def _antiderivative(force: sp.Expr, variable: sp.Symbol) -> sp.Expr:
    """``int_0^variable force`` as :class:`components.NonlinearSpring` derives it (erf terms), memoized.

    Every actuator of a platform has the same force laws; sympy's integration takes
    about a second per law, so it is done once and the state symbol substituted.
    """
    return NonlinearSpring("_antiderivative", force=force, variable=variable).energy(variable)


class _Spring(NonlinearSpring):
    """:class:`components.NonlinearSpring` whose symbolic energy is shared by identical actuators."""

    def energy(self, x):
        return _antiderivative(self.force, self.variable).xreplace({self.variable: x})


def _potential_of_force(force, x) -> sp.Expr:
    """``-int_0^x force`` in closed form (Gaussians integrate to error functions)."""
    q = sp.Symbol("q", real=True)
    return -_antiderivative(force.xreplace({x: q}), q).xreplace({q: x})


def _stretch(params: dict[str, Param]) -> float:
    """Millimetres per fit length unit: 1 with x read in mm, 10 in cm (state ranges and scales grow with it)."""
    return float(MM_PER_M / _per_metre(params))


def _actuator(prefix: str, params: dict[str, Param], state: str):
    """Components of one actuator on the displacement state ``state``.

    Returns the components, the port names to put in series with the body that
    moves with ``state``, the extra connections and the validity conditions.
    """
    q = sp.Symbol("q", real=True)
    k = _stretch(params)
    x = symbol_of_state(state)
    mat = [params[k] for k in _FIT if "_m" in k]
    volt = [params[k] for k in _FIT if "_v" in k]
    F0, beta = voltage_force_terms(x, params)
    V = f"{prefix}V" if prefix else "V"
    comps = [
        _Spring(f"{prefix}k_mat", force=-material_force(q, params), variable=q, params=mat, state=state,
                range=(-0.5e-3 * k, 2.0e-3 * k), scale=1e-3 * k),
        Potential(f"{prefix}k_volt", _potential_of_force(F0, x), params=volt),
        Damper(f"{prefix}b", b=params["b"]),
        # e_a = n e_b, f_b = n f_a with n = -beta: force beta(x) V on the body, current beta(x) x' from the source
        Transformer(f"{prefix}volt", -beta, domains=("translational", "electrical")),
        VoltageSource(V, range=(0.0, 6000.0)),
    ]
    S = {k: p.symbol for k, p in params.items()}
    who = f" ({prefix[:-1]})" if prefix else ""
    c_m1 = params["c_m1"]
    conds = [
        Condition(f"input map beta(x) >= 0{who}", beta,
                  f"the voltage force's input map keeps its sign (x below its zero, {1.785 * k:g} mm for the "
                  f"printed coefficients read in {c_m1.unit})"),
        Condition(f"x above the centre of the compression wall{who}", _per_metre(params) * x - S["c_m1"],
                  f"x >= c_m1 ({c_m1.value:g} {c_m1.unit}): beyond it the fitted material force decreases again"),
    ]
    return comps, [f"{prefix}k_mat", f"{prefix}b", f"{prefix}volt.a"], [bond(f"{prefix}volt.b", V)], conds


def _parameters(overrides: dict, who: str, used, fit_length) -> dict[str, Param]:
    """Default parameters for ``fit_length`` with ``overrides`` (which win); names the model does not use are rejected."""
    base = default_parameters(_check_fit_length(fit_length, who))
    unknown = [k for k in overrides if k not in used]
    if unknown:
        raise ModelError(f"{who}: unknown or unused parameter(s) {unknown}; {who} uses: {sorted(used)}")
    for k, v in overrides.items():
        base[k] = base[k].with_value(v)
    return base


def _suffix(fit_length: str) -> str:
    """Model name suffix: none for the default reading (cm), ``_mm`` for the other."""
    return "" if fit_length == "cm" else f"_{fit_length}"


def _reading(fit_length: str) -> str:
    return "" if fit_length == "cm" else f", fits read with x in {fit_length}"


def msd_hasel(*, load: bool = True, fit_length: str = "cm", **overrides: float) -> PHSystem:
    """One expanding folded HASEL carrying a mass: the nonlinear mass-spring-damper of eqs. 3-12.

    States ``x`` (displacement from rest, m, positive = extension) and ``p``
    (momentum of the carried mass, kg*m/s); inputs ``V`` (applied voltage, volts) and
    ``F_load`` (external compressive force on the mass, N); port outputs ``V.i``
    (``beta(x) x'``, A) and ``F_load.v`` (velocity in the direction of the load, m/s);
    measured outputs ``displacement`` [m], ``force_material`` and ``force_voltage`` [N].

    Parameters
    ----------
    load : bool
        Include the weight ``m g`` of the carried mass (the documented preload).
    fit_length : {"cm", "mm"}
        Unit in which the printed fits (eqs. 8 and 10) read x, which the paper does not
        print.  ``"cm"`` (default) gives strokes up to about 1 cm, the scale of the paper's
        platform; ``"mm"`` the same force laws at exactly a tenth of the displacements (see
        "Scale of motion" in ``docs/systems/msd_hasel.md``).  The centres and widths
        carry this unit, so overrides of them are read in it.  The model is named
        ``msd_hasel`` in cm and ``msd_hasel_mm`` in mm.
    **overrides : float
        Parameter values by name (``b=2.0``, ``m=0.03``); see :func:`default_parameters`.
        They replace the defaults of the chosen ``fit_length``.

    Returns
    -------
    PHSystem

    Raises
    ------
    ModelError
        If ``fit_length`` is not ``"mm"`` or ``"cm"``, or an override names a parameter
        this model does not use (``tau`` and the platform's geometry act only in
        :func:`hasel_platform`).

    Examples
    --------
    >>> s = msd_hasel()
    >>> s.state_names, s.input_names, s.measured_names
    (['x', 'p'], ['V', 'F_load'], ['displacement', 'force_material', 'force_voltage'])
    >>> from phs import equilibrium
    >>> round(equilibrium(s, u={"V": 5000.0}, x0={"x": 5e-3})["x"] * 1e3, 3)     # mm under 0.49 N at 5 kV
    9.016
    >>> s = msd_hasel(fit_length="mm")
    >>> round(equilibrium(s, u={"V": 5000.0}, x0={"x": 0.5e-3})["x"] * 1e3, 3)   # the same force laws read in mm
    0.902
    """
    P = _parameters(overrides, "msd_hasel", _FIT + ["m", "b"] + (["g"] if load else []), fit_length)
    x = symbol_of_state("x")
    k = _stretch(P)
    comps, members, conns, conds = _actuator("", P, "x")
    comps += [Mass("m", m=P["m"], state="p", range=(-0.025 * k, 0.025 * k), scale=1e-3 * k),
              ForceSource("F_load", range=(-5.0, 5.0)),
              # unit transformer between the mass (port a) and the load (port b): force -F_load on the mass and
              # output F_load.v = -x'
              Transformer("load_dir", _fixed(1), domains=("translational", "translational"))]
    conns += [series("m", *members, "load_dir.a"), bond("load_dir.b", "F_load")]
    if load:
        comps.append(Gravity("weight", height=x, m=P["m"], g=P["g"]))
    F0, beta = voltage_force_terms(x, P)
    V = symbol_of_input("V")
    used = [P["m"], P["b"]] + ([P["g"]] if load else [])
    return interconnect(
        "msd_hasel" + _suffix(fit_length), comps, conns, params=used, conditions=conds,
        measured=[Measured("displacement", x, "m", "actuator displacement from rest (positive = extension)"),
                  Measured("force_material", material_force(x, P), "N", "material force, eq. 8"),
                  Measured("force_voltage", F0 + beta * V, "N", "voltage force, eq. 10")],
        description="expanding folded HASEL as a nonlinear mass-spring-damper (Hainsworth et al., eqs. 3-12)"
                    + _reading(fit_length),
    )


# -- platform ------------------------------------------------------------------------------------------------


def _plate_rotation(u, w):
    """Rotation ``R_y(beta) R_x(alpha)`` with ``u = sin(alpha) cos(beta)``, ``w = sin(beta)``.

    In these coordinates the height change of a plate point (x_j, y_j) is exactly
    ``y_j u - x_j w``, so the actuator lengths are linear in (z, u, w).
    """
    C, S = sp.sqrt(1 - w**2), sp.sqrt(1 - u**2 - w**2)
    return sp.Matrix([[C, w * u / C, w * S / C], [0, S / C, -u / C], [-w, u, S]])


def _relative_angular_velocity(u, w, ud, wd):
    """Body-frame angular velocity of :func:`_plate_rotation` for rates (ud, wd)."""
    C2, S = 1 - w**2, sp.sqrt(1 - u**2 - w**2)
    return sp.Matrix([(ud * C2 + u * w * wd) / (C2 * S), wd * S / C2, -u * wd / C2])


def hasel_platform(stages: int = 2, *, fit_length: str = "cm", **overrides: float) -> PHSystem:
    """Stacked plates carried by three MSD HASELs per stage: the paper's two-stage platform (Fig. 8).

    Each stage is a rigid plate (a uniform disc of mass ``m_p`` and radius ``r_p``)
    carried by three actuators attached at 120 degrees (angles ``psi_j = 0, 120,
    240`` degrees from the x axis) on a circle of radius ``r_a`` to the plate below
    (the ground for stage 1).  A plate moves relative to the one below by a heave
    and two tilts (roll ``alpha`` about x, pitch ``beta`` about y, ``R = R_y(beta)
    R_x(alpha)``); the actuators, bonded to both plates, are taken as stiff in shear
    and twist, so surge, sway and yaw relative to the plate below are suppressed: a
    reduced-DOF model of the 3-D platform, three degrees of freedom per stage, six
    for the reference assembly.  The actuators are massless (their point masses of
    Fig. 2 are the attachment points on the plates).

    Coordinates: per stage, the heave ``z`` and the heights ``hx = -r_a sin(beta)``,
    ``hy = r_a sin(alpha) cos(beta)`` of the plate's rim points on its x and y axes
    relative to its centre (geometric variables ``s{k}.z``, ``s{k}.hx``,
    ``s{k}.hy`` [m]).  The displacement of actuator j is then exactly
    ``x_kj = z + cos(psi_j) hx + sin(psi_j) hy`` (vertical motion of its attachment
    point in the frame of the plate below), so the three coordinates follow linearly
    from the three actuator displacements ``s{k}.a{j}.x`` (the states of the
    material springs) and, conversely, each actuator's velocity is the sum of the
    plate velocities through transformers of fixed moduli ``1, cos(psi_j),
    sin(psi_j)``.  Plate k's pose is ``R_k = R_{k-1} R(alpha_k, beta_k)``,
    ``c_k = c_{k-1} + R_{k-1} (0, 0, h_s + z_k)``; its kinetic energy
    ``m_p |c_k'|**2/2 + Omega_k^T I Omega_k/2`` gives the inertia matrix M of a
    :class:`components.ConfigurationInertia` on the plates' coordinates (momenta
    ``s{k}.p_z``, ``s{k}.p_hx``, ``s{k}.p_hy``; never inverted symbolically).

    Per actuator: material spring (eq. 8), conservative voltage force and damper in
    series, driven by its voltage through the input-map transformer (eq. 10), as in
    :func:`msd_hasel`; its force reaches the plates through the three geometric
    transformers (a 0-junction: common force, velocities adding).  Gravity acts on
    both plates; the torsional restoring term of eq. 4 is
    ``3 tau (alpha_k**2 + beta_k**2)/2`` per stage (the three actuators of a stage
    bend with the relative tilt of its plate).

    Path to the full 3-D platform: give each plate six coordinates (add surge, sway,
    yaw with shear and twist springs for the actuators), or replace the vertical
    actuators by inclined legs (a Stewart platform) whose lengths are functions of
    the full pose, with modulated transformers ``d length / d pose``; the actuator
    components are unchanged, only M and the transformer moduli change.

    Parameters
    ----------
    stages : int
        Number of stacked stages (2 for the paper's platform).
    fit_length : {"cm", "mm"}
        Unit in which the printed fits read x, as in :func:`msd_hasel` (``"mm"``: a tenth
        of the actuator strokes; the model is then named ``hasel_platform{stages}_mm``).
    **overrides : float
        Parameter values by name (see :func:`default_parameters`); they replace the
        defaults of the chosen ``fit_length``.

    Returns
    -------
    PHSystem
        Inputs ``s{k}.a{j}.V`` [V]; measured outputs ``ee.x``, ``ee.y``, ``ee.z``
        (centre of the top plate, m, from the centre of the base) and ``s{k}.alpha``,
        ``s{k}.beta`` (tilts relative to the plate below, rad).

    Raises
    ------
    ModelError
        If ``stages`` is not a positive integer, ``fit_length`` is not ``"mm"`` or
        ``"cm"``, or an override names a parameter the platform does not use (``m``: the
        plates' mass is ``m_p``).

    Examples
    --------
    >>> s = hasel_platform(1)
    >>> s.state_names
    ['s1.a1.x', 's1.a2.x', 's1.a3.x', 's1.p_z', 's1.p_hx', 's1.p_hy']
    >>> s.input_names
    ['s1.a1.V', 's1.a2.V', 's1.a3.V']
    """
    if not isinstance(stages, int) or isinstance(stages, bool) or stages < 1:
        raise ModelError(f"hasel_platform: stages must be a positive integer, got {stages!r}")
    P = _parameters(overrides, "hasel_platform", _FIT + ["b", "tau", "g", "m_p", "r_p", "r_a", "h_s"], fit_length)
    S = {k: p.symbol for k, p in P.items()}
    m_p, r_a, h_s = S["m_p"], S["r_a"], S["h_s"]
    inertia = sp.diag(m_p * S["r_p"] ** 2 / 4, m_p * S["r_p"] ** 2 / 4, m_p * S["r_p"] ** 2 / 2)
    psi = [2 * sp.pi * j / 3 for j in range(3)]
    coords = [f"s{k}.{c}" for k in range(1, stages + 1) for c in ("z", "hx", "hy")]
    q = [geometric_symbol(c) for c in coords]
    n = len(q)
    comps, conns, conds, measured = [], [], [], []
    R_abs, c_abs = sp.eye(3), sp.zeros(3, 1)
    W_prev, Jc_prev = sp.zeros(3, n), sp.zeros(3, n)
    M = sp.zeros(n, n)
    rates = sp.symbols("u_rate w_rate", real=True)
    for k in range(1, stages + 1):
        z, hx, hy = q[3 * (k - 1): 3 * k]
        X = [symbol_of_state(f"s{k}.a{j}.x") for j in (1, 2, 3)]
        comps.append(Geometry(f"s{k}.pose", {
            f"s{k}.z": sp.Add(*X) / 3,
            f"s{k}.hx": sp.Rational(2, 3) * sp.Add(*[sp.cos(a) * x for a, x in zip(psi, X, strict=True)]),
            f"s{k}.hy": sp.Rational(2, 3) * sp.Add(*[sp.sin(a) * x for a, x in zip(psi, X, strict=True)]),
        }, units={c: "m" for c in coords[3 * (k - 1): 3 * k]}))
        u, w = hy / r_a, -hx / r_a
        R_rel = _plate_rotation(u, w)
        offset = R_abs * sp.Matrix([0, 0, h_s + z])  # c_k = c_{k-1} + R_{k-1} (0, 0, h_s + z_k)
        c_abs = c_abs + offset
        Jc = Jc_prev + offset.jacobian(q)
        om = _relative_angular_velocity(u, w, *rates)  # Omega_k = R_rel^T Omega_{k-1} + Omega_rel
        W_rel = om.jacobian(rates[:1]) * sp.Matrix([u]).jacobian(q) + om.jacobian(rates[1:]) * sp.Matrix([w]).jacobian(q)
        W = R_rel.T * W_prev + W_rel
        M += m_p * Jc.T * Jc + W.T * inertia * W
        R_abs, Jc_prev, W_prev = R_abs * R_rel, Jc, W
        alpha, beta = sp.asin(u / sp.sqrt(1 - w**2)), sp.asin(w)
        comps += [Gravity(f"s{k}.weight", height=c_abs[2], m=P["m_p"], g=P["g"]),
                  Potential(f"s{k}.tilt", 3 * S["tau"] * (alpha**2 + beta**2) / 2, params=[P["tau"]])]
        measured += [Measured(f"s{k}.alpha", alpha, "rad", f"roll of plate {k} relative to the plate below"),
                     Measured(f"s{k}.beta", beta, "rad", f"pitch of plate {k} relative to the plate below")]
        on_coord = {c: [f"plates.p{3 * (k - 1) + i + 1}"] for i, c in enumerate(("z", "hx", "hy"))}
        for j in (1, 2, 3):
            name = f"s{k}.a{j}"
            c, members, extra, cd = _actuator(f"{name}.", P, f"{name}.x")
            branches = []
            for coord, ratio in (("z", 1), ("hx", sp.cos(psi[j - 1])), ("hy", sp.sin(psi[j - 1]))):
                if ratio == 0:
                    continue
                c.append(Transformer(f"{name}.{coord}", _fixed(ratio), domains=("translational", "translational")))
                on_coord[coord].append(f"{name}.{coord}.a")
                branches.append(f"{name}.{coord}.b")
            comps += c
            conns += [parallel(*branches, series(*members)), *extra]
            conds += cd
        conns += [series(*members) for members in on_coord.values()]
    M = sp.Matrix(n, n, lambda i, j: M[min(i, j), max(i, j)])
    momenta = [f"s{k}.p_{c}" for k in range(1, stages + 1) for c in ("z", "hx", "hy")]
    comps.append(ConfigurationInertia("plates", coords, M, params=[P["m_p"], P["r_p"], P["r_a"], P["h_s"]],
                                      momenta=momenta, range=(-0.05 * _stretch(P), 0.05 * _stretch(P)),
                                      scale=1e-3 * _stretch(P), domain="translational"))
    measured = [Measured("ee.x", c_abs[0], "m", "end effector (centre of the top plate), x"),
                Measured("ee.y", c_abs[1], "m", "end effector (centre of the top plate), y"),
                Measured("ee.z", c_abs[2], "m", "end effector (centre of the top plate), height above the base"),
                *measured]
    return interconnect(
        f"hasel_platform{stages}{_suffix(fit_length)}", comps, conns, params=[P["b"], P["g"]], conditions=conds, measured=measured,
        description=f"{stages}-stage platform of MSD HASELs, three per stage (Hainsworth et al., Fig. 8)"
                    + _reading(fit_length),
    )
