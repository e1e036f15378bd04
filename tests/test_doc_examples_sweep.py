"""The design-study example of docs/workflows/sweep.md runs at reduced size (``--quick``) and draws its figures."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "docs" / "examples" / "sweep_msd_hasel.py"
FIGURES = ("sweep_msd_hasel_summary.png", "sweep_msd_hasel_stroke.png", "sweep_msd_hasel_band.png")


def test_sweep_example_runs_and_writes_its_figures(tmp_path):
    env = dict(os.environ, MPLBACKEND="Agg", PHS_DOCS_OUT=str(tmp_path))
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick"], capture_output=True, text=True, env=env, cwd=ROOT,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    for name in FIGURES:
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    out = proc.stdout
    assert "resumed: 0 new runs, 18 rows" in out  # the finished study resumes without redoing anything
    # the printed damping leaves the validity domain for large steps; b = 10 kg/s never does
    assert "b = 10 kg/s: 0 of 9 runs leave the validity domain" in out
    line = next(x for x in out.splitlines() if x.startswith("b = 1 kg/s:"))
    assert 0 < int(line.split(":")[1].split()[0]) < 9
    stroke = next(x for x in out.splitlines() if x.startswith("Monte Carlo: stroke"))
    median = float(stroke.split()[3])
    assert 0.5 < median < 1.2  # mm: a 3 kV step strokes the loaded actuator by about 0.8 mm
