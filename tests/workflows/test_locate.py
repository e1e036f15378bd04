"""Locating the mismatch: synthetic residuals with a known structure are found, with the right number.

Every case builds a residual whose cause is known (a friction term, a delay, a decaying tail, a
harmonic, a cubic gain, pure noise) and checks the finding that should name it.  Recordings are a few
seconds at 1 kHz, so the whole file runs in a few seconds.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phs.errors import InputDataError
from phs.workflows.diagnose.locate import KINDS, Finding, locate, plot_findings

FS = 1000.0


def _grid(seconds, fs=FS):
    return np.arange(int(round(seconds * fs))) / fs


def _first(found, kind, channel="y"):
    return next(f for f in found if f.kind == kind and f.channel == channel)


def _lowpass(x, tau, dt):
    """First-order lag (a stand-in for a model state driven by x)."""
    y = np.empty_like(x)
    acc, a = 0.0, dt / (tau + dt)
    for i, v in enumerate(x):
        acc += a * (v - acc)
        y[i] = acc
    return y


def _oscillation(t):
    """Position and velocity of a two-tone motion (not periodic at the input's frequency)."""
    x = np.sin(2 * np.pi * 0.9 * t) + 0.4 * np.sin(2 * np.pi * 2.3 * t + 1.0)
    v = 2 * np.pi * (0.9 * np.cos(2 * np.pi * 0.9 * t) + 0.4 * 2.3 * np.cos(2 * np.pi * 2.3 * t + 1.0))
    return x, v


def test_coulomb_friction_is_the_top_feature(rng):
    t = _grid(6)
    x, v = _oscillation(t)
    U = np.sin(2 * np.pi * 0.5 * t)
    r = 0.3 * np.sign(v) + 0.015 * rng.standard_normal(t.size)
    found = locate(t, {"y": r}, {"x": x, "v:v": v, "Q": _lowpass(U, 0.05, 1e-3)}, {"U": U})
    top = _first(found, "feature")
    assert top.where == "residual ~ sign(v)"
    # noise variance 0.015² against 0.3² of signal: R² = 1 / (1 + 0.0025) = 0.9975
    assert top.strength > 0.99
    assert top.details["coefficient"] == pytest.approx(0.3, rel=0.02)
    assert top.details["significant"] and top.strength > top.details["threshold"]
    # the same velocity passed by name instead of the prefix
    again = locate(t, {"y": r}, {"x": x, "vel": v}, {"U": U}, velocities=["vel"])
    assert _first(again, "feature").where == "residual ~ sign(vel)"


def test_delay_gives_the_lag_of_the_cross_correlation_peak(rng):
    t = _grid(4)
    hold = 20  # random steps every 20 ms: a broad-band input
    U = np.repeat(rng.standard_normal(t.size // hold + 1), hold)[:t.size]
    d = 15  # samples = 15 ms
    r = np.concatenate([np.full(d, U[0]), U[:-d]]) + 0.1 * rng.standard_normal(t.size)
    found = locate(t, {"y": r}, {}, {"U": U})
    lag = next(f for f in found if f.kind == "input_lag" and not f.details["derivative"])
    # ± one sample, as required; the peak of a triangle-shaped correlation is exact in the noise-free case
    assert lag.details["lag_samples"] == pytest.approx(d, abs=1)
    assert lag.details["lag_s"] == pytest.approx(0.015, abs=1e-3)
    assert lag.where.startswith("lag +15 ms (residual follows U")
    assert lag.significant


def test_negative_lag_means_the_residual_precedes_the_input(rng):
    t = _grid(3)
    U = np.repeat(rng.standard_normal(t.size // 20 + 1), 20)[:t.size]
    r = np.concatenate([U[10:], np.full(10, U[-1])])
    lag = next(f for f in locate(t, {"y": r}, {}, {"U": U}) if f.kind == "input_lag")
    assert lag.details["lag_samples"] == -10 and "precedes" in lag.where


def test_exponential_tails_after_steps_give_tau(rng):
    t = _grid(8)
    U = np.where((t % 1.6) < 0.8, 1.0, -1.0) * np.repeat([1.0, 2.0], t.size // 2)
    tau = 0.15
    # charge-retention-like tail: amplitude proportional to the step, decaying with tau
    r = np.zeros_like(t)
    du = np.diff(U, prepend=U[0])
    for i in np.flatnonzero(du):
        r[i:] += 0.05 * du[i] * np.exp(-(t[i:] - t[i]) / tau)
    r += 0.005 * rng.standard_normal(t.size)
    found = locate(t, {"y": r}, {}, {"U": U}, max_findings_per_kind=5)
    tail = next(f for f in found if f.kind == "drift" and "tau_s" in f.details)
    # the brief asks for 10 %; the variable-projection fit is far better (noise is 10 % of the amplitude)
    assert tail.details["tau_s"] == pytest.approx(tau, rel=0.10)
    assert tail.details["amplitude_per_unit_step"] == pytest.approx(0.05, rel=0.1)
    assert tail.details["sign_consistency"] == 1.0 and tail.significant
    # the energy concentrates right after the steps
    win = next(f for f in found if f.kind == "time_window" and f.details.get("event") == "step")
    assert win.details["density_ratio"] > 2


def test_third_harmonic_is_found(rng):
    t = _grid(5)
    U = np.sin(2 * np.pi * 4.0 * t)
    r = 0.2 * np.sin(2 * np.pi * 12.0 * t + 0.3) + 0.05 * rng.standard_normal(t.size)
    found = locate(t, {"y": r}, {"x": _lowpass(U, 0.01, 1e-3)}, {"U": U})
    h = _first(found, "harmonic")
    assert h.details["order"] == 3
    assert h.details["fundamental_hz"] == pytest.approx(4.0, rel=1e-3)
    # signal power 0.02 against noise 0.0025 spread over 500 Hz: nearly all residual power is in the band
    assert h.strength > 0.8 and h.significant
    assert "3rd harmonic of 4 Hz" in h.where


def test_a_line_that_is_no_harmonic_is_a_spectral_peak(rng):
    t = _grid(5)
    U = np.sin(2 * np.pi * 4.0 * t)
    r = 0.1 * np.sin(2 * np.pi * 37.0 * t) + 0.05 * rng.standard_normal(t.size)
    found = locate(t, {"y": r}, {}, {"U": U})
    peak = next(f for f in found if f.kind == "spectrum" and "peak_coherence" not in f.details)
    assert peak.details["frequency_hz"] == pytest.approx(37.0, abs=0.8)  # one bin of the averaged spectrum
    assert not [f for f in found if f.kind == "harmonic"]  # 37 Hz is no multiple of 4 Hz


def test_white_noise_is_white_and_explained_by_no_feature():
    """Over several seeds: no finding but the whiteness test, and that one says white."""
    t = _grid(3)
    x, v = _oscillation(t)
    U = np.where((t % 0.5) < 0.25, 1.0, 0.0)
    feats = {"x": x, "v:v": v, "Q": _lowpass(U, 0.03, 1e-3)}
    for seed in range(5):
        r = np.random.default_rng(seed).standard_normal(t.size)
        found = locate(t, {"y": r}, feats, {"U": U}, significant_only=False)
        white = _first(found, "whiteness")
        assert white.details["p_value"] > 0.01, seed
        feats_found = [f for f in found if f.kind == "feature"]
        assert feats_found and all(not f.significant for f in feats_found), seed
        assert all(f.strength < f.details["threshold"] for f in feats_found)
        # with the default filter only the whiteness finding is left
        assert [f.kind for f in locate(t, {"y": r}, feats, {"U": U}, seed=seed)] == ["whiteness"], seed


@pytest.mark.parametrize("noise", [0.0, 0.02])
def test_cubic_effect_scales_with_exponent_three(rng, noise):
    t = _grid(8)
    levels = np.array([0.0, 1.0, 0.0, 1.5, 0.0, 2.0, 0.0, 3.0])
    U = np.repeat(levels, t.size // levels.size)
    x = _lowpass(U, 0.02, 1e-3)  # the state follows the input within ~0.1 s of a 1 s level
    r = 0.01 * x**3 + noise * rng.standard_normal(t.size)
    found = locate(t, {"y": r}, {"x": x}, {"U": U}, noise_std={"y": noise})
    sc = _first(found, "amplitude_scaling")
    # transients of x at each step bias the segment RMS slightly; 0.15 covers it (measured: 2.9-3.0)
    assert sc.strength == pytest.approx(3.0, abs=0.15)
    assert sc.details["n_blocks"] == 4 and sc.significant
    assert _first(found, "feature").where == "residual ~ x³"


def test_rate_scaling_of_a_derivative_effect():
    t = _grid(8)
    f = np.repeat([1.0, 2.0, 4.0, 8.0], t.size // 4)
    phase = 2 * np.pi * np.cumsum(f) / FS
    U = np.sin(phase)
    r = 0.01 * np.gradient(U, 1 / FS)  # grows with the rate: exponent 1
    sc = _first(locate(t, {"y": r}, {}, {"U": U}), "rate_scaling")
    assert sc.strength == pytest.approx(1.0, abs=0.1)


def test_time_window_after_a_single_step(rng):
    t = _grid(4)
    U = np.where(t >= 2.0, 1.0, 0.0)
    r = 0.01 * rng.standard_normal(t.size)
    burst = (t >= 2.0) & (t < 2.3)
    r[burst] += 0.3 * np.sin(2 * np.pi * 20 * (t[burst] - 2.0))
    w = _first(locate(t, {"y": r}, {}, {"U": U}), "time_window")
    assert w.details["t_start"] == pytest.approx(2.0, abs=0.05) and w.details["t_end"] == pytest.approx(2.3, abs=0.05)
    assert w.details["event"] == "step" and "after the step of U at 2.00" in w.where
    assert w.strength > 0.9  # the burst holds nearly all of the energy


def test_velocity_reversals_concentrate_a_stiction_like_residual(rng):
    t = _grid(6)
    x, v = _oscillation(t)
    r = 0.01 * rng.standard_normal(t.size) + 0.5 * np.exp(-np.abs(v) / 0.2)  # large only where v ≈ 0
    found = locate(t, {"y": r}, {"x": x, "v:v": v}, {"U": np.sin(2 * np.pi * 0.5 * t)})
    win = next(f for f in found if f.kind == "time_window" and f.details.get("event") == "reversal")
    assert win.details["density_ratio"] > 2 and win.significant


def test_slow_drift_is_low_frequency(rng):
    t = _grid(10)
    U = np.sin(2 * np.pi * 2.0 * t)
    r = 0.2 * (t / t[-1]) ** 2 + 0.02 * rng.standard_normal(t.size)
    d = next(f for f in locate(t, {"y": r}, {}, {"U": U}) if f.kind == "drift")
    assert d.details["cutoff_hz"] == pytest.approx(0.2, rel=0.01)  # a tenth of the 2 Hz excitation
    # a trend is not periodic over the recording: some of its energy leaks above the cut-off (measured 0.86)
    assert d.strength > 0.8 and d.significant


def test_robust_to_zero_residual_constant_input_and_short_recording(rng):
    t = _grid(0.3)  # 300 samples
    found = locate(t, {"zero": np.zeros(t.size), "noise": rng.standard_normal(t.size)},
                   {"x": np.ones(t.size), "v:v": np.zeros(t.size)}, {"U": np.full(t.size, 2.0)}, significant_only=False)
    assert not [f for f in found if f.channel == "zero"]
    assert {f.kind for f in found} <= set(KINDS)
    assert _first(found, "whiteness", "noise").details["lags"] == 20
    json.dumps([f.to_dict() for f in found], allow_nan=False)
    assert locate(t, {}, {}, {}) == []


def test_findings_are_json_and_documented(rng):
    t = _grid(4)
    x, v = _oscillation(t)
    U = np.where((t % 1.0) < 0.5, 1.0, -1.0)
    r = 0.2 * np.sign(v) + 0.05 * x**3 + 0.02 * rng.standard_normal(t.size)
    found = locate(t, {"y": r, "z": rng.standard_normal(t.size)}, {"x": x, "v:v": v}, {"U": U},
                   significant_only=False, max_findings_per_kind=2)
    assert found
    for f in found:
        d = json.loads(json.dumps(f.to_dict(), allow_nan=False))
        assert set(d) == {"kind", "channel", "where", "strength", "meaning", "details"}
        assert f.kind in KINDS and f.meaning and f.where and isinstance(f.details["significant"], bool)
        assert sum(g.kind == f.kind and g.channel == f.channel for g in found) <= 2
    order = [(f.channel, KINDS.index(f.kind)) for f in found]
    assert order == sorted(order, key=lambda c: (["y", "z"].index(c[0]), c[1]))


@settings(max_examples=8, deadline=None)
@given(scale=st.floats(1e-6, 1e6), sign=st.sampled_from([1.0, -1.0]))
def test_findings_do_not_depend_on_the_residual_scale(scale, sign):
    """Scaling the residual changes no place and no scale-free strength."""
    t = _grid(2)
    x, v = _oscillation(t)
    U = np.where((t % 0.5) < 0.25, 1.0, 0.0)
    r = 0.2 * np.sign(v) + 0.1 * _lowpass(U, 0.05, 1e-3) + 0.02 * np.random.default_rng(3).standard_normal(t.size)
    base = locate(t, {"y": r}, {"x": x, "v:v": v}, {"U": U})
    scaled = locate(t, {"y": sign * scale * r}, {"x": x, "v:v": v}, {"U": U})
    assert [(f.kind, f.where.replace(", inverted", "")) for f in base] == \
        [(f.kind, f.where.replace(", inverted", "")) for f in scaled]
    for a, b in zip(base, scaled):
        if a.kind not in ("amplitude_scaling", "rate_scaling"):
            assert b.strength == pytest.approx(a.strength, rel=1e-3, abs=1e-6)


_SHAPES = {
    "constant": lambda n, g: np.full(n, g.normal()),
    "zero": lambda n, g: np.zeros(n),
    "noise": lambda n, g: g.standard_normal(n),
    "steps": lambda n, g: np.repeat(g.standard_normal(n), int(g.integers(1, n)))[:n],
    "sine": lambda n, g: np.sin(np.arange(n) * g.uniform(0.001, 3.0)),
    "square": lambda n, g: np.sign(np.sin(np.arange(n) * g.uniform(0.001, 1.0))),
    "tiny walk": lambda n, g: 1e-9 * np.cumsum(g.standard_normal(n)),
}


@settings(max_examples=25, deadline=None)
@given(n=st.integers(16, 400), dt=st.floats(1e-4, 1.0), seed=st.integers(0, 2**16),
       shapes=st.lists(st.sampled_from(sorted(_SHAPES)), min_size=6, max_size=6))
def test_any_valid_recording_gives_findings_as_json(n, dt, seed, shapes):
    """Constant, zero, stepped, periodic, tiny or short signals never break the analyses."""
    g = np.random.default_rng(seed)
    sig = [_SHAPES[k](n, g) for k in shapes]
    found = locate(np.arange(n) * dt + 3.0, {"a": sig[0], "b": sig[1]}, {"x": sig[2], "v:v": sig[3]},
                   {"U": sig[4], "W": sig[5]}, noise_std={"a": 0.1}, significant_only=False)
    json.dumps([f.to_dict() for f in found], allow_nan=False)
    for ch, r in (("a", sig[0]), ("b", sig[1])):
        mine = [f for f in found if f.channel == ch]
        if not np.any(r):
            assert not mine  # a zero residual has nothing to locate
        elif np.ptp(r) == 0:
            assert {f.kind for f in mine} == {"drift"}  # a constant residual is all offset
            assert next(f for f in mine if "offset_share" in f.details).details["offset_share"] == pytest.approx(1.0)


@pytest.mark.parametrize("bad, culprit", [
    (lambda t: ({"y": np.r_[np.nan, np.zeros(t.size - 1)]}, {}, {}), "residual 'y'"),
    (lambda t: ({"y": np.zeros(t.size)}, {"x": np.zeros(t.size - 1)}, {}), "feature 'x'"),
    (lambda t: ({"y": np.zeros(t.size)}, {}, {"U": np.r_[np.zeros(t.size - 1), np.inf]}), "input 'U'"),
    (lambda t: ({"y": np.zeros((t.size, 2))}, {}, {}), "residual 'y'"),
])
def test_bad_signals_name_the_culprit(bad, culprit):
    t = _grid(0.1)
    with pytest.raises(InputDataError, match=culprit):
        locate(t, *bad(t))


def test_bad_arguments_name_the_culprit():
    t = _grid(0.1)
    z = np.zeros(t.size)
    with pytest.raises(InputDataError, match="velocity 'w'"):
        locate(t, {"y": z}, {"x": z}, {}, velocities=["w"])
    with pytest.raises(InputDataError, match="noise_std names 'q'"):
        locate(t, {"y": z}, {}, {}, noise_std={"q": 1.0})
    with pytest.raises(InputDataError, match="not uniform"):
        locate(np.r_[t[:-1], t[-1] + 0.5], {"y": z}, {}, {})
    with pytest.raises(InputDataError, match="finding kind 'bogus'"):
        Finding("bogus", "y", "", 0.0, "")
    with pytest.raises(TypeError, match="bogus"):
        locate(t, {"y": z}, {}, {}, bogus=1)


def test_plot_is_written_atomically(tmp_path, rng):
    t = _grid(3)
    x, v = _oscillation(t)
    U = np.where((t % 1.0) < 0.5, 1.0, 0.0)
    res = {"y": 0.2 * np.sign(v) + 0.02 * rng.standard_normal(t.size), "z": np.zeros(t.size)}
    found = locate(t, res, {"x": x, "v:v": v}, {"U": U})
    p = plot_findings(t, res, {"x": x, "v:v": v}, {"U": U}, found, tmp_path / "locate.png")
    assert open(p, "rb").read(8) == b"\x89PNG\r\n\x1a\n"
    assert sorted(os.listdir(tmp_path)) == ["locate.png"]  # no temporary file left
    with pytest.raises(InputDataError, match="does not exist"):
        plot_findings(t, res, {}, {"U": U}, found, tmp_path / "missing" / "locate.png")
    with pytest.raises(InputDataError, match=".png, .svg or .pdf"):
        plot_findings(t, res, {}, {"U": U}, found, tmp_path / "locate.gif")
    assert sorted(os.listdir(tmp_path)) == ["locate.png"]


def test_twenty_seconds_two_channels_ten_features_is_fast(rng):
    t = _grid(20)
    U = np.where((t % 2.0) < 1.0, 1.0, -1.0) * np.repeat([1.0, 2.0, 3.0, 4.0], t.size // 4)
    feats = {f"s{i}": np.sin(2 * np.pi * (0.3 + 0.2 * i) * t + i) for i in range(8)}
    x, v = _oscillation(t)
    feats.update({"x": x, "v:v": v})
    res = {"a": 0.1 * np.sign(v) + 0.01 * rng.standard_normal(t.size), "b": rng.standard_normal(t.size)}
    n = 500
    locate(t[:n], {k: r[:n] for k, r in res.items()}, {k: f[:n] for k, f in feats.items()}, {"U": U[:n]})  # warm-up
    start = time.process_time()  # CPU time of this process: steady when others load the shared machine
    locate(t, res, feats, {"U": U})
    elapsed = time.process_time() - start
    # the requirement is 2 s; measured 0.4-0.6 s CPU (0.3-2 s wall, depending on the load of the shared machine)
    assert elapsed < 2.0, elapsed
