"""Recordings of truths outside the library, integrated from hand-written equations (``examples/concealed_outside.py``).

The truths' right-hand sides are written out with numpy and integrated by scipy; here they are checked
against the framework's own simulation of the actuator (``codegen.simulate`` of components), once with
the effect made negligible (``size`` 1e-9) for every case and once at full size for the appendage, which
components can express too.  The recordings are deterministic, the validation run is another, every
effect shows above the noise at size 1, and bad cases and sizes are refused in one line.
"""

from __future__ import annotations

import doctest

import numpy as np
import pytest

from codegen import simulate
from examples import concealed_outside as co
from examples.concealed_effects import program
from examples.concealed_truths import BASE
from phs.errors import InputDataError
from phs.signals import Sampled
from systems.electrostatic_actuator import electrostatic_actuator

CHANNELS = ("position", "current")
# Agreement of the scipy integration (LSODA, rtol 1e-10) with CVODES (rtol 1e-11: at 1e-9 CVODES itself is 6e-5 of
# the current's range off on the appendage's validation run), as a share of each channel's range.  Measured: position
# at most 2.4e-9, current 4.1e-7 (the current (U - Q/C(x)) / R_s is a difference of two nearly equal voltages).
# 1e-5 of the range is 25 times that, 40 times below the current's noise (3 % of its std, 3.9e-4 of its range on
# the validation run), and 200 times below what reading the validation run's chirp as straight lines between samples
# would make of the current (2.0e-3; the position: 8.4e-4), the misreading the spline of ``reading`` avoids.
TOL = 1e-5
RTOL_FRAMEWORK = 1e-11


@pytest.fixture(scope="module")
def programs():
    """The training program (holds, square waves: lines between kinks) and the validation program's first cycle,
    to the end of its 2-30 Hz chirp (sines sampled at 1 kHz: the spline over their smooth windows)."""
    return {"train": program("none", 2.0), "validation": program("none", 6.4, validation=True)}


@pytest.fixture(scope="module")
def framework(programs):
    s = electrostatic_actuator(**BASE)
    return {k: simulate(s, t, u={"U": Sampled(tuple(t), tuple(U))}, rtol=RTOL_FRAMEWORK) for k, (t, U) in programs.items()}


@pytest.mark.parametrize("effect", co.OUTSIDE)
def test_hand_written_equations_agree_with_the_framework_when_the_effect_vanishes(effect, programs, framework):
    """At size 1e-9 every effect is far below rounding (an appendage of 4e-13 kg, a drift of 1.5e-10 of k, a current
    limit of 1.5 kA, flexible_mode's appendage 1e-13 kg): each truth is the nominal actuator written out by hand."""
    for split, (t, U) in programs.items():
        ours = co.simulate(effect, t, U, size=1e-9)
        for ch in CHANNELS:
            ref = np.asarray(framework[split][ch], dtype=float)
            assert np.max(np.abs(ours[ch] - ref)) <= TOL * np.ptp(ref), (split, ch)


@pytest.mark.parametrize("effect", ["second_mode", "flexible_mode"])
def test_appendage_equations_agree_with_the_framework_at_full_size(effect, programs):
    """The appendage built from components (a mass on a Kelvin-Voigt mount in the electrode's velocity junction,
    as ``concealed_truths``' payload) and simulated by the framework gives the scipy truth's recording (same
    tolerance: measured 2.4e-9 position, 2.7e-7 current for second_mode; 3.5e-9 and 3.1e-7 for flexible_mode).  Each case on its own
    program: ``flexible_mode`` on ``ringing`` (2 s of training, and the validation run to the end of its 10-50 Hz
    chirp, 3.7 s, across both of the case's modes)."""
    from components import Damper, LinearSpring, Mass
    from examples.concealed_truths import _build
    from phs import parallel, series

    v = co.parameters(effect)

    def part(S):
        return {"components": [Mass("m2", m=v["m2"], state="m2.p", scale=1e-5),
                               LinearSpring("k2", K=v["k2"], state="k2.l", range=(-2e-5, 2e-5), scale=1e-5), Damper("c2", b=v["c2"])],
                "mechanical": [parallel(series("k2", "c2"), "m2")]}
    system = _build("appendage", part)
    runs = programs.values() if effect == "second_mode" else [co.command(effect, 2.0), co.command(effect, 3.7, validation=True)]
    for t, U in runs:
        ref = simulate(system, t, u={"U": Sampled(tuple(t), tuple(U))}, rtol=RTOL_FRAMEWORK)
        ours = co.simulate(effect, t, U)
        for ch in CHANNELS:
            y = np.asarray(ref[ch], dtype=float)
            assert np.max(np.abs(ours[ch] - y)) <= TOL * np.ptp(y), ch


