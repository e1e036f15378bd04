"""The identification examples of docs/workflows/identify.md run at reduced size (``--quick``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen import simulate
from phs.signals import staircase
from phs.workflows.identify import identify
from phs.workflows.recording import Recording
from systems.curling_hasel import curling_hasel

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"
SILVERBOX = ROOT.parent / "shared" / "data" / "silverbox" / "SNLS80mV.csv"


def _run(script: str, out: Path) -> str:
    proc = subprocess.run([sys.executable, str(EXAMPLES / script), "--quick", "--out", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


def test_identify_curling_hasel_example(tmp_path):
    out = _run("identify_curling_hasel.py", tmp_path)
    assert (tmp_path / "identify_curling_hasel.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Identification of 'curling_hasel4': 6 parameters" in out
    assert "| parameter | -10 % | -5 % | 0 % | +5 % | +10 % | SD (ours) | rank | SD (paper) | rank (paper) |" in out
    # the printed ranking is the order of the printed SD column (the script's table, not a constant)
    rows = [line.split("|") for line in out.splitlines() if line.startswith("| `")]
    sd = {row[1].strip().strip("`"): float(row[7]) for row in rows}
    ranking = next(line for line in out.splitlines() if line.startswith("ranking, ours:"))
    assert [k.strip() for k in ranking.split(":")[1].split(">")] == sorted(sd, key=lambda k: -sd[k])


def test_sensitivity_ranking_of_the_model_through_the_library():
    """The ±5/±10 % sensitivity table of the tip fit computed by ``phs.workflows.identify`` at reduced
    size: 3 s at 1 kHz of a staircase to -5 kV (1 kV every 0.5 s), 1 % noise, the six parameters of
    the paper's Table 5 fitted from the truth.  The model ranks gamma2 above gamma1 where the paper
    ranks gamma1 first (docs/workflows/identify.md explains why: at -5 kV the angles settle near the
    input map's zero pi/(2 gamma2)); measured SDs: gamma2 7.04, gamma1 5.32, K_b 1.09, b 0.057,
    R2 0.032, C1 0.028.  The last three act through the ~10 s drift or the short transients: their
    order depends on the record's length (the 10 s experiment of the docs puts R2 > C1 > b)."""
    free = ["K_b", "b", "gamma1", "gamma2", "C1", "R2"]
    x0 = {f"seg{i}.l_p": 0.015 for i in range(1, 5)}
    s = curling_hasel(4)
    t = np.arange(0, 3.0 + 5e-4, 1e-3)
    U = staircase(-1000.0, every=0.5, n_steps=5)(t)
    res = simulate(s, t, u={"U": U}, x0=x0)
    rng = np.random.default_rng(7)
    rec = Recording.from_arrays(t, {"U": U, **{ch: res[ch] + 0.01 * np.ptp(res[ch]) * rng.standard_normal(len(t))
                                               for ch in ("tip", "current")}})
    table = identify(s, rec, free, x0=x0).sensitivity_table(channel="tip")
    sd = {k: table[k]["std"] for k in free}
    ranking = sorted(free, key=lambda k: -sd[k])
    assert ranking[:3] == ["gamma2", "gamma1", "K_b"], sd
    assert sd["gamma2"] > 1.2 * sd["gamma1"] and sd["gamma1"] > 3 * sd["K_b"], sd
    assert max(sd[k] for k in ("b", "C1", "R2")) < 0.1 * sd["K_b"], sd


@pytest.mark.skipif(not SILVERBOX.is_file(), reason="Silverbox data (../shared/data/silverbox) not present")
def test_identify_silverbox_example(tmp_path):
    out = _run("identify_silverbox.py", tmp_path)
    assert (tmp_path / "identify_silverbox.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Identification of 'msd': 3 parameters" in out
    line = next(line for line in out.splitlines() if line.startswith("fitted natural frequency"))
    assert 65 < float(line.split()[3]) < 75  # the Silverbox resonates near 70 Hz
    windows = next(line for line in out.splitlines() if line.startswith("arrow windows"))
    fits = [float(part.split("->")[1]) for part in windows.split(":", 1)[1].split(",")]
    assert fits[-1] < max(fits) - 10  # the linear model fails at the large-amplitude end of the arrow
    k3 = next(line for line in out.splitlines() if line.startswith("force residual"))
    assert float(k3.split("~")[1].split()[0]) > 0  # hardening: a positive cubic stiffness is missing


def test_silverbox_example_skips_without_data(tmp_path):
    """Copied elsewhere, where ../shared/data is absent, the script prints a message and exits 0."""
    root = tmp_path / "repo"
    (root / "docs" / "examples").mkdir(parents=True)
    script = root / "docs" / "examples" / "identify_silverbox.py"
    script.write_text((EXAMPLES / "identify_silverbox.py").read_text())
    proc = subprocess.run([sys.executable, str(script), "--quick", "--out", str(tmp_path / "figs")], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "not found" in proc.stdout and "skipping" in proc.stdout
    assert not (tmp_path / "figs").exists()
