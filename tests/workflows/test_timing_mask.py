"""Validation samples an abrupt input change's timing decides (phs.workflows.diagnose.timing).

The structural laws on generated inputs (steps on and off the sample grid, smooth edges, chirps, noise, odd
lengths): which intervals are abrupt, the two halved courses bracketing the straight line; then the mask against
a truth whose steps fall between the samples, where the truth itself replayed from the samples misses the
sample after each step by far more than the noise.
"""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from codegen import simulate
from phs.kinks import ABRUPT_SIZE, ABRUPT_WINDOW, abrupt_runs
from phs.signals import Sampled
from phs.workflows.diagnose.hypotheses import Data
from phs.workflows.diagnose.timing import TIMING_SHARE, halved_course, timing_mask, without_timing_samples
from phs.workflows.recording import Recording
from systems.examples import rc_circuit


@st.composite
def stepped(draw):
    """Levels held over stretches of at least ABRUPT_WINDOW + 1 samples (a DAC's command): the steps' intervals."""
    n_steps = draw(st.integers(1, 6))
    lengths = draw(st.lists(st.integers(ABRUPT_WINDOW + 1, 40), min_size=n_steps + 1, max_size=n_steps + 1))
    levels = draw(st.lists(st.floats(-5, 5), min_size=n_steps + 1, max_size=n_steps + 1))
    v = np.concatenate([np.full(n, lv) for n, lv in zip(lengths, levels)])
    span = float(np.ptp(v))
    steps = np.cumsum(lengths)[:-1] - 1
    big = [int(k) for k in steps if abs(v[k + 1] - v[k]) > ABRUPT_SIZE * span]
    return v, big


@given(stepped())
def test_every_step_between_held_levels_is_one_abrupt_interval(case):
    v, steps = case
    assert abrupt_runs(v) == [(k, k + 1) for k in steps]


@given(st.floats(0.002, 0.2), st.floats(0.0, 6.3), st.integers(40, 401), st.floats(0.0, 0.002))
def test_a_sampled_sine_or_chirp_has_no_abrupt_interval(cycles_per_sample, phase, n, noise):
    """Down to five samples per period, with noise of 0.2 % of the amplitude, a chirp up to that frequency too."""
    k = np.arange(n)
    rng = np.random.default_rng(n)
    sine = np.sin(2 * np.pi * cycles_per_sample * k + phase) + noise * rng.standard_normal(n)
    chirp = np.sin(2 * np.pi * cycles_per_sample * k * k / (2 * n) + phase) + noise * rng.standard_normal(n)
    assert abrupt_runs(sine) == []
    assert abrupt_runs(chirp) == []


@given(st.integers(ABRUPT_WINDOW + 1, 60), st.integers(10, 50), st.floats(0.1, 10.0))
def test_a_smooth_edge_over_enough_samples_is_not_abrupt(width, flat, height):
    """A raised-cosine edge over at least ABRUPT_WINDOW + 1 intervals: its largest interval change is the median
    of the window around it (the flats fill at most half the window)."""
    s = np.arange(width + 1) / width
    v = np.concatenate([np.zeros(flat), height * (0.5 - 0.5 * np.cos(np.pi * s)), np.full(flat, height)])
    assert abrupt_runs(v) == []


@given(st.lists(st.floats(-3, 3), min_size=3, max_size=30), st.data())
def test_the_halved_courses_pass_through_the_samples_and_bracket_the_line(values, data):
    v = np.asarray(values)
    t = np.cumsum(np.r_[0.0, data.draw(st.lists(st.floats(0.1, 2.0), min_size=len(v) - 1, max_size=len(v) - 1))])
    k = data.draw(st.integers(0, len(v) - 2))
    runs = [(k, k + 1)]
    courses = [halved_course(t, v, runs, side) for side in (True, False)]
    for times, vals in courses:
        assert np.all(np.diff(times) > 0)
        np.testing.assert_allclose(np.interp(t, times, vals), v, atol=1e-12)
    mid = 0.5 * (t[k] + t[k + 1])
    line = 0.5 * (v[k] + v[k + 1])
    a, b = (float(np.interp(mid, *c)) for c in courses)
    assert min(a, b) - 1e-12 <= line <= max(a, b) + 1e-12
    np.testing.assert_allclose(0.5 * (a + b), line, atol=1e-12)  # the line is their mean at the midpoint


