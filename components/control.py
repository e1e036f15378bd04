"""Feedback controllers as port-Hamiltonian components: PD position loop and velocity loop.

A plant recorded under feedback is modelled as plant + known controller: the controller is a
component joined to the plant's moving body by the usual junction (``series("m", "ctrl")``:
it shares the body's velocity ``v`` and adds its force), its input is the recorded reference,
and the force it computes is a measured output, so a recorded controller output can be fitted
as one more channel.  That output is marked a computed command (``Measured.command``): diagnosis
tries drive elements (a delay, a saturation) between it and the plant
(:mod:`components.candidates.elements`).

Position loop (PD)
------------------
The controller force on the plant is ``F_c = K_p (r - x) - K_d v`` (derivative on the
measurement), or, with a reference filter of time constant ``tau``,
``F_c = K_p (r_f - x) + K_d (r_f' - v)`` with ``tau r_f' = r - r_f``.

Port-Hamiltonian form.  A position reference cannot enter as a port variable, and a storage of
the deflection ``x - r`` with energy ``K_p (x - r)**2 / 2`` would need the reference *rate* as
the input (``(x - r)' = v - r'``), which recorded references give only through numerical
differentiation.  The loop is written instead with the identity
``K_p (x - r)**2 / 2 = K_p x**2 / 2 - K_p r x + K_p r**2 / 2``: the controller stores
``K_p x**2 / 2`` (a virtual spring to the origin, state ``{name}.x`` with ``x' = v``, or the
plant's own position state when ``position=`` names it), dissipates ``K_d v**2`` (a virtual
damper to ground), and the reference acts as the force ``K_p r`` through the input map
(input ``r`` [m], power-conjugate output ``y = K_p v`` [N/s], supplied power ``K_p r v``, the
work rate of that force).  The closed-loop equations are those of the spring to the reference;
the stored energy differs by terms of the reference alone.  This needs no derivative of ``r``.

With ``tau``, the filtered reference ``r_f`` is a state driven by ``r`` alone.  Such a one-way
(signal) coupling is passive only under a storage weight: ``r_f`` stores ``k_f r_f**2 / 2`` with
``k_f = K_p + (tau K_p - K_d)**2 / (4 tau K_d)``, for which the dissipation form of the controller,
``K_d v**2 - a s v + s**2 / (tau k_f)`` in ``s = k_f r_f`` and ``a = (K_p - K_d / tau) / k_f``, is
positive definite.  It needs ``K_d > 0``.  The output is ``y = (K_d / tau) v + s / tau``.  A
recorded reference sampled at any rate is used as it is; the filter smooths its steps.

Integral action is not offered: a force ``K_i * integral(r - x) dt`` makes the controller's
velocity-to-force map ``K_d + K_p / s + K_i / s**2``, whose real part is negative below
``sqrt(K_i / K_d)`` rad/s.  No storage, definite or not, gives such a map a power balance with
``R`` positive semidefinite (over a period of a sinusoidal motion the stored energy returns to its
value while the net power supplied is negative), and indeed a mass ``m > K_p K_d / K_i`` under it
is unstable.  See ``docs/workflows/closed_loop.md``.

Velocity loop
-------------
A virtual damper ``K_v`` between the plant and a reference moving at ``r_v`` (input [m/s], a flow
source): ``F_c = K_v (r_v - v)``, dissipating ``K_v (v - r_v)**2``; the input's conjugate output
is the controller force itself.
"""

from __future__ import annotations

from numbers import Real

from components._base import require_positive
from phs.component import Component, Dissipator, Piece, Relation, Source, symbol_of_output, symbol_of_state
from phs.errors import ModelError
from phs.params import EnergyTerm, InputInfo, Measured


def _nonnegative(comp: str, key: str, value) -> None:
    if isinstance(value, Real) and not isinstance(value, bool) and value < 0:
        raise ModelError(f"component {comp!r}: parameter {key!r} must be zero or positive, got {value}")