def test_recordings_are_deterministic_and_the_validation_run_is_another():
    a, info = co.generate("stiffness_drift", seconds=2.0, seed=3)
    b, _ = co.generate("stiffness_drift", seconds=2.0, seed=3)
    c, _ = co.generate("stiffness_drift", seconds=2.0, seed=4)
    v, vinfo = co.generate("stiffness_drift", seconds=2.0, seed=3, validation=True)
    for ch in ("U", *CHANNELS):
        assert np.array_equal(a[ch], b[ch])
        assert not np.array_equal(a[ch], v[ch])
    assert not np.array_equal(a["position"], c["position"]) and np.array_equal(a["U"], c["U"])
    assert a.names == ["U", "position", "current"] and len(a) == 2001 and a.holds == {"U": "linear"}
    for ch in CHANNELS:
        noise = a[ch] - info["clean"][ch]
        # 2001 samples: the std of the drawn noise is within 3 sigma (3 / sqrt(2 * 2000) = 4.7 %) of the stated one
        assert np.std(noise) == pytest.approx(info["noise_std"][ch], rel=0.05)
    assert (info["nature"], info["state"], vinfo["validation"]) == ("drift", "x", True)


@pytest.mark.parametrize("effect, seconds", [("second_mode", 3.0), ("stiffness_drift", 3.0), ("current_limit", 5.5),
                                             ("flexible_mode", 3.0)])
def test_each_effect_changes_the_outputs_beyond_the_noise(effect, seconds):
    """At size 1 the clean outputs differ from the nominal actuator's (size 1e-9) by more than the noise std on some
    channel of a training run, the RMS over the whole run.  The current limit shows only where the program asks
    more than it (the +-16 V square wave from 4.9 s on; before, at most 1.95 uA of its 2 uA): a 5.5 s run.
    Measured, position / current in noise stds (at size 0.5): second_mode 5.69 / 1.86 (3.98 / 1.33),
    stiffness_drift 1.91 / 0.41 (0.94 / 0.21), current_limit 0.15 / 11.46 (0 / 0: at 4 uA the limit is above what 5.5 s ask),
    flexible_mode (on its ``ringing`` program) 9.08 / 2.27 (6.90 / 1.82)."""
    rec, info = co.generate(effect, seconds=seconds)
    t, U = co.command(effect, seconds)
    nominal = co.simulate(effect, t, U, size=1e-9)
    rms = {ch: float(np.sqrt(np.mean((info["clean"][ch] - nominal[ch]) ** 2))) / info["noise_std"][ch] for ch in CHANNELS}
    assert max(rms.values()) > 1.0, rms
    smaller = co.simulate(effect, t, U, size=0.5)  # half the effect changes them less
    assert max(float(np.sqrt(np.mean((smaller[ch] - nominal[ch]) ** 2))) / info["noise_std"][ch] for ch in CHANNELS) < max(rms.values())


@pytest.mark.parametrize("kwargs, culprit", [
    ({"effect": "fringe_field"}, "fringe_field"),
    ({"effect": "second_mode", "size": 0.0}, "size"),
    ({"effect": "current_limit", "size": -1.0}, "size"),
    ({"effect": "second_mode", "size": float("nan")}, "size"),
    ({"effect": "stiffness_drift", "size": 10.0}, "stiffness"),
    ({"effect": "second_mode", "seconds": 0.1}, "seconds"),
])
def test_bad_cases_and_sizes_are_refused_in_one_line(kwargs, culprit):
    effect = kwargs.pop("effect")
    with pytest.raises(InputDataError) as err:
        co.generate(effect, **kwargs)
    msg = str(err.value)
    assert culprit in msg and "\n" not in msg


def test_module_examples():
    """``examples/`` is outside the doctest paths: the module's examples run here."""
    result = doctest.testmod(co, optionflags=doctest.ELLIPSIS)
    assert result.failed == 0 and result.attempted > 5
