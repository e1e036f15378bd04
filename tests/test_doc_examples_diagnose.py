"""The diagnosis examples of docs/workflows/diagnose.md run at reduced size (``--quick``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"
SILVERBOX = ROOT.parent / "shared" / "data" / "silverbox" / "SNLS80mV.csv"


def _run(script: str, out: Path) -> str:
    proc = subprocess.run([sys.executable, str(EXAMPLES / script), "--quick", "--out", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


def test_diagnose_curling_hasel_example(tmp_path):
    out = _run("diagnose_curling_hasel.py", tmp_path)
    for name in ("fits", "hypotheses", "locate"):
        assert (tmp_path / f"diagnose_curling_hasel_{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Diagnosis of 'curling_hasel2'" in out
    assert "verdict charge_retention" in out  # the drift branch the nominal model lacks
    assert "structural checks of the augmented model: passed" in out


@pytest.mark.slow  # the same window is diagnosed by tests/workflows/test_diagnose_real.py
@pytest.mark.skipif(not SILVERBOX.is_file(), reason="Silverbox data (../shared/data/silverbox) not present")
def test_diagnose_silverbox_example(tmp_path):
    out = _run("diagnose_silverbox.py", tmp_path)
    assert "verdict cubic_stiffness" in out
    assert (tmp_path / "diagnose_silverbox_fits.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
