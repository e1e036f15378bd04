"""Concealed-effect recordings (``examples/concealed_effects.py``).

Every truth hides its effect from the refitted nominal actuator (>= 85 % fit on both training
channels) yet leaves it detectable (on some validation channel the refit scores at least 3 points
below the noise-limited fit); the no-effect control's refit is noise-limited.  Recordings are
deterministic; the truths built as port-Hamiltonian systems are passive; the command line writes
every file or none.
"""

from __future__ import annotations

import doctest
import importlib
import importlib.util
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from phs.errors import InputDataError
from phs.workflows.recording import Recording

ROOT = Path(__file__).resolve().parents[2]


def _module():
    """The generator, imported as ``examples.concealed_effects`` (or loaded by path when the
    repository root is not on ``sys.path``)."""
    try:
        return importlib.import_module("examples.concealed_effects")
    except ImportError:
        name = "concealed_effects"
        if name not in sys.modules:
            spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / "concealed_effects.py")
            mod = importlib.util.module_from_spec(spec)
            sys.modules[name] = mod
            spec.loader.exec_module(mod)
        return sys.modules[name]


ce = _module()
LIBRARY = {"charge_retention", "leakage", "series_resistance", "coulomb_friction", "viscoelastic_creep", "cubic_stiffness",
           "hysteresis", "quadratic_drag", "added_mass", "input_saturation", "slew_rate_limit", "time_delay", "offset"}
# the shortest recordings that still hold every program's revealing part (the first 3 s of each program hold
# its steps and holds, its square waves or its chirp); the full length is checked under -m slow
SECONDS = 3.0
# "not obviously structured": the systematic part of the refit's residual (truth minus refitted nominal) stays
# within a few noise standard deviations in RMS on every channel (measured at most 3.9 on 3 s runs, 3.6 on 20 s)
MAX_MISMATCH_TO_NOISE = 6.0


def test_every_effect_of_the_library_has_a_case_and_there_is_a_control():
    assert set(ce.EFFECTS) == LIBRARY | {"none"}
    assert len(ce.EFFECTS) == len(set(ce.EFFECTS))


def _assert_concealed_and_detectable(r):
    ch = ("position", "current")
    if r["effect"] == "none":
        # the control is the nominal structure: the refit reaches the noise-limited fit (0.5 points: the
        # refit also fits a little of the noise on training and misses as little on validation)
        assert r["noise_limited"], r
        assert not r["detectable"], r
        return
    # concealed: at least 85 % on both training channels, yet below the noise-limited fit on one of them
    assert all(r["nominal_fit"][c] >= ce.MIN_FIT for c in ch), r["nominal_fit"]
    assert max(r["truth_fit"][c] - r["nominal_fit"][c] for c in ch) > 0.3, (r["truth_fit"], r["nominal_fit"])
    assert all(r["mismatch_to_noise"][c] <= MAX_MISMATCH_TO_NOISE for c in ch), r["mismatch_to_noise"]
    # detectable: on some validation channel the truth's own (noise-limited) fit is >= 3 points better
    assert max(r["validation_gap"].values()) >= ce.MIN_GAP, r["validation_gap"]
    assert r["concealed"] and r["detectable"]


@pytest.mark.parametrize("effect", ce.EFFECTS)
def test_effect_is_concealed_from_the_refit_nominal_model_yet_detectable(effect):
    _assert_concealed_and_detectable(ce.concealment(effect, seconds=SECONDS))


@pytest.mark.slow
@pytest.mark.parametrize("effect", ce.EFFECTS)
def test_effect_is_concealed_yet_detectable_at_full_length(effect):
    _assert_concealed_and_detectable(ce.concealment(effect, seconds=20.0))


def test_generation_is_deterministic_and_seeded():
    a, ia = ce.generate("hysteresis", seconds=1.0)
    b, _ = ce.generate("hysteresis", seconds=1.0)
    c, ic = ce.generate("hysteresis", seconds=1.0, seed=1)
    for name in ("U", "position", "current"):
        assert np.array_equal(a[name], b[name]), name
    assert np.array_equal(a["U"], c["U"])
    assert np.array_equal(ia["clean"]["position"], ic["clean"]["position"])
    assert not np.array_equal(a["position"], c["position"])
    # the noise has the documented size: 1 % of the position's range, 3 % of the current's std
    assert ia["noise_std"]["position"] == pytest.approx(0.01 * np.ptp(ia["clean"]["position"]))
    assert ia["noise_std"]["current"] == pytest.approx(0.03 * np.std(ia["clean"]["current"]))
    resid = a["position"] - ia["clean"]["position"]
    assert np.std(resid) == pytest.approx(ia["noise_std"]["position"], rel=0.15)  # 1001 samples: ~4 % sampling error
    v, iv = ce.generate("hysteresis", seconds=1.0, validation=True)
    assert not np.array_equal(v["U"], a["U"]) and iv["validation"]
    assert ia["form"].startswith("Bouc-Wen") and ia["parameters"]["n"] == 2
    assert a.names == ["U", "position", "current"] and a.dt == pytest.approx(1e-3)


