"""Lab-protocol recordings of ready-made actuators whose truth holds one effect the nominal model lacks.

Where :mod:`examples.concealed_effects` drives one actuator with one kind of program and fits three of
its parameters, these recordings are what a lab brings: one run holds a rest, bipolar (or, for a
unipolar drive, offset) squares with smooth edges, held squares, a staircase, a chirp burst and a PRBS,
sampled at 500 Hz, 1 kHz or 2 kHz for 15-20 s, and the nominal model has five free parameters.

Actuators (:data:`ACTUATORS`)
    ``esa``: :func:`systems.electrostatic_actuator.electrostatic_actuator`, measured ``position`` and
    ``current``, free ``k, b, eps, g0, m``; the truths are those of :mod:`examples.concealed_truths`
    (the specimen differs from the nominal defaults in k, b and eps).  ``msd``:
    :func:`systems.msd_hasel.msd_hasel` (the expanding folded HASEL carrying 50 g), measured
    ``displacement``, free ``m, b, a_v1, a_v2, A_m2``, ``F_load`` held at 0; its specimen (:data:`MSD_BASE`)
    differs from the defaults by 4-8 % in those parameters, and its truths are amplifier effects built like
    those of :mod:`examples.concealed_truths`: ``slew_rate_limit`` (the high-voltage amplifier follows the
    command at most at 25 kV/s), ``time_delay`` (the applied voltage is the command 6 ms late) and ``none``.
The command
    a continuous signal: smooth edges are raised cosines (40-60 ms), held edges and block boundaries are
    straight ramps of one sample period ending on a sample, chirps are analytic; it is sampled on the
    recording's grid and declared ``linear`` between samples (what a recorded smooth signal is).
Independent truth
    :func:`simulate_truth` integrates the truth's right-hand side, lambdified from its PHSystem with its
    exact Jacobian, by ``scipy.integrate.solve_ivp`` (Radau), restarted at every edge of the command: it
    shares no code with :mod:`codegen`'s simulator, so a recording does not carry that simulator's errors.
Noise
    std 1 % of each channel's range (position, displacement) and 3 % of the current's standard deviation,
    one seeded stream per case, seed and split.

    python examples/lab_protocols.py --out DIR [--cases A,B] [--seconds S]

A case is a key of :data:`LAB_CASES` or any ``actuator:effect@rate`` (:func:`parse_case`): on ``esa`` any
effect of :mod:`examples.concealed_truths` or a pair ``A+B`` of them, at 500 Hz, 1 kHz or 2 kHz.

writes ``DIR/{case}_{train,validation}.csv`` (``:`` and ``@`` of the case name as ``_``).

Examples
--------
>>> sorted(ACTUATORS)
['esa', 'msd']
>>> LAB_CASES["esa:charge_retention@1kHz"]
('esa', 'charge_retention', 1000.0)
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import re
import sys
import zlib
from dataclasses import dataclass

import numpy as np
import sympy as sp

from phs.errors import InputDataError

if __package__:  # imported as examples.lab_protocols
    from .concealed_truths import Truth, _rate_limited, truth
else:  # run as a script
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from examples.concealed_truths import Truth, _rate_limited, truth

RATES = (500.0, 1000.0, 2000.0)
NOISE = {"position": ("range", 0.01), "current": ("std", 0.03), "displacement": ("range", 0.01)}

# blocks (volts, seconds, hertz): ("rest", s) | ("squares", low, high, Hz, s, edge) with edge the raised-cosine
# time of each edge (0: held, a one-sample ramp) | ("stairs", (levels...), s per level) | ("chirp", offset,
# amplitude, Hz0, Hz1, s) starting at offset - amplitude | ("prbs", low, high, bit s, s, seed) from a 7-bit LFSR
ESA_TRAINING = [("rest", 0.8), ("squares", -16, 16, 1.0, 3.0, 0.04), ("squares", 8, 22, 2.0, 2.0, 0.0),
                ("stairs", (6, 12, 18, 24, 12, 0), 0.5), ("chirp", 12, 8, 1.0, 30.0, 2.0), ("rest", 0.7),
                ("prbs", 6, 20, 0.05, 2.5, 1), ("rest", 0.5)]
ESA_VALIDATION = [("rest", 0.6), ("prbs", 4, 18, 0.04, 2.0, 2), ("stairs", (20, 10, 16, 4), 0.5),
                  ("chirp", 14, 6, 2.0, 40.0, 2.0), ("squares", -20, 12, 1.5, 2.0, 0.05), ("squares", 6, 16, 3.0, 1.5, 0.0),
                  ("rest", 0.6)]
MSD_TRAINING = [("rest", 0.8), ("squares", 400, 2400, 1.0, 3.0, 0.06), ("squares", 1000, 2200, 2.0, 2.0, 0.0),
                ("stairs", (500, 1000, 1500, 2000, 2500, 1200, 0), 0.5), ("chirp", 1500, 700, 0.5, 15.0, 2.0),
                ("rest", 0.7), ("prbs", 800, 2200, 0.08, 2.5, 3), ("rest", 0.5)]
MSD_VALIDATION = [("rest", 0.6), ("prbs", 600, 2000, 0.06, 2.0, 4), ("stairs", (2200, 1100, 1700, 500), 0.5),
                  ("chirp", 1400, 600, 1.0, 20.0, 2.0), ("squares", 300, 2300, 1.5, 2.0, 0.05),
                  ("squares", 900, 1900, 3.0, 1.5, 0.0), ("rest", 0.6)]
CYCLE_GAINS = (1.0, 0.85, 1.05)  # amplitude of successive repetitions of a protocol (about the rest level)
MSD_BASE = {"m": 0.053, "b": 1.07, "a_v1": 0.51, "a_v2": 0.63, "A_m2": 0.127}
MSD_EFFECTS = {"slew_rate_limit": {"S": 25e3}, "time_delay": {"delay": 6e-3}, "none": {}}


@dataclass(frozen=True)
class Actuator:
    """A ready-made actuator as a lab records it: nominal model, free parameters, channels, protocols."""

    name: str
    nominal: object  # callable () -> PHSystem
    free: tuple
    command: str
    channels: tuple
    rest: float
    training: list
    validation: list
    held_inputs: tuple = ()  # (name, value) of inputs kept constant
    units: tuple = ()  # (signal, unit)


def _esa():
    from systems.electrostatic_actuator import electrostatic_actuator

    return electrostatic_actuator()


def _msd():
    from systems.msd_hasel import msd_hasel

    return msd_hasel()


ACTUATORS = {
    "esa": Actuator("esa", _esa, ("k", "b", "eps", "g0", "m"), "U", ("position", "current"), 0.1, ESA_TRAINING, ESA_VALIDATION,
                    units=(("U", "V"), ("position", "m"), ("current", "A"))),
    "msd": Actuator("msd", _msd, ("m", "b", "a_v1", "a_v2", "A_m2"), "V", ("displacement",), 0.0, MSD_TRAINING, MSD_VALIDATION,
                    held_inputs=(("F_load", 0.0),), units=(("V", "V"), ("F_load", "N"), ("displacement", "m"))),
}
LAB_CASES = {
    "esa:charge_retention@1kHz": ("esa", "charge_retention", 1000.0),
    "esa:cubic_stiffness@500Hz": ("esa", "cubic_stiffness", 500.0),
    "esa:time_delay@2kHz": ("esa", "time_delay", 2000.0),
    "msd:slew_rate_limit@1kHz": ("msd", "slew_rate_limit", 1000.0),
    "msd:none@500Hz": ("msd", "none", 500.0),
}
"""The lab set: case name -> (actuator, effect, sampling rate [Hz])."""
RATE_NAMES = {"500Hz": 500.0, "1kHz": 1000.0, "2kHz": 2000.0}
_CASE = re.compile(r"(esa|msd):([a-z_]+(?:\+[a-z_]+)?)@(500Hz|1kHz|2kHz)")


def parse_case(case: str) -> tuple[str, str, float]:
    """``(actuator, effect, rate)`` of a lab case: a key of :data:`LAB_CASES`, or any ``actuator:effect@rate``
    with an effect the actuator's truths know (``esa``: those of :mod:`examples.concealed_truths` or a pair
    ``A+B`` of them; ``msd``: :data:`MSD_EFFECTS`) at a rate of :data:`RATE_NAMES`.

    Examples
    --------
    >>> parse_case("esa:time_delay+cubic_stiffness@1kHz")
    ('esa', 'time_delay+cubic_stiffness', 1000.0)
    >>> parse_case("esa:warp@1kHz")
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: lab case 'esa:warp@1kHz': unknown effect 'warp'; known: ...
    """
    if case in LAB_CASES:
        return LAB_CASES[case]
    m = _CASE.fullmatch(case) if isinstance(case, str) else None
    if m is None:
        raise InputDataError(f"unknown lab case {case!r}: not actuator:effect@rate with an actuator of "
                             f"{', '.join(ACTUATORS)} and a rate of {', '.join(RATE_NAMES)}; listed: {', '.join(LAB_CASES)}")
    name, effect, rate = m.groups()
    try:
        truth_of(name, effect)
    except InputDataError as err:
        raise InputDataError(f"lab case {case!r}: {err}") from None
    return name, effect, RATE_NAMES[rate]


def _case_seed(case: str) -> int:
    """The first entry of a case's noise seed: its place in :data:`LAB_CASES` (from 1), else a checksum of
    its name from 1000 up (the same on every machine)."""
    if case in LAB_CASES:
        return list(LAB_CASES).index(case) + 1
    return 1000 + zlib.crc32(case.encode()) % 1_000_000


def msd_truth(effect: str) -> Truth:
    """The MSD HASEL specimen (:data:`MSD_BASE`) with an amplifier effect of :data:`MSD_EFFECTS`.

    Examples
    --------
    >>> tr = msd_truth("time_delay")
    >>> tr.parameters, tr.system.param("m").value
    ({'delay': 0.006}, 0.053)
    """
    from systems.msd_hasel import msd_hasel

    if effect not in MSD_EFFECTS:
        raise InputDataError(f"unknown effect {effect!r} for msd; known: {', '.join(MSD_EFFECTS)}")
    system, v = msd_hasel(**MSD_BASE), MSD_EFFECTS[effect]
    if effect == "slew_rate_limit":
        return Truth(effect, system, "the amplifier's output follows the command at most at a slew rate S (V/s)", dict(v),
                     applied=lambda t, U: _rate_limited(t, U, v["S"], substeps=4))
    if effect == "time_delay":
        d = v["delay"]
        return Truth(effect, system, "transport delay of the applied voltage: V_applied(t) = V(t - d)", dict(v),
                     applied=lambda t, U: (np.concatenate([[t[0]], t + d]), np.concatenate([[U[0]], U])))
    return Truth(effect, system, "the nominal HASEL (with the specimen's own m, b, a_v1, a_v2, A_m2)", {})


# -- the command ---------------------------------------------------------------------------------------------------------
def _lfsr_bits(n: int, seed: int) -> np.ndarray:
    """``n`` bits of the maximal-length 7-bit LFSR x^7 + x^6 + 1 from the state ``seed``."""
    state, out = (seed % 127) + 1, np.empty(n, dtype=int)
    for i in range(n):
        bit = ((state >> 6) ^ (state >> 5)) & 1
        state = ((state << 1) | bit) & 0x7F
        out[i] = bit
    return out


def _block(block, tl, rest, gain, dt):
    """Values of one block at local times ``tl`` (amplitudes scaled by ``gain`` about ``rest``) and its edges
    (local start times, widths)."""
    kind = block[0]
    if kind == "rest":
        return np.full_like(tl, rest), []
    if kind == "chirp":
        off, amp, f0, f1, dur = block[1:]
        phase = 2 * np.pi * (f0 * tl + (f1 - f0) / (2 * dur) * tl**2)
        return rest + gain * (off - rest) - gain * amp * np.cos(phase), []
    step, seg, edges, te, w, lo, hi, smooth = _levels(block, rest, gain, dt)
    v = seg[np.minimum((tl // step).astype(int), len(seg) - 1)]
    if len(te):
        i = np.searchsorted(te, tl, side="right") - 1
        ii = np.maximum(i, 0)
        on = (i >= 0) & (tl < te[ii] + w[ii])
        if np.any(on):
            k = i[on]
            sh = (tl[on] - te[k]) / w[k]
            v = v.copy()
            v[on] = lo[k] + (hi[k] - lo[k]) * ((0.5 - 0.5 * np.cos(np.pi * sh)) if smooth else sh)
    return v, edges


@functools.lru_cache(maxsize=256)
def _levels(block, rest, gain, dt):
    """A block of held levels: segment length, level of each segment, edges (list and arrays of starts, widths,
    levels before and after) and whether the edges are raised cosines."""
    def g(level):
        return rest + gain * (level - rest)

    kind, width, smooth = block[0], dt, False
    if kind == "stairs":
        step, seg = block[2], np.array([g(v) for v in block[1]])
    elif kind == "squares":
        low, high, f, dur, w = block[1:]
        step = 0.5 / f
        seg = np.array([g(high), g(low)] * (int(math.ceil(dur / step)) // 2 + 1))
        width, smooth = (w, True) if w > 0 else (dt, False)
    elif kind == "prbs":
        low, high, step, dur, seed = block[1:]
        seg = np.where(_lfsr_bits(int(math.ceil(dur / step)) + 1, seed) == 1, g(high), g(low))
    else:
        raise InputDataError(f"unknown protocol block {kind!r}")
    ks = [k for k in range(1, len(seg)) if seg[k] != seg[k - 1]]
    edges = [(k * step, width) for k in ks]
    return (step, seg, edges, np.array([k * step for k in ks]), np.full(len(ks), width), seg[np.array(ks, dtype=int) - 1],
            seg[np.array(ks, dtype=int)], smooth)


def _duration(block) -> float:
    """Length of a protocol block [s]."""
    return {"rest": lambda b: b[1], "squares": lambda b: b[4], "stairs": lambda b: b[2] * len(b[1]),
            "chirp": lambda b: b[5], "prbs": lambda b: b[4]}[block[0]](block)


def command(actuator: str, seconds: float, fs: float, validation: bool = False):
    """The continuous command of a run as a function, and its edges (times where it is not smooth).

    The run rests at the actuator's rest level, then repeats its protocol (each repetition scaled by the
    next of :data:`CYCLE_GAINS` about the rest level) until ``seconds``; each block starts with a
    one-sample ramp from where the previous block ended.

    Returns
    -------
    (callable, numpy.ndarray)
        ``f(t)`` for an array of times, and the sorted edge times.

    Examples
    --------
    >>> f, edges = command("esa", 2.0, 1000.0)
    >>> float(f(np.array([0.0]))[0]), bool(len(edges) > 4), float(f(np.array([1.3]))[0])
    (0.1, True, 16.0)
    """
    act = _actuator(actuator)
    dt = 1.0 / fs
    blocks = act.validation if validation else act.training
    plan, start, cycle = [], 0.0, 0  # (start, duration, block, gain)
    while start < seconds:
        gain = CYCLE_GAINS[cycle % len(CYCLE_GAINS)]
        for b in blocks:
            dur = _duration(b)
            plan.append((start, dur, b, gain))
            start += dur
        cycle += 1
    edge_times, firsts, prevs, prev = [0.0], [], [], act.rest
    for s0, dur, b, gain in plan:
        edge_times += [s0, s0 + dt] + [s0 + te + x for te, w in _block(b, np.zeros(1), act.rest, gain, dt)[1] if te < dur for x in (0, w)]
        firsts.append(float(_block(b, np.array([dt]), act.rest, gain, dt)[0][0]))  # each block ramps from the last one's end
        prevs.append(prev)
        prev = float(_block(b, np.array([max(dur - 1e-12, 0.0)]), act.rest, gain, dt)[0][0])
    starts = np.array([p[0] for p in plan])

    def f(t):
        t = np.asarray(t, dtype=float)
        out = np.full(t.shape, act.rest)
        which = np.searchsorted(starts, t, side="right") - 1
        for k in np.unique(which[which >= 0]):
            s0, dur, b, gain = plan[k]
            sel = which == k
            tl = t[sel] - s0
            vals, _ = _block(b, tl, act.rest, gain, dt)
            ramp = tl < dt
            vals[ramp] = prevs[k] + (firsts[k] - prevs[k]) * tl[ramp] / dt
            out[sel] = vals
        return out

    return f, np.unique(np.round(np.array(edge_times), 12))


def _actuator(name):
    if name not in ACTUATORS:
        raise InputDataError(f"unknown actuator {name!r}; known: {', '.join(ACTUATORS)}")
    return ACTUATORS[name]


def truth_of(actuator: str, effect: str) -> Truth:
    """The truth of ``effect`` on ``actuator`` (``esa``: :func:`examples.concealed_truths.truth`).

    Examples
    --------
    >>> truth_of("esa", "none").system.state_names
    ['x', 'm.p', 'Q']
    """
    return truth(effect) if _actuator(actuator).name == "esa" else msd_truth(effect)


# -- the independent integrator ------------------------------------------------------------------------------------------
def simulate_truth(tr: Truth, t, U, x0, held=(), *, rtol: float = 1e-8, edges=None, command_fn=None) -> dict:
    """Measured outputs of a truth on the grid ``t``, integrated by scipy's Radau on its lambdified right-hand side.

    The command is ``command_fn`` (a continuous function) when given, else ``U`` linearly interpolated;
    an amplifier effect (``tr.applied``) maps the command sampled every tenth of a sample first.  The
    integration restarts at every edge in ``edges`` (and, for an applied effect, at its kinks that change
    the slope by more than 1 % of the command's range per sample).  ``held`` are (input, value) pairs.

    Examples
    --------
    >>> t = np.arange(201) / 1000.0
    >>> out = simulate_truth(truth_of("esa", "none"), t, np.full(201, 10.0), np.zeros(3))
    >>> sorted(out), bool(out["position"][-1] > 1e-7)
    (['current', 'position'], True)
    """
    from scipy.integrate import solve_ivp

    s = tr.system
    names = s.input_names
    held = dict(held)
    drive = [n for n in names if n not in held]
    args = (s.x, s.u, s.p)
    f = sp.lambdify(args, s.dynamics, cse=True)
    jac = sp.lambdify(args, s.dynamics_jacobian, cse=True)
    meas = sp.lambdify(args, list(s.measured_expressions), cse=True)
    p = np.array([s.param_values()[k] for k in s.param_names], dtype=float)
    t = np.asarray(t, dtype=float)
    edges = [] if edges is None else list(edges)
    if tr.applied is not None:
        fine = np.linspace(t[0], t[-1], 10 * (len(t) - 1) + 1)
        times, values = tr.applied(fine, command_fn(fine) if command_fn is not None else np.interp(fine, t, U))
        times, values = np.asarray(times, float), np.asarray(values, float)
        slope = np.diff(values) / np.maximum(np.diff(times), 1e-15)
        big = np.abs(np.diff(slope)) * (t[1] - t[0]) > 0.01 * max(float(np.ptp(values)), 1e-12)
        edges = list(times[1:-1][big]) + ([times[1]] if times[1] > t[0] else [])
        cmd = lambda tt: np.interp(tt, times, values)  # noqa: E731
    elif command_fn is not None:
        cmd = command_fn
    else:
        cmd = lambda tt: np.interp(tt, t, U)  # noqa: E731

    def u_at(tt):
        c = float(cmd(np.array([tt]))[0])
        return [c if n in drive else held[n] for n in names]

    typical = np.array([st.typical if getattr(st, "typical", None) else 1.0 for st in s.states], dtype=float)
    atol = rtol * 1e-2 * typical
    cuts = sorted({float(e) for e in edges if t[0] < e < t[-1]} | {float(t[0]), float(t[-1])})
    X = np.empty((len(t), len(x0)))
    x = np.asarray(x0, dtype=float)
    X[0] = x
    for a, b in zip(cuts[:-1], cuts[1:]):
        idx = np.nonzero((t > a) & (t <= b))[0]
        te = np.append(t[idx], b) if len(idx) == 0 or t[idx[-1]] < b else t[idx]
        sol = solve_ivp(lambda tt, xx: np.asarray(f(xx, u_at(tt), p), dtype=float).ravel(), (a, b), x, method="Radau",
                        t_eval=te, rtol=rtol, atol=atol, jac=lambda tt, xx: np.asarray(jac(xx, u_at(tt), p), dtype=float))
        if not sol.success:
            from phs.errors import SimulationError

            raise SimulationError(f"{s.name}: solve_ivp failed between t = {a:g} and {b:g} s ({sol.message})")
        X[idx] = sol.y.T[: len(idx)]
        x = sol.y[:, -1]
    uu = np.array([[*u_at(tt)] for tt in t])
    Y = np.array([np.asarray(meas(X[k], uu[k], p), dtype=float).ravel() for k in range(len(t))])
    return {name: Y[:, j] for j, name in enumerate(s.measured_names)}


def _rest_state(tr: Truth, act: Actuator) -> np.ndarray:
    """The truth at rest under the rest command (the origin for the electrostatic actuator)."""
    if act.name == "esa":
        return np.zeros(len(tr.system.state_names))
    from phs import equilibrium

    u = {act.command: act.rest, **dict(act.held_inputs)}
    eq = equilibrium(tr.system, u=u, x0={"x": 3e-4}).as_dict()
    return np.array([eq[k] for k in tr.system.state_names], dtype=float)


def generate(case: str, *, seconds: float = 17.0, seed: int = 0, validation: bool = False):
    """A noisy lab-protocol recording of a case of :data:`LAB_CASES`, and what the truth was.

    Parameters
    ----------
    case : str
        A key of :data:`LAB_CASES`, or any case :func:`parse_case` reads (``actuator:effect@rate``, the effect
        possibly a pair ``A+B`` on ``esa``).
    seconds : float
        Length of the run (at least 0.5 s).
    seed : int
        Noise seed (each case, seed and split has its own stream).
    validation : bool
        The actuator's validation protocol instead of its training protocol.

    Returns
    -------
    (Recording, dict)
        The command, the held inputs and the noisy channels; ``info``: ``case``, ``actuator``, ``effect``,
        ``form``, ``parameters``, ``rate``, ``free`` (the nominal model's), ``x0`` (the rest state by name,
        for the nominal model's states), ``noise_std``, ``clean``.

    Examples
    --------
    >>> rec, info = generate("esa:cubic_stiffness@500Hz", seconds=1.0)
    >>> rec.names, len(rec), info["free"]
    (['U', 'position', 'current'], 501, ['k', 'b', 'eps', 'g0', 'm'])
    """
    from phs.workflows.recording import Recording

    name, effect, fs = parse_case(case)
    if not seconds >= 0.5:
        raise InputDataError(f"seconds must be at least 0.5, got {seconds}")
    act, tr = ACTUATORS[name], truth_of(name, effect)
    t = np.arange(int(round(seconds * fs)) + 1) / fs
    fn, edges = command(name, seconds, fs, validation)
    U = fn(t)
    x0 = _rest_state(tr, act)
    clean = simulate_truth(tr, t, U, x0, act.held_inputs, edges=edges, command_fn=fn)
    clean = {ch: clean[ch] for ch in act.channels}
    noise_std = {ch: NOISE[ch][1] * (float(np.ptp(y)) if NOISE[ch][0] == "range" else float(np.std(y))) for ch, y in clean.items()}
    rng = np.random.default_rng([_case_seed(case), int(seed), int(bool(validation))])
    noisy = {ch: y + noise_std[ch] * rng.standard_normal(len(t)) for ch, y in clean.items()}
    signals = {act.command: U, **{k: np.full(len(t), v) for k, v in act.held_inputs}, **noisy}
    split = "validation" if validation else "train"
    rec = Recording.from_arrays(t, signals, source=f"lab_protocols:{case}:{split}", units=dict(act.units),
                                holds={act.command: "linear"})
    nominal_states = act.nominal().state_names
    info = {"case": case, "actuator": name, "effect": effect, "form": tr.form, "parameters": dict(tr.parameters), "rate": fs,
            "free": list(act.free), "x0": {k: float(v) for k, v in zip(tr.system.state_names, x0) if k in nominal_states},
            "noise_std": noise_std, "clean": clean}
    return rec, info


def main(argv=None) -> int:
    """Command line: write the training and validation CSV files of lab cases.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     main(["--out", d, "--seconds", "0.5", "--cases", "esa:cubic_stiffness@500Hz"])
    ...     sorted(os.listdir(d))
    0
    ['esa_cubic_stiffness_500Hz_train.csv', 'esa_cubic_stiffness_500Hz_validation.csv']
    """
    from examples.concealed_effects import write_csv

    ap = argparse.ArgumentParser(prog="lab_protocols.py", description="Write lab-protocol recordings of concealed cases.")
    ap.add_argument("--out", required=True, help="directory for the CSV files (created if missing)")
    ap.add_argument("--seconds", type=float, default=17.0, help="length of every recording (default 17 s)")
    ap.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    ap.add_argument("--cases", default=",".join(LAB_CASES),
                    help="comma-separated cases (default: the listed ones; any actuator:effect@rate, see parse_case)")
    args = ap.parse_args(argv)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    for c in cases:
        try:
            parse_case(c)
        except InputDataError as err:
            ap.error(str(err))
    files = {}
    for c in cases:
        for split, validation in (("train", False), ("validation", True)):
            files[f"{c.replace(':', '_').replace('@', '_')}_{split}.csv"] = generate(c, seconds=args.seconds, seed=args.seed,
                                                                                     validation=validation)[0]
    os.makedirs(args.out, exist_ok=True)
    for name, rec in files.items():
        write_csv(rec, os.path.join(args.out, name))
    return 0


if __name__ == "__main__":
    sys.exit(main())
