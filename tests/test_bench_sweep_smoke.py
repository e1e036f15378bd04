"""Smoke test of bench/sweep.py: the quick run completes, its four paths agree, and it reports its figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "sweep.py"
KEYS = {"ratio_map_vs_serial", "ratio_map_vs_solve_ivp", "ratio_dask_vs_map", "runs_per_second", "seconds",
        "agreement", "results_agree", "targets_met"}


def test_quick_sweep_benchmark_reports_json_and_paths_agree():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert KEYS <= figures.keys(), sorted(KEYS - figures.keys())
    assert figures["quick"] is True and figures["variants"] == 8
    assert figures["results_agree"] is True
    assert figures["agreement"]["serial_vs_map"] <= 1e-12 and figures["agreement"]["dask_vs_map"] <= 1e-12
    assert figures["failed"] == {"map": 0, "serial": 0, "dask": 0}
    for key in ("ratio_map_vs_serial", "ratio_map_vs_solve_ivp", "ratio_dask_vs_map"):
        assert figures[key] > 0, key