class PositionLoop(Component):
    """PD position control: a virtual spring ``K_p`` and damper ``K_d`` pulling the plant to ``r``.

    Join its port in series with the plant's moving body.  Equations and the port-Hamiltonian
    form are in the module docstring (:mod:`components.control`).

    Parameters
    ----------
    name : str
    K_p : float, Param or expression
        Proportional gain, the virtual stiffness [N/m] (> 0).
    K_d : float, Param or expression
        Derivative gain, the virtual damping [N*s/m] (>= 0; > 0 with ``tau``).
    tau : float, Param, expression or None
        Time constant [s] of the first-order reference filter; ``None`` (default) feeds the
        reference unfiltered and takes the derivative of the measured position only.
    reference : str
        Name of the reference input [m] (default ``"r"``).
    effort : str, optional
        Name of the measured controller force [N] (default ``{name}.F``).
    position : str, optional
        Name of a plant state that is the position (its rate is the port velocity); by default
        the controller owns the position state ``{name}.x``.
    range : (float, float)
        Physical range [m] of the position and the filtered reference.
    feedforward : str, optional
        Name of an input added to the controller's output (a feedforward or test signal injected after
        the control law and recorded with it): the body feels ``F_c + feedforward_gain · u_ff`` and the
        measured ``effort`` is that sum.  Its conjugate output ``{feedforward}.v`` is
        ``feedforward_gain`` times the body's velocity.
    feedforward_gain : float or Param
        Force per unit of the feedforward input [N per its unit], the parameter ``{name}.k_ff`` (default 1:
        the input is a force).
    feedforward_unit : str
        Unit of the feedforward input (default ``"N"``).

    Examples
    --------
    >>> from phs import interconnect, series
    >>> from components import Mass
    >>> s = interconnect("servo", [Mass("m", m=2.0), PositionLoop("pd", K_p=8.0, K_d=4.0)], [series("m", "pd")])
    >>> s.state_names, s.input_names, s.measured_names
    (['m.p', 'pd.x'], ['r'], ['pd.F'])
    >>> s.G.T, s.R
    (Matrix([[pd.K_p, 0]]), Matrix([
    [pd.K_d, 0],
    [     0, 0]]))
    """

    def __init__(self, name: str, K_p=1.0, K_d=0.0, tau=None, *, reference: str = "r", effort: str | None = None,
                 position: str | None = None, range=(-1.0, 1.0), feedforward: str | None = None,
                 feedforward_gain: float = 1.0, feedforward_unit: str = "N"):
        super().__init__(name)
        if feedforward is not None:
            require_positive(name, "feedforward_gain", feedforward_gain)
        self.feedforward, self.ff_gain, self.ff_unit = feedforward, feedforward_gain, feedforward_unit
        require_positive(name, "K_p", K_p)
        _nonnegative(name, "K_d", K_d)
        if tau is not None:
            require_positive(name, "tau", tau)
            require_positive(name, "K_d", K_d)  # the filtered loop is passive only with damping
        self.K_p, self.K_d, self.tau = K_p, K_d, tau
        self.reference, self.effort = reference, effort or f"{name}.F"
        self.position, self.range = position, tuple(float(v) for v in range)

    def piece(self) -> Piece:
        kp, d1 = self._param("K_p", self.K_p, "N/m", "proportional gain (virtual stiffness)")
        # a zero gain (P control) keeps a nonnegative range: the structural checks sample parameters over it
        kd, d2 = self._param("K_d", self.K_d, "N*s/m", "derivative gain (virtual damping)", (0.0, 1.0) if self.K_d == 0 else None)
        params = d1 + d2
        port = self._port("p", "translational")
        ref = self._port("ref", "any", supplies=True)
        filtered = self.tau is not None
        info = InputInfo(self.reference, "m", f"{self.reference}.y", "N/s", "effort",
                         "reference position" + (" (filtered)" if filtered else ""))
        storages, energy, rels, internal = [], [], [], [ref]
        if self.position is None:
            xs = self._state("x", None, "m", self.range, "position seen by the controller", "C", "translational")
            storages.append(xs)
            energy.append(EnergyTerm(f"{self.name}.spring", kp * xs.state.symbol**2 / 2))
            rels.append(Relation(xs.port.flow - port.flow, self.name, "junction"))
            spring_force, x = xs.port.effort, xs.state.symbol
        else:
            x = symbol_of_state(self.position)
            energy.append(EnergyTerm(f"{self.name}.spring", kp * x**2 / 2))
            spring_force = 0  # acts through dH/dx of the plant's own position state
        y = symbol_of_output(info.output)
        r = info.symbol
        ff, ff_force = None, 0  # a signal added after the control law (feedforward), a force on the body
        if self.feedforward is not None:
            kff, d4 = self._param("k_ff", self.ff_gain, f"N/({self.ff_unit})", "force per unit of the signal added to the output")
            params += d4
            ff = self._port("ff", "any", supplies=True)
            internal.append(ff)
            ff_force = kff * ff.effort
            rels.append(Relation(ff.flow - kff * port.flow, self.name, "feedforward"))
        if not filtered:
            rels += [Relation(port.effort - (spring_force + kd * port.flow - kp * ref.effort - ff_force), self.name, "controller"),
                     Relation(ref.flow - kp * port.flow, self.name, "controller")]
            diss = Dissipator(self.name, (), kd * port.flow**2)
            force = kp * (r - x) - kd / kp * y
        else:
            tau, d3 = self._param("tau", self.tau, "s", "reference filter time constant")
            params += d3
            kf = kp + (tau * kp - kd) ** 2 / (4 * tau * kd)
            a, b = (kp - kd / tau) / kf, kd / tau
            fs = self._state("r_f", None, "m", self.range, "filtered reference", "C", "translational")
            storages.append(fs)
            rf, s = fs.state.symbol, fs.port.effort
            energy.append(EnergyTerm(f"{self.name}.filter", kf * rf**2 / 2))
            rels += [Relation(fs.port.flow - ref.effort / tau + s / (tau * kf), self.name, "filter"),
                     Relation(port.effort - (spring_force + kd * port.flow - a * s - b * ref.effort - ff_force), self.name, "controller"),
                     Relation(ref.flow - b * port.flow - s / tau, self.name, "controller")]
            diss = Dissipator(self.name, (), kd * port.flow**2 - a * s * port.flow + s**2 / (tau * kf))
            # K_p (r_f - x) + K_d (r_f' - v), with K_d v = tau y - k_f r_f
            force = kp * (rf - x) + kd * (r - rf) / tau - (tau * y - kf * rf)
        sources = [Source(info, ref)]
        if ff is not None:  # recorded with the command: the measured effort is the sum
            ff_info = InputInfo(self.feedforward, self.ff_unit, f"{self.feedforward}.v", f"N*m/(s*{self.ff_unit})", "effort",
                                f"signal added to the output of the position controller {self.name}")
            sources.append(Source(ff_info, ff))
            force = force + kff * ff_info.symbol
        meas = Measured(self.effort, force, "N", f"force computed by the position controller {self.name}", command=True)
        return Piece(self.name, storages=tuple(storages), energy=tuple(energy), ports=(port,), internal=tuple(internal),
                     relations=tuple(rels), sources=tuple(sources), dissipators=(diss,), params=params,
                     measured=(meas,))


