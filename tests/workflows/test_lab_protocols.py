"""Lab-protocol recordings (``examples/lab_protocols.py``).

The truths are integrated outside the framework's simulator (scipy's Radau on the lambdified right-hand
side); here that integration is checked once against ``codegen.simulate`` at small size, on commands
both read identically (held between samples).  The commands hold every kind of block, stay continuous
and inside the actuators' safe range; bad case names are refused in one line.
"""

from __future__ import annotations

import doctest

import numpy as np
import pytest

from codegen import simulate
from examples import lab_protocols as lp
from phs.errors import InputDataError
from phs.signals import Sampled


def _held(t, U):
    """The samples held from each sample time to the next (as ``Sampled(..., hold="zoh")`` reads them)."""
    return lambda tt: U[np.clip(np.searchsorted(t, tt, side="right") - 1, 0, len(U) - 1)]


@pytest.mark.parametrize("actuator, effect, seconds", [("esa", "charge_retention", 1.6), ("msd", "none", 1.2)])
def test_independent_integration_agrees_with_codegen(actuator, effect, seconds):
    """The validation protocol's rest, PRBS and (msd) staircase at 1 kHz, held between samples: the scipy
    integration and CVODES (both at rtol 1e-8) agree to 1e-5 of each channel's range (measured: at most 4.3e-7, esa position;
    the current's spikes at the edges decay within microseconds, between samples)."""
    fs = 1000.0
    tr = lp.truth_of(actuator, effect)
    act = lp.ACTUATORS[actuator]
    t = np.arange(int(seconds * fs) + 1) / fs
    fn, _ = lp.command(actuator, seconds, fs, validation=True)
    U = fn(t)
    edges = t[1:][np.diff(U) != 0]
    assert len(edges) >= 5  # the PRBS switches
    x0 = lp._rest_state(tr, act)
    ours = lp.simulate_truth(tr, t, U, x0, act.held_inputs, edges=edges, command_fn=_held(t, U))
    u = {act.command: Sampled(tuple(t), tuple(U), hold="zoh"), **dict(act.held_inputs)}
    ref = simulate(tr.system, t, u=u, x0=dict(zip(tr.system.state_names, x0)), rtol=1e-8)
    for ch in act.channels:
        y = np.asarray(ref[ch], dtype=float)
        assert np.max(np.abs(ours[ch] - y)) <= 1e-5 * np.ptp(y), ch


@pytest.mark.parametrize("actuator", ["esa", "msd"])
def test_commands_hold_every_block_kind_stay_continuous_and_in_range(actuator):
    act = lp.ACTUATORS[actuator]
    assert {b[0] for b in act.training} == {"rest", "squares", "stairs", "chirp", "prbs"}
    assert {b[5] > 0 for b in act.training if b[0] == "squares"} == {True, False}  # smooth-edged and held squares
    fs = 1000.0
    fn, edges = lp.command(actuator, 17.0, fs)
    fine = np.arange(0.0, 17.0, 1e-5)
    U = fn(fine)
    # continuous: the steepest part is a one-sample ramp of a held edge (at most the command's whole span per
    # millisecond), so 10 us apart two values differ by at most a hundredth of that span; a jump would be the
    # whole step (38 V from -16 to 22 V between two blocks of the esa protocol)
    span = float(np.ptp(U))
    assert np.max(np.abs(np.diff(U))) <= 1.05 * span / 100
    lo, hi = (-26.0, 26.0) if actuator == "esa" else (0.0, 3000.0)  # esa: below 0.75 of its 34.9 V pull-in
    assert lo <= U.min() and U.max() <= hi
    assert U[0] == act.rest and len(edges) > 50
    # the protocol repeats until the end: the last seconds are not all rest
    assert np.ptp(U[fine > 15.0]) > 0.2 * span


def test_recordings_are_deterministic_and_noisy_per_split():
    a, info = lp.generate("msd:none@500Hz", seconds=1.2)
    b, _ = lp.generate("msd:none@500Hz", seconds=1.2)
    v, _ = lp.generate("msd:none@500Hz", seconds=0.6, validation=True)
    assert np.array_equal(a["displacement"], b["displacement"])
    assert not np.array_equal(a["displacement"], v["displacement"])
    assert len(a) == 601 and a.names == ["V", "F_load", "displacement"]
    noise = a["displacement"] - info["clean"]["displacement"]
    assert np.std(noise) == pytest.approx(info["noise_std"]["displacement"], rel=0.2)  # 601 samples: 3 sigma is 9 %
    assert info["free"] == ["m", "b", "a_v1", "a_v2", "A_m2"] and set(info["x0"]) == {"x", "p"}


def test_a_pair_at_any_rate_is_a_case_of_its_own():
    """Any ``actuator:effect@rate`` is a case (``parse_case``): a pair of effects of the electrostatic actuator's
    truths at a rate of the lab's; it has its own noise stream, and its truth holds both effects' states."""
    rec, info = lp.generate("esa:viscoelastic_creep+cubic_stiffness@2kHz", seconds=0.6)
    assert len(rec) == 1201 and info["rate"] == 2000.0 and info["effect"] == "viscoelastic_creep+cubic_stiffness"
    assert set(info["parameters"]) == {"viscoelastic_creep", "cubic_stiffness"} and info["free"] == ["k", "b", "eps", "g0", "m"]
    assert lp.truth_of("esa", info["effect"]).system.state_names[3:] == ["ve1.z", "ve2.z"]  # the creep's arms
    noise = rec["position"] - info["clean"]["position"]
    assert np.std(noise) == pytest.approx(info["noise_std"]["position"], rel=0.15)  # 1201 samples: 3 sigma is 6 %
    assert lp._case_seed(info["case"]) >= 1000 > len(lp.LAB_CASES)  # a noise stream apart from the listed cases'


@pytest.mark.parametrize("call, words", [
    (lambda: lp.generate("esa:leakage@3kHz"), "unknown lab case 'esa:leakage@3kHz'"),
    (lambda: lp.generate("esa:cubic_stiffness@500Hz", seconds=0.1), "seconds must be at least 0.5"),
    (lambda: lp.msd_truth("hysteresis"), "unknown effect 'hysteresis' for msd"),
    (lambda: lp.command("rod", 1.0, 1000.0), "unknown actuator 'rod'"),
    (lambda: lp.generate("esa:leakage+warp@1kHz"), "lab case 'esa:leakage+warp@1kHz': unknown effect 'warp'"),
    (lambda: lp.generate("msd:leakage@1kHz"), "lab case 'msd:leakage@1kHz': unknown effect 'leakage' for msd"),
    (lambda: lp.generate("esa:leakage+offset+added_mass@1kHz"), "unknown lab case"),
    (lambda: lp.generate("esa:__import__('os')@1kHz"), "unknown lab case"),
])
def test_bad_names_are_refused_in_one_line(call, words):
    with pytest.raises(InputDataError) as exc:
        call()
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_docstring_examples_run():
    """``examples/`` is outside the doctest paths: the module's examples run here."""
    result = doctest.testmod(lp, optionflags=doctest.ELLIPSIS)
    assert result.attempted >= 8 and result.failed == 0
