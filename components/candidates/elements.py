"""Input elements: drive physics between a recorded command and the port-Hamiltonian part.

* :class:`InputElement`: an element (a delay, a saturation, a rate limit) that maps a recorded command
  before it reaches the model; its numeric :meth:`InputElement.transform` is searched, not
  differentiated.  Placed on a model input (the model is unchanged: the element is outside it), or
* inside a feedback loop, between a controller and the plant (:class:`InLoop`).  A controller's
  command is a measured channel (``Measured.command``: the force its firmware computed and recorded),
  not an input: the model computes it from its states.  An element there changes what reaches the
  plant, ``F_applied = e(F_c)``, while the controller's command is what it computes.  The model keeps
  its live controller and receives the element's *deviation* from the recorded command,

  ``d(t) = e(u_c,rec)(t) − u_c,rec(t)``

  (the recorded command smoothed first above a tenth of the sampling rate: :func:`smoothed_command`),

  as a force on the body the controller drives (:func:`with_deviation`: one more input, a force source
  at that body's momentum, so the model stays port-Hamiltonian).  Then
  ``F_c(x(t)) + d(t) = e(u_c,rec)(t) + (F_c(x(t)) − u_c,rec(t))``: the plant gets the element's output
  up to the difference between the model's command and the recorded one, which is the model's own
  error on that channel plus its noise.  The loop stays closed through the model's controller (the
  plant's stiffness under feedback, its stability) while the element acts on what was commanded.  At
  the element's neutral point ``d = 0``: the nominal model.

Examples
--------
>>> import numpy as np
>>> from components.candidates import TimeDelay
>>> t = np.arange(4) * 0.1
>>> InLoop(TimeDelay(), "u_c").drive(t, {"u_c": np.array([0.0, 1.0, 1.0, 1.0])}, "u_c", [0.1])["u_c.time_delay"].tolist()
[0.0, -1.0, 0.0, 0.0]
"""

from __future__ import annotations

from abc import abstractmethod
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from components.candidates.base import Augmentation, Candidate, _rebuild, command_channels, controller_inputs, momentum_states
from phs.errors import ModelError
from phs.params import InputInfo

if TYPE_CHECKING:
    from phs.system import PHSystem

INPUT_GROUP = "+"
"""Joins the inputs of one place of an input element (inputs driven by the same command)."""


def input_members(where: str) -> list[str]:
    """The inputs of an input element's place: ``"V4+V9"`` → ``["V4", "V9"]``, ``"U"`` → ``["U"]``.

    Examples
    --------
    >>> input_members("V4+V9+V15"), input_members("U")
    (['V4', 'V9', 'V15'], ['U'])
    """
    return where.split(INPUT_GROUP)


def deviation_input(channel: str, effect: str) -> str:
    """Name of the input through which an element of kind ``effect`` between the command ``channel``
    and the plant acts (:func:`with_deviation`).

    Examples
    --------
    >>> deviation_input("u_c", "time_delay")
    'u_c.time_delay'
    """
    return f"{channel}.{effect}"


COMMAND_BAND = 0.2
"""Share of the Nyquist frequency kept of a recorded command before an element between the controller
and the plant acts on it (:func:`smoothed_command`).  A digital loop samples at 10 to 30 times its
bandwidth, so above a tenth of the sampling rate a command holds its sensor noise and the ripple of its
own sampling, not motion of the plant; the noise would make the deviation input rough at every sample
and hold the integrator to one step per sample.  On the concealed 4 ms loop delay (position with 1 %
noise, command with 2 %; ``python bench/loop_command.py``), the outputs simulated through the smoothed
deviation differ from those through the raw one by 1.2e-4 (position) and 2.3e-3 (command) of their
standard deviations, far below the noise, and the simulation runs 4.0 times faster (0.049 against 0.196 s)."""


def smoothed_command(u) -> np.ndarray:
    """A recorded command with what lies above :data:`COMMAND_BAND` of the Nyquist frequency removed
    (a zero-phase second-order Butterworth low-pass: no delay added); short records are returned as they are.

    Examples
    --------
    >>> u = np.sin(np.linspace(0.0, 6.0, 600)) + 0.05 * np.random.default_rng(0).normal(size=600)
    >>> bool(np.std(smoothed_command(u) - np.sin(np.linspace(0.0, 6.0, 600))) < 0.03)
    True
    """
    import scipy.signal

    u = np.asarray(u, float)
    if len(u) <= 30:
        return u
    b, a = scipy.signal.butter(2, COMMAND_BAND)
    return scipy.signal.filtfilt(b, a, u)


def _is_deviation(system, name: str) -> bool:
    return any(name.startswith(ch + ".") for ch in command_channels(system))