def test_programs_stay_below_pull_in_and_training_inputs_have_few_kinks():
    """Commands stay below 0.75 V_pi; training commands are piecewise linear with at most one kink per
    20 samples, so identification integrates them piece by piece."""
    for effect in ce.EFFECTS:
        for validation in (False, True):
            t, U = ce.program(effect, 20.0, validation)
            assert np.max(np.abs(U)) <= 0.75 * ce.V_PULL_IN, (effect, validation)
            assert U[0] == 0.0 and len(t) == 20001
            if not validation:
                d2 = np.abs(np.diff(U, 2)) > 1e-12 * np.max(np.abs(U))
                assert d2.sum() <= (len(U) - 1) // 20, (effect, int(d2.sum()))


@pytest.mark.parametrize("effect", ce.EFFECTS)
def test_truth_is_port_hamiltonian_and_passive(effect):
    """J skew-symmetric and the dissipation form [[R, P], [P^T, S]] positive semidefinite at 40 states sampled
    in the declared box (eigenvalues >= -1e-9 of the largest: rounding of the stiff electrical entries)."""
    s = ce.truth(effect).system
    assert sp.simplify(s.J + s.J.T) == sp.zeros(*s.J.shape)
    form = sp.Matrix(sp.BlockMatrix([[s.R, s.P], [s.P.T, s.S]]))
    f = s.lambdify(form)
    p = s.param_vector()
    for x in s.sample_box(40, seed=3):
        M = np.asarray(f(x, np.zeros(len(s.u)), p), dtype=float)
        ev = np.linalg.eigvalsh((M + M.T) / 2)
        assert ev.min() >= -1e-9 * max(abs(ev).max(), 1e-300), (effect, x, ev)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-30.0, 30.0), min_size=3, max_size=40), st.floats(100.0, 50000.0))
def test_rate_limiter_bounds_the_slope_and_follows_slow_commands(levels, rate):
    t = np.arange(len(levels)) / ce.FS
    U = np.asarray(levels)
    tt, y = ce._rate_limited(t, U, rate)
    slope = np.abs(np.diff(y) / np.diff(tt))
    assert slope.max(initial=0.0) <= rate * (1 + 1e-9)
    assert y[0] == U[0] and np.all(np.diff(tt) > 0)
    if np.max(np.abs(np.diff(U)), initial=0.0) * ce.FS <= rate:  # never limited: the command itself
        assert np.allclose(np.interp(t, tt, y), U, atol=1e-9 * max(1.0, np.abs(U).max()))


def test_amplifier_effects_transform_the_command():
    t = np.arange(6) / ce.FS
    U = np.array([0.0, 0.0, 10.0, 10.0, 10.0, 10.0])
    tt, y = ce.truth("time_delay").applied(t, U)
    assert np.interp(0.002 + ce.SIZES["time_delay"]["delay"], tt, y) == pytest.approx(10.0)
    assert np.interp(0.0015, tt, y) == pytest.approx(0.0)
    _, ys = ce.truth("input_saturation").applied(t, np.array([-25.0, 0.0, 5.0, 25.0, 0.0, 0.0]))
    assert -25.0 < ys[0] < 0.0 and ys[1] == 0.0 and 4.9 < ys[2] < 5.0 and 0.0 < ys[3] < 25.0
    assert abs(ys[0]) < ys[3]  # asymmetric: negative voltages saturate harder


def test_invalid_arguments_name_the_culprit():
    with pytest.raises(InputDataError, match="unknown effect 'stiction'"):
        ce.generate("stiction", seconds=1.0)
    with pytest.raises(InputDataError, match="at least 0.5"):
        ce.program("none", 0.1)
    with pytest.raises(InputDataError, match="must be positive"):
        ce.truth("leakage", size=0.0)


def test_command_line_writes_every_file_or_none(tmp_path, capsys):
    out = tmp_path / "rec"
    assert ce.main(["--out", str(out), "--seconds", "0.5", "--effects", "offset,none", "--quiet"]) == 0
    assert sorted(os.listdir(out)) == ["cases.json", "none_train.csv", "none_validation.csv", "offset_train.csv",
                                       "offset_validation.csv"]
    rec = Recording.from_csv(out / "offset_train.csv")
    ref, info = ce.generate("offset", seconds=0.5)
    assert rec.names == ["U", "position", "current"]
    assert np.allclose(rec["position"], ref["position"], rtol=1e-15, atol=0)
    cases = json.loads((out / "cases.json").read_text())
    assert cases["offset"]["parameters"] == pytest.approx(info["parameters"])
    assert cases["none"]["nominal_free"] == ["k", "b", "eps"]
    bad = tmp_path / "bad"
    with pytest.raises(SystemExit):
        ce.main(["--out", str(bad), "--seconds", "0.5", "--effects", "none,stiction", "--quiet"])
    assert "unknown effect(s) ['stiction']" in capsys.readouterr().err
    assert not bad.exists()


def test_docstring_examples_run():
    res = doctest.testmod(ce, optionflags=doctest.ELLIPSIS)
    assert res.failed == 0 and res.attempted >= 8
