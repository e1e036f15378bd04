"""Power-preserving junctions: series (1-junction) and parallel (0-junction).

A junction's members are port references (``"R0.p"``, or ``"R0"`` for a
component with a single port), nested junctions, or names of other named
junctions.  Members absorb power from the junction unless they are sources
(ports that supply power).  A ``"-"`` prefix reverses a member's polarity (its
terminals swapped): the junction sees its effort and flow negated, which
conserves power.
A nested junction is joined to its parent by an internal bond along which
power flows from the parent into the nested junction.
"""

from __future__ import annotations

from dataclasses import dataclass

from phs.errors import InterconnectionError


@dataclass(frozen=True)
class Junction:
    """A 0- or 1-junction; build it with :func:`series` or :func:`parallel`."""

    kind: str  # "1" common flow (series), "0" common effort (parallel)
    members: tuple
    name: str | None = None

    def describe(self) -> str:
        inner = ", ".join(m.describe() if isinstance(m, Junction) else str(m) for m in self.members)
        word = {"1": "series", "0": "parallel", "L": "feedback_link"}[self.kind]
        return f"{word}({inner})"


def _make(kind: str, members, name):
    if len(members) < 2:
        raise InterconnectionError(
            f"a {'series' if kind == '1' else 'parallel'} junction needs at least two members, got {list(members)}"
        )
    for m in members:
        if not isinstance(m, (str, Junction)):
            raise InterconnectionError(f"junction member {m!r} must be a port name or a junction")
    return Junction(kind, tuple(members), name)


def series(*members, name: str | None = None) -> Junction:
    """Members share one flow and their efforts add up (a 1-junction).

    Electrical: elements in series carry the same current, voltages add
    (Kirchhoff's voltage law).  Mechanical (force-velocity analogy): elements
    attached to the same moving point or body share its velocity and their
    forces balance.

    Examples
    --------
    >>> series("U", "R0", "C").describe()
    'series(U, R0, C)'
    """
    return _make("1", members, name)


def parallel(*members, name: str | None = None) -> Junction:
    """Members share one effort and their flows add up (a 0-junction).

    Electrical: elements in parallel see the same voltage, currents add
    (Kirchhoff's current law).  Mechanical: elements that transmit the same
    force (a spring in series with a damper) with velocities adding.

    Examples
    --------
    >>> parallel("C1", "R1").describe()
    'parallel(C1, R1)'
    """
    return _make("0", members, name)


def bond(a: str, b: str) -> Junction:
    """Connect two ports directly (a two-member 0-junction): equal efforts, balanced flows.

    Power leaving one port enters the other; a source or the supplying side
    of a transformer on one end and a load on the other is the usual case.

    Examples
    --------
    >>> bond("tf.b", "spring").describe()
    'parallel(tf.b, spring)'
    """
    return _make("0", (a, b), None)


def feedback_link(a: str, b: str) -> Junction:
    """Negative feedback between two subsystem ports: ``u_a = -y_b`` and ``u_b = y_a``.

    Power-conserving: ``y_a u_a + y_b u_b = 0``.  Used by :func:`phs.feedback`.

    Examples
    --------
    >>> feedback_link("plant.F", "ctrl.v").describe()
    'feedback_link(plant.F, ctrl.v)'
    """
    if not (isinstance(a, str) and isinstance(b, str)):
        raise InterconnectionError("feedback_link joins two port names")
    return Junction("L", (a, b), None)
