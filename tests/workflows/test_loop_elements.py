"""Drive elements between a controller and the plant (``components.candidates.elements.InLoop``).

A delay or a saturation of the force a controller commands is not a port-Hamiltonian element; the model
keeps its live controller and receives the element's deviation from the recorded command as a force on
the driven body.  Checked here against a truth integrated outside the framework
(``examples.concealed_loops.simulate_loop``, classical Runge-Kutta, ten steps per sample):

* the structure: one force input at the driven body, still port-Hamiltonian, the nominal model exactly
  at the element's neutral point;
* the deviation reproduces the truth: driven by the deviation of the delayed (clipped) command, the
  model follows the truth's position and command to 2 % of their standard deviations and at least ten
  times closer than without the element (the check can fail);
* diagnosis names the element at the command, with its parameter near the truth.
"""

from __future__ import annotations

import numpy as np
import pytest

from components.candidates import InLoop, InputSaturation, TimeDelay, command_channels
from components.candidates.base import Scales
from components.candidates.elements import deviation_input, driven_body, smoothed_command, with_deviation
from examples.concealed_loops import DRIVE_LIMIT, LOOP_DELAY, NOMINAL_FREE, generate, nominal, reference, simulate_loop
from phs.errors import InputDataError, ModelError
from phs.workflows.diagnose import diagnose
from phs.workflows.diagnose.hypotheses import _simulate, _transformed
from phs.workflows.recording import Recording
from systems.examples import mass_spring_damper

DT = 1e-3
FOLLOWS = 0.02
"""The model through the deviation follows the truth to this share of each channel's standard deviation
(RMS): the command enters as 1 kHz samples, smoothed (``smoothed_command``) and interpolated linearly,
while the truth delays or clips it at every 0.1 ms step.  Measured: the delay 0.13 % (position) and
0.36 % (command), the saturation 0.67 % and 1.5 %, against 10 %, 20 %, 14 % and 29 % without the element."""


def _truth_recording(seconds=2.0, **effect):
    t = np.arange(0.0, seconds, DT)
    r = reference(t, seed=10)
    x, uc = simulate_loop(t, r, **effect)
    return Recording.from_arrays(t, {"r": r, "position": x, "u_c": uc}, source="truth", units={"r": "m", "position": "m", "u_c": "N"})


def test_the_deviation_is_a_force_at_the_driven_body():
    servo = nominal()
    assert command_channels(servo) == ["u_c"] and driven_body(servo, "u_c") == "m.p"
    s = with_deviation(servo, "u_c", "time_delay")
    assert s.check().ok
    j = s.input_names.index(deviation_input("u_c", "time_delay"))
    col = [float(v) for v in s.G[:, j]]
    assert col == [1.0 if n == "m.p" else 0.0 for n in s.state_names]
    assert not any(s.P[:, j]) and not any(s.S[j, :]) and not any(s.N[j, :])
    # every other part of the model is the nominal one
    assert s.J == servo.J and s.R == servo.R and s.G[:, :j] == servo.G


def test_a_velocity_loop_drives_its_body_too():
    from components import Damper, LinearSpring, Mass, VelocityLoop
    from phs import interconnect, series

    vc = VelocityLoop("vc", K_v=5.0, effort="u_c")
    s = interconnect("vservo", [Mass("m", m=0.5), LinearSpring("k", K=40.0), Damper("b", b=1.0), vc], [series("m", "k", "b", "vc")])
    # its command reads the reference's conjugate output, and the reference acts through P
    assert command_channels(s) == ["u_c"] and driven_body(s, "u_c") == "m.p"
    w = with_deviation(s, "u_c", "input_saturation")
    assert w.check().ok and w.input_names == ["r_v", "u_c.input_saturation"]


def test_attach_points_are_the_commands_and_never_a_deviation():
    servo = nominal()
    assert TimeDelay().attach_points(servo) == ["r", "u_c"]
    assert TimeDelay().attach_points(mass_spring_damper()) == ["F"]  # no controller, no loop place
    aug = TimeDelay().augment(servo, "u_c", Scales.of(servo))
    assert isinstance(aug.element, InLoop) and aug.effect == "time_delay"
    # a second round on the model with the element: its deviation input is not a place of its own
    assert InputSaturation().attach_points(aug.system) == ["r", "u_c"]
    with pytest.raises(ModelError, match="cannot attach"):
        TimeDelay().augment(servo, "r+u_c", Scales.of(servo))
    # places: where the recording varies; a controller output that was not recorded is no place, and
    # where it was, the reference it is computed from is a signal inside the controller, no drive
    ramp = np.linspace(0.0, 1.0, 5)
    assert TimeDelay().places(servo, {"r": ramp, "u_c": ramp}) == ["u_c"]
    assert TimeDelay().places(servo, {"r": ramp}) == ["r"]
    assert TimeDelay().places(servo, {"r": ramp, "u_c": 0 * ramp}) == ["r"]


