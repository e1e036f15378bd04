"""The IDA-PBC example of docs/workflows/idapbc.md runs at reduced size (``--quick``) and writes its figures."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_idapbc_curling_hasel_example(tmp_path):
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, str(ROOT / "docs" / "examples" / "idapbc_curling_hasel.py"), "--quick",
                           "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = proc.stdout
    for name in ("idapbc_curling_hasel.png", "idapbc_curling_hasel_mismatch.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Certificates of the IDA-PBC controller for 'curling_hasel4_design': all passed" in out
    settle = float(re.search(r"within 1 % of 30 mm after ([0-9.]+) ms", out).group(1))
    assert settle < 2000.0
    errors = {m.group(1).strip(): float(m.group(2)) for m in
              re.finditer(r"mismatch, (.+?)\s*: tip error at [0-9.]+ s ([-+0-9.]+) %", out)}
    assert abs(errors["IDA-PBC"]) > 10 * abs(errors["+ passive integral"]) > 0  # the drift's share removed
    assert abs(errors["+ integral of the tip error"]) < 0.1
    assert "charge shaping K_Q = 1e12 J/C^2): Hessian pass" in out and "(voltage (lambda only)): Hessian fail" in out
