"""Round trips that must be exact: ``phs simulate --out`` of a ready-made system driven by an input law, then
``phs fit`` (and ``phs diagnose``) of the file it wrote with the same model, started away from the truth.

``phs simulate --out`` writes each input's law in its header (``F [N] {square(1.5, 0.7, offset=1.5)}``,
:mod:`phs.workflows.between`), so the fit replays the run itself, edges between the samples included.  A noise-free
file must then fit at >= 99.9 % with every parameter back at its truth, and the diagnosis must find nothing missing.
The grids are deliberately odd (steps of 1.3 ms and 0.77 ms, lengths not round, time from 0), so that edges fall
between samples.  A file whose input carries no law is read as a continuous signal unless it declares its input
held: :func:`test_a_daq_file_fits_its_held_steps_exactly_once_declared`.

The default suite runs the small systems at one rate; ``-m slow`` every listed system at three rates (the hydrogel arm,
128 states, and the six-actuator platform are left out: a fit of either takes minutes per law; the undamped Duffing
oscillator has no input and the RLC circuit no measured output).
"""

import json
import os

import numpy as np
import pytest

from phs.workflows.cli import main

# (MODEL, input, amplitude A, base frequency f [Hz], duration T [s], free parameters, fitted outputs)
SYSTEMS = {
    "msd": ("systems:mass_spring_damper", "F", 1.5, 0.7, 6.0, ["k.K", "b.b"], ["position"]),
    "electrostatic": ("systems:electrostatic_actuator", "U", 10.0, 40.0, 0.12, ["k", "b"], ["position", "current"]),
    "rc": ("systems.examples:rc_circuit", "U", 1.0, 150.0, 0.02, ["R.R"], ["v_C"]),
    "catheter": ("systems:catheter_bender", "q", 2e-6, 0.8, 4.0, ["K_b", "k_c"], ["force", "volume"]),
}
SLOW_SYSTEMS = {
    "peano": ("systems:peano_swimmer", "V_L", 3000.0, 2.0, 2.0, ["s_n", "r"], ["tip"]),
    "manta": ("systems:manta_ray_fin", "U", 2000.0, 1.0, 2.0, ["K_b", "b"], ["tip"]),
    "curling": ("systems:curling_hasel", "U", 1500.0, 2.0, 1.0, ["K_b", "b"], ["tip"]),
    "msd_hasel": ("systems:msd_hasel", "V", 300.0, 2.0, 1.0, ["m", "b"], ["displacement"]),
}


def laws(A: float, f: float, T: float) -> dict:
    """Every input law of ``phs.signals`` (and a plain expression), scaled to the system's amplitude and time scale."""
    return {
        "square": f"square({A}, {f}, offset={A})",
        "step": f"step({A}, {T / 3.3})",
        "staircase": f"staircase({A / 3}, {T / 4.7}, 3)",
        "sine": f"sine({A}, {f})",
        "chirp": f"chirp({A}, {f / 2}, {4 * f}, {T})",
        "exponential_chirp": f"exponential_chirp({A}, {f / 2}, {4 * f}, {T})",
        "expression": f"{A / 2} + {A / 2}*sin(2*pi*{f}*t)**3",
    }


def _round_trip(tmp_path, case, law_name, dt_share, diagnose=False):
    model, name, A, f, T, free, outputs = case
    law = laws(A, f, T)[law_name]
    data = os.fspath(tmp_path / "run.csv")
    dt = T / 1000 * dt_share
    assert main(["simulate", model, "--t-end", str(T), "--dt", str(dt), "--input", f"{name}={law}", "--out", data]) == 0
    from phs.workflows.loader import load_model

    truth = {k: load_model(model, {}).param(k).value for k in free}
    start = [f"{k}={v * (1.25 if i % 2 == 0 else 0.8)}" for i, (k, v) in enumerate(truth.items())]
    out = os.fspath(tmp_path / "fit.json")
    args = ["fit", model, data, "--free", ",".join(free), "--outputs", ",".join(outputs), "--json", out, "--quiet"]
    for p in start:
        args += ["--param", p]
    assert main(args) == 0
    fit = json.loads(open(out).read())
    for ch in outputs:
        assert fit["fit_percent"][ch] >= 99.9, (law, ch, fit["fit_percent"])
    for k, v in truth.items():
        lo, hi = fit["intervals"][k]
        # noise-free data: the interval is about as wide as the integration error (rtol 1e-8) lets it be; the
        # truth lies in it or within 1e-5 of itself of the fitted value (an interval of zero width)
        assert lo - 1e-5 * abs(v) <= v <= hi + 1e-5 * abs(v), (law, k, v, fit["values"][k], (lo, hi))
    if diagnose:
        out = os.fspath(tmp_path / "diagnose.json")
        args = ["diagnose", model, data, "--free", ",".join(free), "--outputs", ",".join(outputs), "--json", out,
                "--quiet", "--effects", "cubic_stiffness,time_delay,offset,coulomb_friction"]
        main(args)
        verdict = json.loads(open(out).read())["verdict"]
        assert verdict["effect"] == "none", (law, verdict)


