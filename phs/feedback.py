"""Feedback interconnection of two port-Hamiltonian systems (a power-preserving negative feedback)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from phs.errors import InterconnectionError
from phs.interconnect import interconnect
from phs.junctions import feedback_link, series
from phs.subsystem import _ExternalInput

if TYPE_CHECKING:
    from phs.system import PHSystem


def feedback(sys1, sys2, pairs, name: str | None = None) -> PHSystem:
    """Negative feedback interconnection of two PH systems: ``u1 = -y2 + v1``, ``u2 = y1 + v2``.

    Parameters
    ----------
    sys1, sys2 : PHSystem
    pairs : sequence of (str, str)
        (input of sys1, input of sys2) joined in feedback.
    name : str, optional
        Name of the closed loop (default ``{sys1}_{sys2}``).

    Inputs not listed stay inputs of the result, renamed ``{system}_{input}``.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper, rc_circuit
    >>> from components import Damper
    >>> from phs import interconnect, series
    >>> from phs.params import InputInfo
    >>> ctrl = interconnect("ctrl", [Damper("d", b=2.0), _ExternalInput("v", InputInfo("v", "m/s", "v.F", "N", "flow"))],
    ...                     [series("v", "d")])
    >>> loop = feedback(mass_spring_damper(), ctrl, [("F", "v")])
    >>> loop.R[0, 0]
    b.b + d.b
    """
    if sys1.name == sys2.name:
        raise InterconnectionError(f"feedback: both systems are named {sys1.name!r}; rename one with .renamed()")
    used1 = {a for a, _ in pairs}
    used2 = {b for _, b in pairs}
    for s, used in ((sys1, used1), (sys2, used2)):
        bad = used - set(s.input_names)
        if bad:
            raise InterconnectionError(f"feedback: system {s.name!r} has no input {', '.join(sorted(bad))}; "
                                       f"inputs: {s.input_names}")
    conns = [feedback_link(f"{sys1.name}.{a}", f"{sys2.name}.{b}") for a, b in pairs]
    comps = [sys1, sys2]
    for s, used in ((sys1, used1), (sys2, used2)):
        for inp in s.inputs:
            if inp.name not in used:
                ext = _ExternalInput(f"{s.name}_{inp.name}", inp)
                comps.append(ext)
                conns.append(series(ext.name, f"{s.name}.{inp.name}"))
    return interconnect(name or f"{sys1.name}_{sys2.name}", comps, conns)
