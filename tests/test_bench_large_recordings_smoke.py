"""Smoke test of bench/large_recordings.py: a small run completes and reports its figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "large_recordings.py"


@pytest.mark.slow
def test_small_run_reports_json_with_growth_and_baseline():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--sizes", "1e4,3e4"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert figures["sizes"] == [10000, 30000]
    assert set(figures["simulate_seconds"]) == set(figures["identify_seconds"]) == {"10000", "30000"}
    assert set(figures["baseline_simulate_seconds"]) == {"10000", "30000"}
    assert all(v > 0 for v in figures["peak_mb"].values())
    assert abs(figures["fitted"]["k.K"] - 4.0) <= 0.01 and abs(figures["fitted"]["b.b"] - 0.4) <= 0.01  # 3 s at 10 kHz