@pytest.mark.parametrize("law_name", list(laws(1, 1, 1)))
@pytest.mark.parametrize("system", ["msd", "electrostatic"])
def test_simulate_then_fit_recovers_the_truth(tmp_path, system, law_name):
    _round_trip(tmp_path, SYSTEMS[system], law_name, 1.3)


@pytest.mark.parametrize("system", ["rc", "catheter"])
def test_simulate_then_fit_a_square_recovers_the_truth(tmp_path, system):
    _round_trip(tmp_path, SYSTEMS[system], "square", 0.77)


def test_simulate_a_square_then_diagnose_finds_nothing_missing(tmp_path):
    _round_trip(tmp_path, SYSTEMS["msd"], "square", 1.3, diagnose=True)


@pytest.mark.slow
@pytest.mark.parametrize("dt_share", [0.77, 1.3, 3.1])
@pytest.mark.parametrize("law_name", list(laws(1, 1, 1)))
@pytest.mark.parametrize("system", list(SYSTEMS) + list(SLOW_SYSTEMS))
def test_round_trip_every_system_law_and_rate(tmp_path, system, law_name, dt_share):
    _round_trip(tmp_path, {**SYSTEMS, **SLOW_SYSTEMS}[system], law_name, dt_share, diagnose=(law_name == "square"))


def test_a_daq_file_fits_its_held_steps_exactly_once_declared(tmp_path):
    """A DAQ's file: the command held between samples.  Undeclared, it is read as a continuous signal (straight lines
    between samples) and a warning says that its samples look held; declared held (a header ``{zoh}`` or
    ``holds=``), the steps jump at the samples and the fit is exact."""
    import warnings

    from codegen import simulate
    from phs.errors import InputHoldWarning
    from phs.signals import Sampled
    from phs.workflows.identify import identify
    from phs.workflows.recording import Recording
    from systems.examples import mass_spring_damper

    t = 3.7 + np.arange(0, 4001) * 1.3e-3
    rng = np.random.default_rng(3)
    u = np.repeat(rng.choice([-1.0, 1.0], len(t) // 37 + 1), 37)[: len(t)]  # PRBS held 37 samples
    truth = mass_spring_damper().with_params({"k.K": 5.0, "b.b": 0.6})
    y = simulate(truth, t, u={"F": Sampled(tuple(t), tuple(u), hold="zoh")})["position"]
    for name, header in [("daq.csv", "t,F,position"), ("declared.csv", 't,"F [N] {zoh}",position')]:
        np.savetxt(tmp_path / name, np.column_stack([t, u, y]), delimiter=",", header=header, comments="", fmt="%.17g")
    declared = Recording.from_csv(tmp_path / "declared.csv")
    assert declared.input_signal("F").hold == "zoh"
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputHoldWarning)  # declared: nothing to warn about
        fit = identify(mass_spring_damper(), declared, ["k.K", "b.b"])
    assert fit.values["k.K"] == pytest.approx(5.0, rel=1e-6) and fit.values["b.b"] == pytest.approx(0.6, rel=1e-6)
    option = identify(mass_spring_damper(), Recording.from_csv(tmp_path / "daq.csv", holds={"F": "zoh"}), ["k.K", "b.b"])
    assert option.values["b.b"] == pytest.approx(fit.values["b.b"], rel=1e-9)
    # undeclared: read as straight lines between samples, with a warning naming the column and the declaration;
    # the 1-sample ramps are another input than the held steps, so the fit is no longer exact
    with pytest.warns(InputHoldWarning, match=r"input 'F' changes in isolated jumps.*--hold F=zoh"):
        ramp = identify(mass_spring_damper(), Recording.from_csv(tmp_path / "daq.csv"), ["k.K", "b.b"])
    assert abs(ramp.values["b.b"] / 0.6 - 1) > 1e-4


def test_a_column_that_does_not_follow_its_law_is_refused(tmp_path):
    path = tmp_path / "bad.csv"
    t = np.arange(0, 50) * 0.01
    np.savetxt(path, np.column_stack([t, np.sin(t)]), delimiter=",", header='t,"F [N] {step(1.0, 0.2)}"', comments="",
               fmt="%.17g")
    from phs.errors import InputDataError
    from phs.workflows.recording import Recording

    with pytest.raises(InputDataError, match=r"column 'F' does not follow its declared law \{step\(1.0, 0.2\)\}: .* at row 3"):
        Recording.from_csv(path)
