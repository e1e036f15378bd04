"""Smoke test of bench/rod.py: the quick run (without pyelastica) completes, reports its figures as JSON, and the
tip trajectory of the undamped cantilever converges at second order in n against ours' extrapolated reference."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "rod.py"


def test_quick_rod_benchmark_reports_json_and_converges():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--no-elastica"], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert figures["quick"] is True and figures["pyelastica"] is None
    rows = figures["ours"]
    assert {r["n"] for r in rows} == {4, 6, 8}
    for row in rows:
        assert row["assembly_seconds"] > 0 and row["codegen_seconds"] > 0 and row["seconds"] > 0
    # second order in n (errors against the n = 8/16 extrapolation, so slightly above 2 from n = 4 to 8)
    assert 1.7 < figures["ours_order"] < 2.6
    # the 5 % target is reached at these n; no ratio without pyelastica
    entry = figures["equal_accuracy"]["0.05"]
    assert entry["ours"]["error"] <= 0.05 and entry["ratio"] is None


ASSEMBLY = Path(__file__).resolve().parents[1] / "bench" / "rod_assembly.py"


def test_quick_rod_assembly_benchmark_reports_json():
    proc = subprocess.run([sys.executable, str(ASSEMBLY), "--quick"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert figures["quick"] is True and figures["n"] == [6, 12]
    rows = figures["ours"]["rows"]
    assert rows["6"]["states"] == 36 and rows["12"]["states"] == 72
    for row in rows.values():
        assert row["assembly_cpu"] > 0 and row["codegen_cpu"] > 0 and row["total_wall"] > 0
    # two sizes a factor 2 apart: a fitted exponent is finite; its value is a bench figure, not checked here
    assert math.isfinite(figures["ours"]["total_exponent"])
