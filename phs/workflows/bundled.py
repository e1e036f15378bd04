"""What ``phs`` ships to try it with: the ready-made systems and small example recordings.

Each recording is a CSV file in ``systems/data/`` (installed with the package), simulated from a
ready-made system at stated parameter values with seeded Gaussian noise on the measured outputs,
so that ``phs fit`` and ``phs diagnose`` can be tried without data of one's own and the answer is
known.  :func:`make_recording` regenerates a file from its declaration (:data:`RECORDINGS`).

Examples
--------
>>> [r.name for r in RECORDINGS]
['msd_two_tone']
>>> recording_path("msd_two_tone").endswith("msd_two_tone.csv")
True
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass, field

import numpy as np

from phs.errors import InputDataError


@dataclass(frozen=True)
class BundledRecording:
    """A recording simulated from ``model`` at ``params`` under ``inputs``, with noise of standard
    deviation ``noise`` (in the output's unit) on each measured output, seeded by ``seed``."""

    name: str
    model: str
    description: str
    params: dict = field(default_factory=dict)
    inputs: tuple[str, ...] = ()
    t_end: float = 1.0
    dt: float = 0.01
    noise: dict = field(default_factory=dict)
    seed: int = 0
    free: tuple[str, ...] = ()


#: The recordings shipped in ``systems/data/``.
RECORDINGS: tuple[BundledRecording, ...] = (
    BundledRecording(
        "msd_two_tone", "systems:mass_spring_damper",
        "mass-spring-damper under a two-tone force; true k.K = 5 N/m, b.b = 0.6 N*s/m; 0.5 mm noise on position",
        params={"k.K": 5.0, "b.b": 0.6}, inputs=("F=0.1*sin(2*pi*0.3*t) + 0.05*sin(2*pi*0.9*t)",), t_end=8.0, dt=0.025,
        noise={"position": 5e-4}, seed=1, free=("k.K", "b.b")),
)


def _data_dir() -> str:
    import systems

    return os.path.join(os.path.dirname(os.path.abspath(systems.__file__)), "data")


def recording_path(name: str) -> str:
    """The path of the bundled recording ``name``.

    Raises
    ------
    InputDataError
        Naming the unknown recording and the known ones.

    Examples
    --------
    >>> recording_path("nope")
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: no bundled recording 'nope' (known: msd_two_tone)
    """
    if name not in {r.name for r in RECORDINGS}:
        raise InputDataError(f"no bundled recording {name!r} (known: {', '.join(r.name for r in RECORDINGS)})")
    return os.path.join(_data_dir(), f"{name}.csv")


def make_recording(rec: BundledRecording) -> str:
    """The CSV text of the bundled recording ``rec``: time, inputs and noisy measured outputs.

    Examples
    --------
    >>> text = make_recording(RECORDINGS[0])
    >>> text.splitlines()[0], len(text.splitlines())
    ('t [s],F [N],position [m]', 322)
    """
    from codegen import simulate
    from phs.workflows.inputs import input_signals
    from phs.workflows.loader import load_model

    system = load_model(rec.model, rec.params)
    t = np.arange(0.0, rec.t_end + rec.dt / 2, rec.dt)
    res = simulate(system, t, u=input_signals(system, list(rec.inputs)))
    rng = np.random.default_rng(rec.seed)
    columns = {"t [s]": res.t}
    for s in system.inputs:
        columns[f"{s.name} [{s.unit}]"] = res[s.name]
    for mo in system.measured:
        columns[f"{mo.name} [{mo.unit}]"] = res[mo.name] + rec.noise.get(mo.name, 0.0) * rng.standard_normal(len(t))
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments="",
               fmt="%.9g")
    return buf.getvalue()


def listing() -> str:
    """One line per ready-made system (``systems.MODELS``) and per bundled recording.

    Examples
    --------
    >>> print(listing())  # doctest: +ELLIPSIS
    systems (MODEL = systems:NAME):
      rc_circuit              Voltage source, resistor and capacitor in series (time constant R C)
    ...
    recordings (DATA = phs list --path NAME):
      msd_two_tone            mass-spring-damper under a two-tone force; ...
    """
    import systems

    lines = ["systems (MODEL = systems:NAME):"]
    for name in systems.MODELS:
        doc = (getattr(systems, name).__doc__ or "").strip().splitlines()
        lines.append(f"  {name:22s}  {_first_sentence(doc[0] if doc else '')}")
    lines.append("recordings (DATA = phs list --path NAME):")
    for r in RECORDINGS:
        lines.append(f"  {r.name:22s}  {r.description} (model {r.model}; try --free {','.join(r.free)})")
    return "\n".join(lines)


def _first_sentence(text: str) -> str:
    return re.sub(r"\s*\(see [^)]*\)$", "", text.replace("``", "").rstrip("."))
