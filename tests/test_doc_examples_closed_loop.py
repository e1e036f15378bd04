"""The closed-loop example of docs/workflows/closed_loop.md runs at reduced size (``--quick``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"


def test_closed_loop_example(tmp_path):
    """Plant + known PD controller, diagnosed with the reference as input and position + controller
    force as channels: the dry friction the plant model leaves out is named."""
    proc = subprocess.run([sys.executable, str(EXAMPLES / "closed_loop.py"), "--quick", "--out", str(tmp_path)], cwd=ROOT,
                          capture_output=True, text=True, timeout=900)
    out = proc.stdout
    assert proc.returncode == 0, out[-3000:] + proc.stderr[-3000:]
    assert "verdict coulomb_friction" in out, out[-3000:]
    for name in ("fits", "hypotheses", "locate"):
        assert (tmp_path / f"closed_loop_{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