def driven_body(system, channel: str) -> str:
    """The momentum state the controller whose command is ``channel`` drives: the one body on which the
    command's reference inputs (the inputs its expression reads, or whose conjugate outputs it reads) act
    through the input map (``G`` or ``P``).

    Examples
    --------
    >>> from systems.examples import pd_servo
    >>> servo = pd_servo()
    >>> driven_body(servo, "u_c")
    'm.p'
    """
    reads = {str(v) for v in getattr(system.measured[system.measured_names.index(channel)].expr, "free_symbols", ())}
    refs = [j for j, inp in enumerate(system.inputs) if inp.name in reads or (inp.output and inp.output in reads)]
    names = system.state_names
    bodies = [p for p in momentum_states(system) if any(system.G[names.index(p), j] != 0 or system.P[names.index(p), j] != 0
                                                         for j in refs)]
    if len(bodies) != 1:
        raise ModelError(f"command {channel!r} of {system.name!r}: its references drive {len(bodies)} bodies "
                         f"({', '.join(bodies) or 'none'}); an element between the controller and the plant needs exactly one")
    return bodies[0]


def with_deviation(system, channel: str, effect: str) -> PHSystem:
    """``system`` with one more input, a force on the body driven by the command ``channel``
    (:func:`driven_body`): a force source at that momentum (a column of ``G``, zero ``P``, ``S``, ``N``),
    named :func:`deviation_input`; its conjugate output is the body's velocity.

    Examples
    --------
    >>> from systems.examples import pd_servo
    >>> servo = pd_servo()
    >>> s = with_deviation(servo, "u_c", "time_delay")
    >>> s.input_names, s.check().ok
    (['r', 'u_c.time_delay'], True)
    """
    body = driven_body(system, channel)
    i, m = system.state_names.index(body), len(system.inputs)
    unit = system.states[i].unit
    name = deviation_input(channel, effect)
    if name in system.input_names:
        raise ModelError(f"{system.name!r} already has an input {name!r}")
    rotational = "**2" in unit.replace(" ", "")
    info = InputInfo(name, "N*m" if rotational else "N", f"{name}.v", "rad/s" if rotational else "m/s", "effort",
                     f"deviation of the applied drive from the command {channel} ({effect} between controller and plant)")
    G = sp.Matrix(system.G).row_join(sp.zeros(len(system.states), 1))
    G[i, m] = 1
    P = sp.Matrix(system.P).row_join(sp.zeros(len(system.states), 1))
    S, N = (sp.Matrix(M).row_join(sp.zeros(m, 1)).col_join(sp.zeros(1, m + 1)) for M in (system.S, system.N))
    return _rebuild(system, G=G, P=P, S=S, N=N, inputs=tuple(system.inputs) + (info,), effect=f"{effect} at {channel}")


