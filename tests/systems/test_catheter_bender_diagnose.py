"""The catheter bender's left-out hysteresis is found by diagnosis (``docs/examples/diagnose_catheter_bender.py``).

Slow (about 40 s on 2 cores for the hysteresis case, 5 min for the relaxation case): the example is run
in quick mode and must name the effect each truth holds.
"""

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.slow
@pytest.mark.parametrize("case", ["hysteresis", "relaxation"])
def test_bender_effect_is_named(case, tmp_path):
    env = dict(os.environ, PHS_DOCS_OUT=str(tmp_path), MPLBACKEND="Agg")
    out = subprocess.run([sys.executable, os.path.join(ROOT, "docs", "examples", "diagnose_catheter_bender.py"), "--quick", case],
                         capture_output=True, text=True, env=env, timeout=1800, check=True).stdout
    effect = {"hysteresis": "hysteresis", "relaxation": "viscoelastic_creep"}[case]
    assert f"verdicts: {effect} -> {effect}" in out, out[-2000:]
    assert any(name.endswith("_fits.png") for name in os.listdir(tmp_path))
