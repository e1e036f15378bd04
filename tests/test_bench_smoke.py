"""Smoke test of bench/simulate_curling_hasel.py: the quick run completes and reports its figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "simulate_curling_hasel.py"
KEYS = {"ratio_vs_bdf", "ratio_vs_lsoda", "codegen_seconds", "seconds_ours", "seconds_bdf", "seconds_lsoda",
        "final_state_rel_diff"}


def test_quick_benchmark_reports_json_and_final_states_agree():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert KEYS <= figures.keys(), sorted(KEYS - figures.keys())
    assert figures["quick"] is True
    assert figures["final_states_agree"] is True
    assert 0 <= figures["final_state_rel_diff"] <= 1e-5
    assert set(figures["codegen_seconds"]) == {"4", "8"}
    assert all(v > 0 for v in figures["codegen_seconds"].values())
    for key in ("ratio_vs_bdf", "ratio_vs_lsoda", "seconds_ours", "seconds_bdf", "seconds_lsoda"):
        assert figures[key] > 0, key


def test_sampled_inputs_benchmark_windows_are_closer_to_the_signal():
    """bench/sampled_inputs.py --quick: the spline windows follow the exact sine at least as well as the
    linear interpolant, and both identifications land at the truth (k = 50 to 1e-4)."""
    script = SCRIPT.parent / "sampled_inputs.py"
    proc = subprocess.run([sys.executable, str(script), "--quick"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert figures["windows"]["error_of_peak"] <= figures["linear"]["error_of_peak"] <= 1e-4
    for rule in ("windows", "linear"):
        assert abs(figures[rule]["identify_k"] - 50.0) <= 5e-3
        assert figures[rule]["simulate_seconds"] > 0 and figures[rule]["identify_seconds"] > 0
    # a piecewise-linear drive: restarts at its kinks follow the tight run as well as the windows, which since the
    # local splines are cut at the sharpest kinks too (codegen._grid._local_pieces: on the 2 s drive 6.0e-5 against
    # 5.6e-5 of the current's spread of the default rule's run at rtol 1e-11; the windows stepped across the
    # kinks before, 5.6e-2 on the 10 s drive)
    assert figures["steps_kinks"]["current_error_of_spread"] <= 2 * figures["steps_windows"]["current_error_of_spread"]
    assert figures["steps_kinks"]["current_error_of_spread"] < 1e-3
    # a lab-protocol drive: the local splines follow the truth's current at least as well as the straight lines
    for rtol in ("1e-08", "1e-07"):
        assert (figures["lab_local"][f"current_rms_error_of_noise_rtol{rtol}"]
                <= figures["lab_lines"][f"current_rms_error_of_noise_rtol{rtol}"])
    # a command delayed by a fraction of a sample: its evenly sampled course gives the source's current to 2e-3 of
    # its peak at every delay (measured 8e-4), the first value held once at the start does not below one sample
    # (3.9e-2 at 1e-7 samples, 1.6e-2 at 0.3)
    for d in ("1e-07", "0.3", "2.6"):
        assert figures["delayed_course"][f"current_max_error_of_peak_{d}"] <= 2e-3
    for d in ("1e-07", "0.3"):
        assert figures["delayed_held"][f"current_max_error_of_peak_{d}"] > 5 * figures["delayed_course"][f"current_max_error_of_peak_{d}"]
