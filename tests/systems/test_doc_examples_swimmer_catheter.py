"""docs/examples/peano_swimmer.py and catheter_bender.py run at reduced size and write their outputs."""

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CASES = {"peano_swimmer.py": (["peano_swimmer_force.png", "peano_swimmer_response.png", "peano_swimmer_sweep.png"],
                              "peano_swimmer_params.md", "| `b2` | 21.71 | N |"),
         "catheter_bender.py": (["catheter_bender_regression.png"], "catheter_bender_params.md", "| `k_c` | 500 | N/m |")}


@pytest.mark.parametrize("script", sorted(CASES))
def test_example_runs_and_writes_its_outputs(script, tmp_path):
    figures, table, row = CASES[script]
    env = dict(os.environ, MPLBACKEND="Agg", PHS_DOCS_OUT=str(tmp_path))
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "docs", "examples", script), "--quick"],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert set(figures) <= set(os.listdir(tmp_path))
    assert row in (tmp_path / table).read_text()
    assert "energy balance error" in proc.stdout
