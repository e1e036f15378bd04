"""A diagnosis names no effect when the refitted nominal model cannot describe the recording at all.

The recordings are a mass-spring-damper (``systems.examples.mass_spring_damper``, m = 1 kg, k = 4 N/m,
b = 0.4 N s/m) driven by a square wave plus a sine for 8 s at 100 Hz, position noise 0.5 % of its
spread; the nominal model starts off the truth (m = 1.5, k = 3, b = 0.6) with all three free.  Read
wrongly (position in mm as m, its sign flipped, input and output swapped by the mapping), the verdict is
the refusal naming the channel, in Python and through ``phs diagnose``; a hardening spring the model
lacks is still named.  Each diagnosis that refuses stops after the nominal fit (1-6 s); the candidates
are restricted so that a rule that failed to refuse would still be quick.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from codegen import simulate
from components.candidates import CubicStiffness, Offset, QuadraticDrag
from phs.workflows.cli import main
from phs.workflows.diagnose import diagnose
from phs.workflows.diagnose.refusal import REFUSED, SCALE_FACTOR, SHAPE_FLOOR
from phs.workflows.recording import Recording
from systems.examples import mass_spring_damper

FREE = ["m.m", "k.K", "b.b"]
START = {"m": 1.5, "k": 3.0, "b": 0.6}
CANDIDATES = [Offset(), CubicStiffness()]


def _force(t):
    return np.sign(np.sin(2 * np.pi * 0.3 * t)) + 0.5 * np.sin(2 * np.pi * 1.1 * t)


@pytest.fixture(scope="module")
def msd():
    t = np.arange(0.0, 8.0, 0.01)
    F = _force(t)
    y = simulate(mass_spring_damper(), t, u={"F": F})["position"]
    y = y + 0.005 * np.std(y) * np.random.default_rng(0).standard_normal(t.size)
    return t, F, y


CASES = {  # name: (columns of the recording as the model reads them, the refusal's reason)
    "mm_read_as_m": (lambda F, y: {"F": F, "position": 1000 * y}, "scale"),
    "sign_flipped": (lambda F, y: {"F": F, "position": -y}, "shape"),
    "input_and_output_swapped": (lambda F, y: {"F": y, "position": F}, "shape"),
}


@pytest.mark.parametrize("case", CASES)
def test_a_recording_the_model_cannot_describe_names_no_effect(msd, case):
    t, F, y = msd
    columns, reason = CASES[case]
    d = diagnose(mass_spring_damper(**START), Recording.from_arrays(t, columns(F, y)), free=FREE, candidates=CANDIDATES, n_jobs=1)
    assert d.effect == REFUSED and d.refused, d.summary()
    assert d.verdict["effects"] == [] and d.accepted == [] and d.hypotheses == [] and d.final is d.nominal
    (c,) = d.verdict["cannot_describe"]
    assert c["channel"] == "position" and reason in c["reasons"], c
    # the figures that decided: measured 125 (mm as m), validation correlation -0.88 (sign), training 0.21 (swapped)
    rho = min(c["correlation"], c["validation_correlation"])
    if reason == "scale":
        assert c["spread_ratio"] > SCALE_FACTOR
    else:
        assert rho < SHAPE_FLOOR
    if case == "sign_flipped":
        assert rho < 0 and any("sign" in k for k in c["checks"]), c
    text = d.summary()
    assert "no effect named" in text and "position" in text and "check" in text
    assert not any(name in text for name in ("offset at", "cubic_stiffness at", "Missing physics"))
    js = d.to_dict()
    assert js["verdict"]["effect"] == REFUSED and js["hypotheses"] == []


@pytest.mark.parametrize("case", ["mm_read_as_m", "input_and_output_swapped"])
def test_the_command_line_refuses_with_one_line_and_exit_code_1(msd, case, tmp_path, capsys):
    t, F, y = msd
    path = tmp_path / "run.csv"
    # the file holds the true columns; the swap is a wrong --map
    cols = {"F": F, "position": 1000 * y if case == "mm_read_as_m" else y}
    np.savetxt(path, np.column_stack([t, cols["F"], cols["position"]]), delimiter=",", header="t,F,position", comments="")
    wrong_map = ["--map", "F=position", "--map", "position=F"] if case == "input_and_output_swapped" else []
    out = tmp_path / "d.json"
    code = main(["diagnose", "systems.examples:mass_spring_damper", str(path), "--free", ",".join(FREE), "--param", "m.m=1.5",
                 "--param", "k.K=3", "--param", "b.b=0.6", "--effects", "offset,cubic_stiffness", "--jobs", "1", "--quiet",
                 "--json", str(out), "--report", str(tmp_path / "report"), *wrong_map])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and "cannot describe" in err[0] and "position" in err[0] and "no effect named" in err[0], err
    assert ("unit of column 'position'" in err[0]) if case == "mm_read_as_m" else ("--map" in err[0] or "sign" in err[0]), err
    doc = json.loads(out.read_text())
    assert doc["verdict"]["effect"] == REFUSED and doc["verdict"]["cannot_describe"][0]["channel"] == "position"
    assert (tmp_path / "report" / "index.html").is_file()


def test_a_hardening_spring_is_still_named():
    """The truth has k3 = 40 N/m³ (integrated by scipy outside the framework): the refitted linear model
    follows the recording (correlation above the floor), so the diagnosis goes on and names it."""
    t = np.arange(0.0, 8.0, 0.01)
    F = 1.5 * _force(t)

    def rhs(tt, s):
        x, v = s
        return [v, float(1.5 * _force(np.array(tt))) - 4.0 * x - 40.0 * x**3 - 0.4 * v]

    sol = solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-9, atol=1e-12, max_step=0.005)
    y = sol.y[0] + 0.002 * np.std(sol.y[0]) * np.random.default_rng(1).standard_normal(t.size)
    d = diagnose(mass_spring_damper(**START), Recording.from_arrays(t, {"F": F, "position": y}), free=FREE,
                 candidates=[*CANDIDATES, QuadraticDrag()], n_jobs=1, discover=False, max_effects=1)
    assert not d.refused and d.effect == "cubic_stiffness", d.summary()
    assert d.accepted[0].values["cubic_stiffness.k3"] > 0
