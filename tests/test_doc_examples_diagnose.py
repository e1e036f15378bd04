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


DATA = ROOT.parent / "shared" / "data"
TANKS = DATA / "cascaded_tanks" / "dataBenchmark.csv"
PNEUMATIC = DATA / "pneumatic_actuator_tudelft"


@pytest.mark.skipif(not TANKS.is_file(), reason="cascaded tanks data (../shared/data/cascaded_tanks) not present")
def test_diagnose_cascaded_tanks_example(tmp_path):
    """Half of each record: the Torricelli model's best explanation is the user's overflow candidate at
    the upper tank, accepted over the library's input saturation."""
    out = _run("diagnose_cascaded_tanks.py", tmp_path)
    assert "verdict overflow" in out, out[-3000:]
    assert "overflow at V1" in out
    assert (tmp_path / "diagnose_tanks_fits.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.skipif(not (PNEUMATIC / "chamber_leak_Ultimaker_015.csv").is_file(),
                    reason="pneumatic actuator data (../shared/data/pneumatic_actuator_tudelft) not present")
def test_diagnose_pneumatic_leak_example(tmp_path):
    """The first 60 s of a leaking printed chamber: a closed-chamber model is missing a leak."""
    out = _run("diagnose_pneumatic_leak.py", tmp_path)
    line = next(ln for ln in out.splitlines() if ln.startswith("Ultimaker_015"))
    assert "effects ['leakage'" in line, out[-3000:]
    before, after = (float(v) for v in line.split(" fit ")[1].split("%")[0].split("->"))
    assert before < 5.0 and after > 80.0  # a constant against a decay from 7.7 to 0.7 bar


@pytest.mark.slow  # about 4 minutes: every sample of the drive's velocity is a kink of the input
@pytest.mark.skipif(not (PNEUMATIC / "friction_O-ring257_7bar.csv").is_file(),
                    reason="pneumatic actuator data (../shared/data/pneumatic_actuator_tudelft) not present")
def test_diagnose_seal_friction_example(tmp_path):
    out = _run("diagnose_seal_friction.py", tmp_path)
    assert "verdict coulomb_friction" in out, out[-3000:]
