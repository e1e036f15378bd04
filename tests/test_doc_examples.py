"""The docs' example scripts run (at reduced size) and produce their figures."""

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPTS = ["simulate_basics.py", "curling_hasel.py", "manta_ray_fin.py", "new_actuator.py"]


@pytest.mark.parametrize("script", SCRIPTS)
def test_example_script_runs(script, tmp_path):
    env = dict(os.environ, MPLBACKEND="Agg", PHS_DOCS_OUT=str(tmp_path))
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "docs", "examples", script), "--quick"],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert any(p.endswith(".png") for p in os.listdir(tmp_path)), os.listdir(tmp_path)