def _off_grid_truth(dt, n, tau, seed, noise):
    """An RC circuit (time constant ``tau``) driven by steps at times between the samples, each a ramp of 1 % of
    a sample period, in the first or last 30 % of its interval (a step near the middle is replayed nearly right by
    the straight line, and its samples are kept: TIMING_EVIDENCE); its samples with white noise of std ``noise``
    (volts) and the recorded command."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    frac = rng.uniform(0.05, 0.3, 8) + rng.choice([0.0, 0.65], 8)
    switch = np.sort(rng.choice(np.arange(20, n - 20), size=8, replace=False)) + frac
    levels = np.cumsum(rng.choice([-1.0, 1.0], 9) * rng.uniform(0.5, 1.0, 9))  # steps of 0.5-1 V
    times, values = [0.0], [levels[0]]
    for j, k in enumerate(switch):
        times += [k * dt, (k + 0.01) * dt]
        values += [levels[j], levels[j + 1]]
    times.append(t[-1] + dt)
    values.append(levels[-1])
    sys_ = rc_circuit(R=tau / 1e-6)
    clean = simulate(sys_, t, u={"U": Sampled(tuple(times), tuple(values))}, rtol=1e-10)["v_C"]
    u = np.interp(t, times, values)
    rec = Recording.from_arrays(t, {"U": u, "v_C": clean + noise * rng.standard_normal(n)})
    return sys_, rec, clean


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_mask_leaves_out_what_the_truth_replayed_from_samples_misses(seed):
    """The truth (its own parameters) replayed from the samples misses the sample after each step by up to half
    a step (its time constant is a fifth of a sample period); with those left out its residual is the noise's
    (within 30 %: 1 000 samples, the sum's own spread is 4.5 %), and few samples are left out."""
    sys_, rec, clean = _off_grid_truth(dt=1e-3, n=1000, tau=2e-4, seed=seed, noise=1e-3)
    replay = simulate(sys_, rec.t, u={"U": Sampled(tuple(rec.t), tuple(rec["U"]), hold="linear")}, rtol=1e-10)["v_C"]
    data = Data(rec, rec, np.ones(len(rec), bool), None, ["v_C"], [], {}, [], None)
    mask = timing_mask(NS(system=sys_, x0=np.zeros(1)), data)
    e = clean - replay
    assert np.sum(e**2) > 10 * len(e) * 1e-6          # the truth's own replay is far off at the steps
    assert np.sum(e[mask] ** 2) < 0.3 * mask.sum() * 1e-6  # ... and within the noise elsewhere
    assert 8 <= int(np.sum(~mask)) <= 24                # one or two samples per step
    y = np.asarray(rec["v_C"])
    assert np.sum((y - replay)[mask] ** 2) / (mask.sum() * 1e-6) == pytest.approx(1.0, abs=0.3)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_recording_the_straight_lines_replay_loses_no_sample(seed):
    """The same steps, but the command's course is the straight lines through its samples (a simulation's own
    output): the model replays the samples after each step within the noise, far better than their timing would
    allow, and they stay evidence."""
    sys_, rec, _ = _off_grid_truth(dt=1e-3, n=1000, tau=2e-4, seed=seed, noise=1e-3)
    u = np.asarray(rec["U"])
    y = simulate(sys_, rec.t, u={"U": u})["v_C"] + 1e-3 * np.random.default_rng(seed).standard_normal(len(u))
    lines = Recording.from_arrays(rec.t, {"U": u, "v_C": y})
    data = Data(lines, lines, np.ones(len(lines), bool), None, ["v_C"], [], {}, [], None)
    assert timing_mask(NS(system=sys_, x0=np.zeros(1)), data).all()


def test_a_slow_response_or_a_held_input_loses_no_sample():
    """A time constant of 500 sample periods: half a period's timing moves a sample by at most a step over 1 000
    (steps of at most 1 V: 1 mV, under the √12 σ = 3.5 mV a sample may move); a command declared held (zoh)
    changes at a sample, where the recording says."""
    sys_, rec, _ = _off_grid_truth(dt=1e-3, n=600, tau=0.5, seed=3, noise=1e-3)
    data = Data(rec, rec, np.ones(len(rec), bool), None, ["v_C"], [], {}, [], None)
    assert timing_mask(NS(system=sys_, x0=np.zeros(1)), data).all()
    fast, rec2, _ = _off_grid_truth(dt=1e-3, n=600, tau=2e-4, seed=3, noise=1e-3)
    held = rec2.with_holds({"U": "zoh"})
    data2 = Data(held, held, np.ones(len(held), bool), None, ["v_C"], [], {}, [], None)
    assert timing_mask(NS(system=fast, x0=np.zeros(1)), data2).all()
    data3 = Data(rec2, rec2, np.ones(len(rec2), bool), None, ["v_C"], [], {}, [], None)
    assert not timing_mask(NS(system=fast, x0=np.zeros(1)), data3).all()


def test_the_cap_keeps_the_largest_and_the_nominal_scores_follow_the_mask():
    """Steps every 8 samples into a fast response: more than TIMING_SHARE of the samples would go; the cap keeps
    the share and leaves out those the timing moves most.  The nominal model's validation residual is then the
    sum over the samples left (recomputed from its validation course)."""
    dt, n = 1e-3, 800
    t = np.arange(n) * dt
    k = np.arange(8, n - 8, 8)                       # a step every 8 samples, a fifth into its interval
    times = np.r_[0.0, np.ravel(np.c_[(k + 0.2) * dt, (k + 0.21) * dt]), t[-1] + dt]
    levels = (np.arange(len(k) + 1) % 2).astype(float)
    values = np.r_[0.0, np.ravel(np.c_[levels[:-1], levels[1:]]), levels[-1]]
    u = np.interp(t, times, values)
    sys_ = rc_circuit(R=200.0)
    y = simulate(sys_, t, u={"U": Sampled(tuple(times), tuple(values))})["v_C"] + 1e-3 * np.random.default_rng(4).standard_normal(n)
    rec = Recording.from_arrays(t, {"U": u, "v_C": y})
    data = Data(rec, rec, np.ones(n, bool), None, ["v_C"], [], {}, [], None)
    course = simulate(sys_, t, u={"U": u})["v_C"]
    nominal = NS(system=sys_, x0=np.zeros(1), simulated={"validation": {"v_C": course}}, validation_rss=-1.0,
                 validation_fit_percent={})
    mask = timing_mask(nominal, data)
    assert int(np.sum(~mask)) == int(TIMING_SHARE * n)
    import dataclasses

    @dataclasses.dataclass
    class H:
        system: object
        x0: object
        simulated: dict
        validation_rss: float
        validation_fit_percent: dict

    h, d = without_timing_samples(H(sys_, np.zeros(1), {"validation": {"v_C": course}}, -1.0, {}), data)
    assert np.array_equal(d.val_mask, mask)
    assert h.validation_rss == pytest.approx(np.sum((y - course)[mask] ** 2) / np.var(y[mask]), rel=1e-9)


def test_the_lab_protocols_held_edges_that_straddle_a_sample_are_left_out():
    """A lab recording (examples/lab_protocols.py: held squares whose one-sample edges straddle a sample, an
    independent truth integrated by scipy): the truth's own model replayed from the samples misses the current
    right after those edges by far more than the noise; the mask leaves out those samples only (the edges on
    the sample grid are replayed right and kept), and what is left is within the noise (its residual at most
    1.2 times the noise's: a sum over 10 000 samples spreads by 1.4 %, and the straight lines through a chirp's
    samples add a little)."""
    from examples import lab_protocols as lp

    val, info = lp.generate("esa:none@1kHz", seconds=10.0, seed=2, validation=True)  # its held 3 Hz squares start at 8.6 s
    tr = lp.truth_of("esa", "none")
    x0 = np.asarray(lp._rest_state(tr, lp.ACTUATORS["esa"]), float)
    data = Data(val, val, np.ones(len(val), bool), None, ["position", "current"], [], {}, [], None)
    mask = timing_mask(NS(system=tr.system, x0=x0), data)
    replay = simulate(tr.system, val.t, u={"U": Sampled(tuple(val.t), tuple(val["U"]), hold="linear")},
                      x0=dict(zip(tr.system.state_names, x0)), rtol=1e-8)
    s = info["noise_std"]["current"]
    e = np.asarray(info["clean"]["current"]) - np.asarray(replay["current"])
    assert np.max(np.abs(e)) > 50 * s                       # the edges that straddle a sample
    assert 1 <= int(np.sum(~mask)) <= 0.01 * len(mask)
    y = np.asarray(val["current"])
    r = y - np.asarray(replay["current"])
    assert np.sum(r[mask] ** 2) <= 1.2 * mask.sum() * s**2
    assert np.sum(r**2) > 3 * len(r) * s**2                 # ... which, kept, dominated the residual
