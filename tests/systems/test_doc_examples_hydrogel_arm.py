"""docs/examples/hydrogel_arm.py runs at reduced size, writes its outputs, and its simulated free-vibration
period agrees with the linearised one from the eigenvalues of the Jacobian."""

import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_hydrogel_arm_example_runs_and_its_periods_agree(tmp_path):
    env = dict(os.environ, MPLBACKEND="Agg", PHS_DOCS_OUT=str(tmp_path))
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "docs", "examples", "hydrogel_arm.py"), "--quick"],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "hydrogel_arm.png" in os.listdir(tmp_path)
    table = (tmp_path / "hydrogel_arm_params.md").read_text()
    assert "| `rod.tau` | 0.05 | s |" in table and "`sva9.r`" in table
    linear, simulated = map(float, re.search(r"linearised period ([\d.]+) s .* zero-crossing period ([\d.]+) s",
                                             proc.stdout).groups())
    assert abs(simulated - linear) < 2e-3 * linear
    assert abs(linear - 1.56) < 0.02 * 1.56
    error = float(re.search(r"energy balance error ([\d.e+-]+)", proc.stdout).group(1))
    assert error < 1e-5
