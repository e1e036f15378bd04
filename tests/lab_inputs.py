"""Lab-shaped recordings as hypothesis strategies, for tests that hold a fast path against its reference.

A recording here is what a lab hands over: a uniform time grid at 50 Hz to 50 kHz that does not start at zero,
and one or several inputs, each a concatenation in random order and of random durations of rests, steps (on the
sample grid or between samples, read by an averaging converter), ramps and holds, smooth-edged squares (tanh),
chirps, multisines (up to near the Nyquist frequency), PRBS held for k samples and noise.  Each input is
delivered as the samples on the grid (an array), as samples of its own converter (another rate, an offset
between the grid's points, starting late or ending early: a :class:`~phs.signals.Sampled`), or held by a DAC
(``hold="zoh"``).  Models come with a time scale drawn against the recording's duration and a non-zero
initial state.  Nothing here knows how the simulator or the identification cut their inputs.

Importable from every test as ``lab_inputs``: pytest puts ``tests/`` on ``sys.path`` for ``tests/conftest.py``
(its default ``prepend`` import mode; the test folders have no ``__init__.py``).

Examples
--------
>>> from hypothesis import find
>>> case = find(lab_cases(models=("msd2",)), lambda c: {v.delivery for v in c.inputs.values()} == {"grid", "held"})
>>> sorted(case.u), len(case.t) >= 50
(['F', 'G'], True)
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import sympy as sp
from hypothesis import strategies as st

from phs.signals import Sampled

RATES = (50.0, 100.0, 250.0, 500.0, 1000.0, 2000.0, 5000.0, 10000.0, 20000.0, 44100.0, 50000.0)
"""Common sample rates [Hz]; others between 50 Hz and 50 kHz are drawn too."""

KINDS = ("rest", "step", "ramp", "tanh_square", "chirp", "multisine", "prbs", "noise")
"""The kinds of stretch an input is made of."""

DELIVERIES = ("grid", "grid_linear", "own_converter", "held")
"""How an input reaches the simulation: its samples on the grid as an array (an undeclared reading: straight lines
between samples, as :meth:`codegen.simulator.Simulator.run` and :meth:`phs.workflows.recording.Recording.input_signal`
document it), the same declared continuous (``Sampled(..., hold="linear")``), the samples of its own converter
(another rate and offset, straight lines between them) or held by a DAC (``hold="zoh"``)."""


_UNIT = st.integers(0, 2**20).map(lambda k: k / 2**20)  # no subnormal levels: a converter's values have a resolution
_SIGNED = _UNIT.map(lambda x: 2.0 * x - 1.0)
_SEEDS = st.integers(0, 2**32 - 1)


def log_floats(lo: float, hi: float):
    """Floats spread evenly in log scale over ``[lo, hi]`` (the bounds in either order)."""
    a, b = sorted((float(np.log10(lo)), float(np.log10(hi))))
    return _UNIT.map(lambda x: float(10.0 ** (a + (b - a) * x)))


def _log(draw, lo: float, hi: float) -> float:
    """A float drawn evenly in log scale over ``[lo, hi]`` (a strategy built once: building one per draw is slow)."""
    a, b = np.log10(lo), np.log10(hi)
    return float(10.0 ** (a + (b - a) * draw(_UNIT)))


def _between(draw, lo: float, hi: float) -> float:
    return float(lo + (hi - lo) * draw(_UNIT))


def seeds():
    return _SEEDS


# -- the stretches of an input: each draws its numbers and returns its m samples ----------------------------------
@st.composite
def _rest(draw, m, dt, A, level):
    new = level if draw(st.booleans()) else draw(_SIGNED) * A
    return np.full(m, new)


@st.composite
def _step(draw, m, dt, A, level):
    new = draw(_SIGNED) * A
    p = _between(draw, 0.0, float(m))  # where the step happens, in samples (between samples in general)
    k = np.arange(m)
    if draw(st.booleans()):  # read by point sampling: the samples jump
        return np.where(k < np.ceil(p), level, new)
    frac = np.clip(k + 0.5 - p, 0.0, 1.0)  # read by an averaging converter: one sample in between
    return level + frac * (new - level)


@st.composite
def _ramp(draw, m, dt, A, level):
    new = draw(_SIGNED) * A
    p0 = _between(draw, 0.0, float(m))
    p1 = p0 + _between(draw, 0.3, float(m) + 1.0)  # the ramp's ends lie between samples in general
    return np.interp(np.arange(m), [p0, p1], [level, new])


def _tau(m, dt):
    return np.arange(m) * dt


@st.composite
def _tanh_square(draw, m, dt, A, level):
    f = _log(draw, 1.0 / (m * dt), 0.25 / dt)
    w = _log(draw, 0.01, 1.0)  # edge width, as a share of the half-period's sine
    a = _between(draw, 0.05, 1.0) * A
    ph = _between(draw, 0.0, 2 * np.pi)
    return level + a * np.tanh(np.sin(2 * np.pi * f * _tau(m, dt) + ph) / w) / np.tanh(1.0 / w)


@st.composite
def _chirp(draw, m, dt, A, level):
    f0, f1 = _log(draw, 0.1 / (m * dt), 0.45 / dt), _log(draw, 0.1 / (m * dt), 0.45 / dt)
    a = _between(draw, 0.05, 1.0) * A
    ph = _between(draw, 0.0, 2 * np.pi)
    tau, T = _tau(m, dt), max(m * dt, dt)
    return level + a * np.sin(ph + 2 * np.pi * (f0 * tau + (f1 - f0) * tau**2 / (2 * T)))


@st.composite
def _multisine(draw, m, dt, A, level):
    k = draw(st.integers(1, 6))
    fs = [_log(draw, 0.2 / (m * dt), 0.49 / dt) for _ in range(k)]
    amps = [_between(draw, 0.05, 1.0) for _ in range(k)]
    phs = [_between(draw, 0.0, 2 * np.pi) for _ in range(k)]
    tau = _tau(m, dt)
    return level + A / k * sum(a * np.sin(2 * np.pi * f * tau + p) for f, a, p in zip(fs, amps, phs))


@st.composite
def _prbs(draw, m, dt, A, level):
    hold = draw(st.integers(1, 20))
    bits = np.random.default_rng(draw(seeds())).integers(0, 2, size=m // hold + 1)
    a = _between(draw, 0.05, 1.0) * A
    return level + a * (2.0 * np.repeat(bits, hold)[:m] - 1.0)


@st.composite
def _noise(draw, m, dt, A, level):
    a = _between(draw, 0.01, 1.0) * A
    v = np.random.default_rng(draw(seeds())).standard_normal(m + 4)
    width = draw(st.integers(1, 5))  # white, or smoothed over a few samples by the sensor
    return level + a * np.convolve(v, np.ones(width) / width, mode="same")[2:m + 2]


PIECES = {"rest": _rest, "step": _step, "ramp": _ramp, "tanh_square": _tanh_square, "chirp": _chirp,
          "multisine": _multisine, "prbs": _prbs, "noise": _noise}


@st.composite
def waveforms(draw, n: int, dt: float, amplitude: float, kinds=KINDS, max_pieces: int = 6):
    """``(values, kinds)``: ``n`` samples at spacing ``dt`` made of 1 to ``max_pieces`` stretches of ``kinds``
    in random order and of random lengths, each starting from where the last ended or with a jump.

    Examples
    --------
    >>> from hypothesis import find
    >>> v, ks = find(waveforms(100, 1e-3, 1.0), lambda w: len(w[1]) >= 3)
    >>> v.shape
    (100,)
    """
    k = draw(st.integers(1, min(max_pieces, n)))
    names = draw(st.lists(st.sampled_from(kinds), min_size=k, max_size=k))
    weights = np.array([_between(draw, 0.05, 1.0) for _ in range(k)])
    ends = np.round(np.cumsum(weights) / weights.sum() * n).astype(int)
    starts = np.concatenate([[0], ends[:-1]])
    out = np.empty(n)
    level = draw(_SIGNED) * amplitude
    for name, a, b in zip(names, starts, ends):
        if b <= a:
            continue
        v = draw(PIECES[name](int(b - a), dt, amplitude, level))
        out[a:b] = v
        level = float(v[-1])
    return out, tuple(names)


# -- inputs and recordings -------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class LabInput:
    """One recorded input: its sample times and values, how it behaves between them (``"linear"``: the
    straight line; ``"zoh"``: held), how it is handed to the simulator (``delivery``) and what it is made of."""

    times: np.ndarray
    values: np.ndarray
    hold: str
    delivery: str
    kinds: tuple

    def __call__(self, tt) -> np.ndarray:
        """The input's declared course at ``tt``: the straight line between samples, or held; the first and
        last values before and after the samples."""
        tt = np.asarray(tt, dtype=float)
        if self.hold == "linear":
            return np.interp(tt, self.times, self.values)
        return self.values[np.clip(np.searchsorted(self.times, tt, side="right") - 1, 0, len(self.times) - 1)]

    def spec(self):
        """What a simulation is given: the array on the grid, or the samples as a signal."""
        if self.delivery == "grid":
            return self.values.copy()
        return Sampled(tuple(self.times), tuple(self.values), hold=self.hold)

    def signal(self) -> Sampled:
        """The samples as a signal with their hold resolved."""
        return Sampled(tuple(self.times), tuple(self.values), hold=self.hold)

    def __repr__(self) -> str:
        return (f"LabInput({self.delivery}, {self.hold}, {len(self.times)} samples from {self.times[0]!r} every "
                f"{(self.times[-1] - self.times[0]) / max(len(self.times) - 1, 1)!r}, kinds={self.kinds})")


@dataclasses.dataclass(frozen=True)
class LabCase:
    """A model (``model``, a key of :data:`MODELS`) with parameter overrides and an initial state, and a
    recording: the time grid ``t`` and the inputs by name."""

    model: str
    t: np.ndarray
    inputs: dict
    params: dict
    x0: dict
    amplitude: float

    @property
    def system(self):
        return model(self.model)

    @property
    def u(self) -> dict:
        return {k: v.spec() for k, v in self.inputs.items()}

    @property
    def on_grid(self) -> dict:
        """The inputs' declared courses at the grid's points (what a recording's CSV would hold)."""
        return {k: v(self.t) for k, v in self.inputs.items()}

    def knots(self) -> np.ndarray:
        """Every time in ``(t[0], t[-1])`` where an input's course may change slope or jump: its sample times."""
        ts = np.concatenate([v.times for v in self.inputs.values()] or [np.zeros(0)])
        return np.unique(ts[(ts > self.t[0]) & (ts < self.t[-1])])

    def __repr__(self) -> str:
        dt = self.t[1] - self.t[0]
        return (f"LabCase({self.model!r}, {len(self.t)} samples at {1 / dt:.6g} Hz from t0={self.t[0]!r}, "
                f"params={self.params}, x0={self.x0}, inputs={self.inputs})")


_RATE = st.one_of(st.sampled_from(RATES), log_floats(50.0, 50000.0))

T0_MAX = 1e3
"""Latest start of a generated grid [s] by default: a recording's time since its program started.  Clock times of
a day or more (1e5 s, or the epoch's 1.7e9 s) lose precision in the simulator's absolute-time input templates
(see ``tests/codegen/test_fast_paths_differential.py::test_absolute_times_keep_their_precision``)."""


@st.composite
def time_grids(draw, min_samples: int = 50, max_samples: int = 300, t0_max: float = T0_MAX):
    """A uniform grid at 50 Hz to 50 kHz, ``min_samples`` to ``max_samples`` long, starting away from zero (up to
    ``t0_max`` seconds)."""
    rate = draw(_RATE)
    n = draw(st.integers(min_samples, max_samples))
    t0 = draw(st.one_of(st.floats(-2.0, 2.0), log_floats(1e-3, t0_max), st.just(0.0)))
    return t0 + np.arange(n) / rate


@st.composite
def lab_inputs(draw, t: np.ndarray, amplitude: float, deliveries=DELIVERIES, kinds=KINDS, on_grid: bool = False):
    """One input for the grid ``t``, of amplitude ``amplitude``, delivered in one of ``deliveries`` (sampled on
    the grid's own times when ``on_grid``: a recording's columns)."""
    dt = float(t[1] - t[0])
    delivery = draw(st.sampled_from(deliveries))
    hold = "zoh" if delivery == "held" else "linear"
    if delivery in ("grid", "grid_linear") or on_grid or (delivery == "held" and draw(st.booleans())):
        times = t.copy()
    else:  # its own converter: another rate, its samples between the grid's points, maybe starting late or ending early
        ratio = draw(st.sampled_from((1.0, 0.5, 2.0, 3.0, 1 / 3, 0.7)))
        offset = _between(draw, -1.0, 1.0)
        dti = dt * ratio
        first = t[0] + offset * dti
        late = draw(st.sampled_from((0.0, 0.0, 0.1, -0.1)))  # a share of the record missing at the start / end
        span = (t[-1] - t[0]) * (1 - abs(late))
        first = first + (t[-1] - t[0]) * max(late, 0.0)
        m = max(2, int(np.floor(span / dti)) + 2)
        times = first + np.arange(m) * dti
    values, names = draw(waveforms(len(times), float(np.median(np.diff(times))), amplitude, kinds))
    return LabInput(times, values, hold, delivery, names)


# -- models ------------------------------------------------------------------------------------------------------------
def _two_force_msd():
    from components import Damper, ForceSource, LinearSpring, Mass
    from phs import Measured, interconnect, series, symbol_of_state

    return interconnect("msd2", [ForceSource("F"), ForceSource("G"), Mass("m", m=1.0), LinearSpring("k", K=4.0),
                                 Damper("b", b=0.4)], [series("F", "G", "m", "k", "b")],
                        measured=[Measured("position", symbol_of_state("k.l"), "m", "spring elongation")],
                        description="mass-spring-damper under two forces")


def _forced_duffing():
    from components import Damper, ForceSource, Mass, NonlinearSpring
    from phs import Measured, Param, interconnect, series, symbol_of_state

    q = sp.Symbol("q", real=True)
    kp, k3p = Param("k", 1.0, "N/m", "linear stiffness"), Param("k3", 0.5, "N/m**3", "cubic stiffness")
    spring = NonlinearSpring("s", force=kp.symbol * q + k3p.symbol * q**3, variable=q, params=[kp, k3p])
    return interconnect("duffing2", [ForceSource("F"), ForceSource("G"), Mass("m", m=1.0), spring, Damper("b", b=0.3)],
                        [series("F", "G", "m", "s", "b")],
                        measured=[Measured("position", symbol_of_state("s.q"), "m", "spring deflection")],
                        description="Duffing oscillator under two forces")


MODELS = ("rc", "rlc", "msd", "msd2", "duffing2")
"""The small models of the differential tests: linear ones with one input (RC, RLC, mass-spring-damper) and two
(``msd2``: two forces on one mass), and a nonlinear one with two (``duffing2``: a damped Duffing oscillator)."""
LINEAR = ("rc", "rlc", "msd", "msd2")


@functools.cache
def model(name: str):
    """The system of a key of :data:`MODELS` (built once; it is immutable)."""
    from systems.examples import mass_spring_damper, rc_circuit, rlc_circuit

    return {"rc": rc_circuit, "rlc": rlc_circuit, "msd": mass_spring_damper, "msd2": _two_force_msd,
            "duffing2": _forced_duffing}[name]()


@st.composite
def _dynamics(draw, name: str, duration: float, A: float):
    """Parameter overrides giving the model a time scale between a thirtieth of the recording and three times
    it, and an initial state of the size the inputs drive it to."""
    T = duration * _log(draw, 1 / 30, 3.0)  # a time constant or a natural period
    zeta = _log(draw, 0.05, 2.0)
    w0 = 2 * np.pi / T
    r = [draw(_SIGNED) for _ in range(2)]
    if name == "rc":
        C = 1e-6
        return {"R.R": T / C}, {"C.Q": C * A * r[0]}
    if name == "rlc":
        C = 1e-6
        L = 1 / (w0**2 * C)
        return {"R.R": 2 * zeta * np.sqrt(L / C), "L.L": L}, {"L.phi": L * A * r[0] / np.sqrt(L / C), "C.Q": C * A * r[1]}
    if name in ("msd", "msd2"):
        return {"k.K": w0**2, "b.b": 2 * zeta * w0}, {"m.p": w0 * A / w0**2 * r[0], "k.l": A / w0**2 * r[1]}
    k3 = w0**2 * _log(draw, 0.1, 10.0) / (A / w0**2) ** 2  # the cubic term matters at the drive's amplitude
    return {"k": w0**2, "k3": k3, "b.b": 2 * zeta * w0}, {"m.p": w0 * A / w0**2 * r[0], "s.q": A / w0**2 * r[1]}


@st.composite
def lab_cases(draw, models=MODELS, min_samples: int = 50, max_samples: int = 300, deliveries=DELIVERIES, kinds=KINDS,
              on_grid: bool = False):
    """A :class:`LabCase`: one of ``models`` with a drawn time scale and initial state, on a drawn grid, each of its
    inputs drawn on its own (kinds and delivery; sampled on the grid when ``on_grid``, as a recording's columns)."""
    name = draw(st.sampled_from(models))
    t = draw(time_grids(min_samples, max_samples))
    A = _log(draw, 0.1, 10.0)
    inputs = {u: draw(lab_inputs(t, A, deliveries, kinds, on_grid)) for u in model(name).input_names}
    params, x0 = draw(_dynamics(name, float(t[-1] - t[0]), A))
    return LabCase(name, t, inputs, params, x0, A)