class VelocityLoop(Component):
    """Velocity control: a virtual damper ``K_v`` between the plant and a reference velocity.

    ``F_c = K_v (r_v - v)``; input ``reference`` [m/s] (a flow source), whose power-conjugate
    output ``{reference}.F`` [N] is the controller force, also measured as ``effort``.

    Parameters
    ----------
    name : str
    K_v : float, Param or expression
        Velocity gain, the virtual damping [N*s/m] (> 0).
    reference : str
        Name of the reference-velocity input (default ``"r_v"``).
    effort : str, optional
        Name of the measured controller force (default ``{name}.F``).

    Examples
    --------
    >>> from phs import interconnect, series
    >>> from components import Mass
    >>> s = interconnect("cruise", [Mass("m", m=2.0), VelocityLoop("pi", K_v=3.0)], [series("m", "pi")])
    >>> s.R, s.P, s.S
    (Matrix([[pi.K_v]]), Matrix([[-pi.K_v]]), Matrix([[pi.K_v]]))
    """

    def __init__(self, name: str, K_v=1.0, *, reference: str = "r_v", effort: str | None = None):
        super().__init__(name)
        require_positive(name, "K_v", K_v)
        self.K_v, self.reference, self.effort = K_v, reference, effort or f"{name}.F"

    def piece(self) -> Piece:
        kv, decl = self._param("K_v", self.K_v, "N*s/m", "velocity gain (virtual damping)")
        port = self._port("p", "translational")
        ref = self._port("ref", "any", supplies=True)
        info = InputInfo(self.reference, "m/s", f"{self.reference}.F", "N", "flow", "reference velocity")
        rels = (Relation(port.effort - kv * (port.flow - ref.flow), self.name, "controller"),
                Relation(ref.effort + port.effort, self.name, "controller"))
        slip = port.flow - ref.flow
        meas = Measured(self.effort, symbol_of_output(info.output), "N", f"force computed by the velocity controller {self.name}",
                        command=True)
        return Piece(self.name, ports=(port,), internal=(ref,), relations=rels, sources=(Source(info, ref),),
                     dissipators=(Dissipator(self.name, (), kv * slip**2),), params=decl, measured=(meas,))


__all__ = ["PositionLoop", "VelocityLoop"]
