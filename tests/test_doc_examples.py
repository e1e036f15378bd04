"""The docs' example scripts run (at reduced size), produce their figures, and print numbers that agree
with independent values: analytic solutions, conservation of energy, the values their docs pages state."""

import math
import os
import re
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPTS = ["simulate_basics.py", "curling_hasel.py", "manta_ray_fin.py", "new_actuator.py"]


def _numbers(line: str) -> list[float]:
    return [float(x) for x in re.findall(r"[-+]?\d+\.?\d*(?:e[-+]?\d+)?", line.split(":", 1)[1])]


def _line(out: str, start: str) -> str:
    return next(line for line in out.splitlines() if line.strip().startswith(start))


def _check_simulate_basics(out):
    # DC: no current through the capacitors, U drives R0 + R1 + R2 in series (5 kV, 1 k, 1 M, 1.47 M)
    i = 5000.0 / (1e3 + 1e6 + 1.47e6)
    q = re.search(r"'Q1': ([0-9.e+-]+), 'Q2': ([0-9.e+-]+)", out)
    # (the equilibrium solver stops on a scaled residual: measured 6e-6 relative on Q1, 1e-6 on Q2)
    assert float(q.group(1)) == pytest.approx(1.75e-5 * 1e6 * i, rel=1e-4)
    assert float(q.group(2)) == pytest.approx(4e-10 * 1.47e6 * i, rel=1e-4)
    assert _numbers(_line(out, "energy balance error"))[0] < 1e-6  # H(t) - H(0) = supplied - dissipated


def _check_curling_hasel(out):
    # the DC equilibrium's tip from its printed angles by the tip formula h = (L_v + L_e) sum_j sin(sum_i<=j theta_i)
    line = _line(out, "DC equilibrium tip")
    tip_mm = float(re.search(r"tip ([0-9.]+) mm", line).group(1))
    angles = [float(a) for a in line.split("angles")[1].split(",")]
    partial = [sum(angles[: j + 1]) for j in range(len(angles))]
    assert tip_mm == pytest.approx(1e3 * 0.030 * sum(math.sin(a) for a in partial), abs=0.02)  # angles printed to 1e-4
    assert tip_mm == pytest.approx(36.8, abs=0.05)  # docs/systems/curling_hasel.md: "The DC equilibrium (dotted) is 36.8 mm"
    # the table of docs/systems/curling_hasel.md: tip at 1 s (the quick run stops at 6 s instead of 30 s)
    for drive, at_1s in (("DC 5 kV", 45.27), ("AC 5 kV, 4 Hz", 45.80), ("AC 5 kV, 2 Hz", 45.79)):
        nums = _numbers(_line(out, drive + ":"))
        assert nums[1] == pytest.approx(at_1s, abs=0.01), drive
        assert nums[-1] < 1e-6, drive  # energy balance error
    # the paper's drift finding: the bipolar square wave drifts far less than DC
    assert _numbers(_line(out, "DC 5 kV:"))[-2] > 50 * _numbers(_line(out, "AC 5 kV, 4 Hz:"))[-2]


def _check_manta_ray_fin(out):
    for freq in ("1 Hz", "0.5 Hz"):
        lo, hi, err = (_numbers(_line(out, freq + ":"))[i] for i in (0, 1, 2))
        assert 0 < lo < hi
        assert hi == pytest.approx(20.0, abs=2.0)  # docs/systems/manta_ray_fin.md: "flaps over about 20 mm"
        assert err < 1e-5  # energy balance


def _check_new_actuator(out):
    # parallel-plate pull-in: V = sqrt(8 k g0^3 / (27 eps A)) at x = g0 / 3, from the printed parameters
    k, eps, area, g0 = 50.0, 2.6562e-11, 4e-4, 1e-4
    assert re.search(r"k\s+= 50 N/m", out) and re.search(r"eps\s+= 2.6562e-11", out) and re.search(r"g0\s+= 0.0001 m", out)
    v_pi = float(re.search(r"pull-in voltage ([0-9.]+) V", out).group(1))
    assert v_pi == pytest.approx(math.sqrt(8 * k * g0**3 / (27 * eps * area)), abs=1e-3)
    assert _numbers(_line(out, "equilibrium versus the analytic force balance"))[0] < 1e-6
    for frac in ("0.5", "0.9"):
        assert _numbers(_line(out, f"step to {frac} V_pi"))[-1] < 1e-5
    assert "left the validity domain" in _line(out, "1.2 V_pi")  # beyond pull-in the electrodes touch


CHECKS = {"simulate_basics.py": _check_simulate_basics, "curling_hasel.py": _check_curling_hasel,
          "manta_ray_fin.py": _check_manta_ray_fin, "new_actuator.py": _check_new_actuator}


@pytest.mark.parametrize("script", SCRIPTS)
def test_example_script_runs(script, tmp_path):
    env = dict(os.environ, MPLBACKEND="Agg", PHS_DOCS_OUT=str(tmp_path))
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "docs", "examples", script), "--quick"],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert any(p.endswith(".png") for p in os.listdir(tmp_path)), os.listdir(tmp_path)
    CHECKS[script](proc.stdout)
