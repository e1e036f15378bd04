"""Smoke test of bench/diagnose.py (slow: two 4 s diagnoses; with ``--lab``, two 3 s lab-protocol ones): the
quick runs complete, name both concealed cases right and report their figures with the load they ran under,
the CPU seconds and where the time went."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "diagnose.py"
KEYS = {"seconds_per_case", "max_seconds", "verdict_correct", "target_seconds", "target_seconds_loaded", "cpus",
        "load_before_max", "cases"}


@pytest.mark.slow
def test_quick_diagnosis_benchmark_reports_json():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--no-baseline"], capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert KEYS <= figures.keys(), sorted(KEYS - figures.keys())
    assert set(figures["cases"]) == {"charge_retention", "none"}
    assert figures["verdict_correct"] == 1.0, {k: c["verdict"] for k, c in figures["cases"].items()}
    assert figures["seconds_per_case"] == pytest.approx(
        sum(c["seconds"] for c in figures["cases"].values()) / 2, abs=0.01)
    assert all(c["load_before"] is None or c["load_before"] >= 0 for c in figures["cases"].values())
    _check_timing(figures)


def _check_timing(figures):
    """Every case's CPU seconds and phase split: the phases' wall seconds add up to the case's (``other`` is the
    rest), and the nominal fit and the screening took time."""
    for c in figures["cases"].values():
        assert c["cpu_seconds"] > 0
        phases = c["phases"]
        assert set(phases) == {"nominal fit", "location", "screening", "refits", "discovery", "other"}
        assert sum(v["wall"] for v in phases.values()) == pytest.approx(c["seconds"], abs=0.1)
        assert phases["nominal fit"]["wall"] > 0 and phases["screening"]["wall"] > 0


@pytest.mark.slow
def test_quick_lab_benchmark_names_both_cases_and_times_the_phases():
    """``--lab --quick``: two 3 s lab-protocol recordings (the electrostatic actuator at 500 Hz with a stiffening
    suspension, the MSD HASEL's control at 500 Hz), five free parameters each."""
    proc = subprocess.run([sys.executable, str(SCRIPT), "--lab", "--quick", "--no-baseline"], capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert KEYS <= figures.keys() and figures["lab"] is True
    assert set(figures["cases"]) == {"esa:cubic_stiffness@500Hz", "msd:none@500Hz"}
    assert figures["verdict_correct"] == 1.0, {k: c["verdict"] for k, c in figures["cases"].items()}
    _check_timing(figures)


def test_lab_pairs_are_lab_cases_of_the_random_pairs():
    """``--lab --pairs N``: the random pairs of ``examples.concealed_effects`` as lab cases of the electrostatic
    actuator, each at one of the lab's rates, the same for the same seed."""
    import importlib.util

    from examples import lab_protocols
    from examples.concealed_effects import random_pairs

    spec = importlib.util.spec_from_file_location("bench_diagnose", SCRIPT)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    cases = bench.lab_pairs(8, 3)
    assert cases == bench.lab_pairs(8, 3) and cases != bench.lab_pairs(8, 4)
    assert [c.split(":")[1].split("@")[0] for c in cases] == random_pairs(8, 3)
    assert {lab_protocols.parse_case(c)[0] for c in cases} == {"esa"}
    assert {lab_protocols.parse_case(c)[2] for c in cases} <= {500.0, 1000.0, 2000.0}
    assert all(bench._is_lab(c) for c in cases) and not bench._is_lab("charge_retention")


def test_integration_counter_counts_simulations_and_sensitivities_in_forked_workers(monkeypatch):
    """``install_counter``: every simulator run (in this process and in two forked workers) and every CVODES call
    of a fit (plain, and with one sensitivity direction per free parameter) is counted with its samples."""
    import importlib.util

    import phs.workflows.identify.sensitivities as sens
    from codegen import Simulator, simulate
    from phs.workflows.diagnose.pool import run_forked
    from phs.workflows.identify.solve import identify
    from phs.workflows.recording import Recording
    from systems.examples import rc_circuit

    simulator = importlib.import_module("codegen.simulator")  # the module, not codegen's function
    # the wrappers are removed after the test (monkeypatch restores what it set)
    monkeypatch.setattr(simulator.Simulator, "run", simulator.Simulator.run)
    monkeypatch.setattr(sens, "_integrate", sens._integrate)
    monkeypatch.setattr(sens, "_integrate_sensitivities", sens._integrate_sensitivities)
    spec = importlib.util.spec_from_file_location("bench_diagnose", SCRIPT)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    counter = bench.install_counter()
    t = np.linspace(0.0, 0.01, 101)
    run_forked(_simulated_samples, [(t,), (t,)], 2)
    Simulator(rc_circuit(), energy=False).run(t, u={"U": 1.0})
    sims = counter.read()["simulations"]
    assert (sims["calls"], sims["samples"], sims["sample_directions"]) == (3, 303, 0)
    assert sims["seconds"] > 0

    counter.reset()
    truth = rc_circuit().with_params({"R.R": 150.0})
    y = simulate(truth, t, u={"U": 1.0})["v_C"]
    rec = Recording.from_arrays(t, {"U": np.ones(t.size), "v_C": y})
    identify(rc_circuit(), rec, ["R.R"], x0=[0.0])
    got = counter.read()
    plain, with_sens = got["fit integrations"], got["sensitivity integrations"]
    assert plain["calls"] > 0 and with_sens["calls"] > 0
    assert with_sens["sample_directions"] == with_sens["samples"]  # one free parameter: one direction


def _simulated_samples(t):
    from codegen import Simulator
    from systems.examples import rc_circuit

    return len(Simulator(rc_circuit(), energy=False).run(t, u={"U": 1.0}).t)
