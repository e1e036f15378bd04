"""Smoke test of bench/rod.py: the quick run (without pyelastica) completes, reports its figures, and the settled
cantilever tip converges to the continuum reference at second order."""

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
    coarse, fine = figures["ours"]["6"], figures["ours"]["12"]
    for row in (coarse, fine):
        assert row["assembly_seconds"] > 0 and row["codegen_seconds"] > 0 and row["run_seconds"] > 0
    assert fine["tip_error"] < 1e-3
    assert 1.8 < math.log2(coarse["tip_error"] / fine["tip_error"]) < 2.2


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