def test_a_command_driving_no_single_body_is_refused():
    servo = nominal()
    # the reference made an input of nothing: the command's reference drives no body
    bare = with_deviation(servo, "u_c", "x")
    with pytest.raises(ModelError, match="already has an input"):
        with_deviation(bare, "u_c", "x")
    from phs import Measured

    lone = mass_spring_damper()
    lone = lone.__class__(lone.name, states=lone.states, H=list(lone.energy_terms), J=lone.J, R=lone.R, G=lone.G,
                          inputs=lone.inputs, params=lone.params, measured=[Measured("c", lone.states[1].symbol, "m", command=True)])
    with pytest.raises(ModelError, match="drive 0 bodies"):
        driven_body(lone, "c")


def test_the_neutral_element_is_the_nominal_model():
    rec = _truth_recording(1.0, delay=LOOP_DELAY)
    servo = nominal()
    for el, theta in ((TimeDelay(), [0.0]), (InputSaturation(), InputSaturation().neutral(rec.t, rec["u_c"]))):
        s = with_deviation(servo, "u_c", el.effect)
        r = _transformed(rec, InLoop(el, "u_c"), "u_c", theta)
        assert not np.any(r[deviation_input("u_c", el.effect)])
        a, b = _simulate(s, r, [0.0] * 3), _simulate(servo, rec, [0.0] * 3)
        for ch in ("position", "u_c"):
            assert np.array_equal(np.asarray(a[ch]), np.asarray(b[ch])), ch


@pytest.mark.parametrize("element, theta, effect", [
    (TimeDelay(), [LOOP_DELAY], {"delay": LOOP_DELAY}),
    (InputSaturation(), (DRIVE_LIMIT, DRIVE_LIMIT), {"limit": DRIVE_LIMIT}),
])
def test_the_deviation_reproduces_an_element_inside_the_loop(element, theta, effect):
    rec = _truth_recording(**effect)
    if isinstance(element, InputSaturation):  # a hard clip at the drive's limits, on this command
        theta = element.at_limits(rec.t, smoothed_command(rec["u_c"]), *theta)
    s = with_deviation(nominal(), "u_c", element.effect)
    x0 = [0.0] * 3
    through = _simulate(s, _transformed(rec, InLoop(element, "u_c"), "u_c", theta), x0)
    without = _simulate(nominal(), rec, x0)
    for ch in ("position", "u_c"):
        scale = float(np.std(rec[ch]))
        err = float(np.std(np.asarray(through[ch]) - rec[ch])) / scale
        missed = float(np.std(np.asarray(without[ch]) - rec[ch])) / scale
        # the check can fail: without the element the model misses the truth by 10 to 29 % of the channel
        assert err < FOLLOWS and err < missed / 10, (ch, err, missed)


def test_the_command_is_smoothed_without_delay():
    t = np.arange(0.0, 2.0, DT)
    u = np.sin(2 * np.pi * 3 * t)
    noisy = u + 0.05 * np.random.default_rng(0).normal(size=t.size)
    s = smoothed_command(noisy)
    # white noise keeps the share of its power below the cut-off, about 0.2 (std 0.45 of its level, 0.023
    # here); a filter that did nothing would leave 0.05
    assert np.std(s - u) < 0.03
    # no lag: the clean sine passes unchanged inside the record (a 1 ms lag would move it by 0.019)
    assert np.max(np.abs(smoothed_command(u) - u)[100:-100]) < 1e-3


@pytest.mark.parametrize("case, effect, key, truth", [
    ("loop_delay", "time_delay", "time_delay.tau_d", LOOP_DELAY),
    ("drive_saturation", "input_saturation", "U_hi", DRIVE_LIMIT),
])
def test_diagnosis_names_the_element_between_controller_and_plant(case, effect, key, truth):
    train, info = generate(case, seconds=3.0, seed=1)
    val, _ = generate(case, seconds=3.0, seed=2, validation=True)
    d = diagnose(nominal(), train, validation=val, free=list(NOMINAL_FREE))
    assert d.verdict["effects"] == info["effects"] == [effect], d.summary()
    main = d.accepted[0]
    assert main.augmentation.attached_to == "u_c", d.summary()
    values = main.element_values
    if key == "U_hi":  # the level the saturation tends to, from its compression of the peak and its sharpness
        values = dict(zip(("U_hi", "U_lo"), InputSaturation.limits([values[f"{effect}.{n}"] for n in ("c_hi", "c_lo", "p", "ref_hi", "ref_lo")]),
                          strict=True))
    assert abs(values[key] - truth) < 0.25 * truth, (main.element_values, d.summary())
    assert d.final.validation_fit_percent["u_c"] - d.nominal.validation_fit_percent["u_c"] > 5.0, d.summary()
    assert not d.verdict["failed"]


def test_a_model_file_keeps_the_command_mark(tmp_path):
    from phs import load

    path = tmp_path / "servo.json"
    nominal().save(path)
    back = load(path)
    assert command_channels(back) == ["u_c"]
    assert [m.command for m in back.measured] == [m.command for m in nominal().measured] == [True, False]
    # a mark that is not a boolean is refused with the place named
    import json

    data = json.loads(path.read_text())
    data["measured"][0]["command"] = "yes"
    path.write_text(json.dumps(data))
    with pytest.raises(InputDataError, match=r"measured\[0\]\.command has type str"):
        load(path)
