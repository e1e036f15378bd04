"""The passivity example of docs/workflows/passivity.md runs at reduced size (``--quick``) and prints its findings."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ("passivity_curling_energy.png", "passivity_nonpassive.png", "passivity_margin_sweep.png")


def test_passivity_example(tmp_path):
    env = dict(os.environ, MPLBACKEND="Agg", PHS_DOCS_OUT=str(tmp_path))
    proc = subprocess.run([sys.executable, str(ROOT / "docs" / "examples" / "passivity_curling_hasel.py"), "--quick"],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = proc.stdout
    for name in FIGURES:
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert "Passivity of 'curling_hasel4'" in out and ": PASSIVE;" in out
    assert "Passivity of 'fitted_damper'" in out and "NOT CERTIFIED PASSIVE" in out
    assert "element responsible: damper" in out
    assert "worst point v = -1.200 m/s" in out or "worst point v = +1.200 m/s" in out
    assert "released at 1.0 m/s: fail (element damper)" in out
    assert "margin sweep: 36 variants" in out