class InputElement(Candidate):
    """An element between the recorded input and the model's input (drive electronics, transport):
    :meth:`transform` maps the sampled input with parameter values ``theta`` (one per entry of
    :meth:`parameters`).  On a model input the model itself is unchanged; on a controller's command
    (:func:`command_channels`) the element sits inside the loop (:class:`InLoop`)."""

    kind = "input"

    def attach_points(self, system) -> list[str]:
        return [n for n in system.input_names if not _is_deviation(system, n)] + command_channels(system)

    def places(self, system, commands) -> list[str]:
        """Where the element is tried, given the recorded signals (``commands[name]``, a mapping holding
        at least the attach points'): every attach point whose command varies (on a constant one the
        element changes nothing), with the inputs driven by the very same command joined into one place
        ``a+b+c`` (an element in each of their drives, with one set of parameters: several actuators of
        one kind driven together, as :func:`~components.candidates.base.with_groups` joins the parts of
        identical segments).  A controller's command is a place of its own, when it was recorded; the inputs
        it is computed from (:func:`controller_inputs`: its reference, a signal added to its output) are then
        no place: they are signals inside the controller, and a drive element acts on the command.

        Examples
        --------
        >>> import numpy as np
        >>> from components.candidates import TimeDelay
        >>> from systems.hydrogel_arm import hydrogel_arm
        >>> arm = hydrogel_arm(per_segment=1, svas=[4, 9, 15])
        >>> pulse = np.array([0.0, 3.6, 3.6, 0.0])
        >>> TimeDelay().places(arm, {"V4": pulse, "V9": pulse, "V15": pulse})
        ['V9+V4+V15']
        >>> TimeDelay().places(arm, {"V4": pulse, "V9": 0 * pulse, "V15": 2 * pulse})
        ['V4', 'V15']
        """
        groups: list[tuple[np.ndarray, list[str]]] = []
        loops = command_channels(system)
        # a recorded command is where a drive element sits; the signals it is computed from are not drives
        recorded = any(c in commands and np.ptp(np.asarray(commands[c], float)) > 0 for c in loops)
        inside = set(controller_inputs(system)) if recorded else set()
        out = []
        for n in self.attach_points(system):
            if n in loops and n not in commands:  # the controller's output was not recorded
                continue
            if n in inside:
                continue
            u = np.asarray(commands[n], float)
            if np.ptp(u) == 0:
                continue
            if n in loops:
                out.append(n)
                continue
            for command, members in groups:
                if command.shape == u.shape and np.array_equal(command, u):
                    members.append(n)
                    break
            else:
                groups.append((u, [n]))
        return [INPUT_GROUP.join(members) for _, members in groups] + out

    def _check_where(self, system, where: str) -> None:
        points = self.attach_points(system)
        members = [where] if where in command_channels(system) else input_members(where)
        bad = [n for n in members if n not in points or n in command_channels(system) and len(members) > 1]
        if bad:
            raise ModelError(f"candidate {self.effect!r} cannot attach to {where!r} of {system.name!r}; "
                             f"possible: {points or 'none'} (inputs possibly several joined by {INPUT_GROUP!r})")

    @abstractmethod
    def parameters(self, t, u) -> list[tuple[str, float, float, float]]:
        """``(name, start, lo, hi)`` per parameter, given the recorded input."""

    @abstractmethod
    def transform(self, t: np.ndarray, u: np.ndarray, theta) -> np.ndarray:
        """The input the model receives."""

    def neutral(self, t, u) -> list | None:
        """Parameter values (one per entry of :meth:`parameters`) at which :meth:`transform` passes the
        input through unchanged, or None when unknown."""
        return None

    def derived(self, theta) -> dict:
        """Readable quantities of the parameters ``theta`` that the report shows beside them (a saturation's
        limits beside its compression of the peak); none by default."""
        return {}

    def course(self, t, u, theta) -> tuple | None:
        """The element's output in continuous time as ``(times, values)`` (linear between them) when it is
        not the straight line through its values at the samples (:meth:`transform`), else None: a delay by
        a fraction of a sample moves the command's kinks between the samples (on a command that steps, the
        current of a capacitive load differs by most of its spread between the two)."""
        return None

    def drive(self, t, signals, where: str, theta) -> dict:
        """The model inputs this element sets at ``where`` from the recorded ``signals`` (a mapping of
        name to samples): the transformed command of every input of the place."""
        return {n: self.transform(t, np.asarray(signals[n], float), theta) for n in input_members(where)}

    def drive_between(self, t, signals, where: str, theta) -> dict:
        """The courses between samples (:meth:`course`) of the inputs :meth:`drive` sets, where they are not
        straight lines (:attr:`phs.workflows.recording.Recording.between`)."""
        out = {}
        for n in input_members(where):
            c = self.course(t, np.asarray(signals[n], float), theta)
            if c is not None:
                out[n] = c
        return out

    def augment(self, system, where, scales) -> Augmentation:
        self._check_where(system, where)
        if where in command_channels(system):
            inner = InLoop(self, where)
            return Augmentation(self.effect, where, inner.component, with_deviation(system, where, self.effect), [], {}, [], {}, inner)
        return Augmentation(self.effect, where, self.component, system, [], {}, [], {}, self)

    component = ""


class InLoop(InputElement):
    """The element ``inner`` between a controller's command (the measured channel ``channel``) and the
    plant (see the module): it sets the deviation input ``inner(u_c) − u_c`` from the recorded command."""

    def __init__(self, inner: InputElement, channel: str):
        self.inner, self.channel = inner, channel
        self.effect, self.summary = inner.effect, inner.summary
        self.component = f"{inner.component} between the command {channel} and the plant"

    def parameters(self, t, u) -> list[tuple[str, float, float, float]]:
        return self.inner.parameters(t, u)

    def transform(self, t, u, theta) -> np.ndarray:
        return self.inner.transform(t, u, theta)

    def derived(self, theta) -> dict:
        return self.inner.derived(theta)

    def neutral(self, t, u) -> list | None:
        return self.inner.neutral(t, u)

    def drive(self, t, signals, where, theta) -> dict:
        u = smoothed_command(signals[self.channel])
        return {deviation_input(self.channel, self.effect): self.inner.transform(t, u, theta) - u}

    def drive_between(self, t, signals, where, theta) -> dict:
        # the command is smoothed far below the sampling rate: straight lines between samples follow it
        return {}

    def __repr__(self) -> str:
        return f"InLoop({self.inner!r}, {self.channel!r})"
