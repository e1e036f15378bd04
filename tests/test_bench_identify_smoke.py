"""Smoke test of bench/identify_curling_hasel.py: the quick run completes and reports its figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "identify_curling_hasel.py"
KEYS = {"ratio_vs_scipy_fd", "seconds", "baseline_seconds", "cost", "baseline_cost", "baseline_capped"}


def test_quick_identification_benchmark_reports_json():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick"], capture_output=True, text=True, timeout=90)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert KEYS <= figures.keys(), sorted(KEYS - figures.keys())
    assert figures["quick"] is True
    assert figures["free"] == ["K_b", "gamma1"]
    for key in ("ratio_vs_scipy_fd", "seconds", "baseline_seconds", "cost", "baseline_cost"):
        assert figures[key] > 0, key
    assert isinstance(figures["baseline_capped"], bool)
    # ours converges from +-30 %: K_b and gamma1 within 5 % of the truth on 2 s of noisy data
    assert all(abs(e) < 0.05 for e in figures["relative_errors"].values()), figures["relative_errors"]
    if figures["baseline_capped"]:
        assert "lower bound" in proc.stdout
