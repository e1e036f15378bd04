"""Smoke test of bench/diagnose.py (slow: two 4 s diagnoses): the quick run completes, names both
concealed cases right and reports its figures with the load it ran under."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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
