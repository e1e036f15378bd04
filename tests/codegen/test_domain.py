"""The validity domain stops a simulation where it is left (codegen._domain.gated, used by codegen.simulator).

The right-hand side CVODES integrates is NaN outside the domain, so the integration stops within a few steps of
the exit; the failed output interval is then integrated again without the gate to name the first point outside.
Before, the integrator went on to the end of each call (up to the whole grid) and only the states at the output
points were checked afterwards: a step of 10 MV on the curling HASEL integrated 2 s of a meaningless and stiff
trajectory (24 s of CPU time) before saying that the domain was left.
"""

from __future__ import annotations

import importlib
import re
import time

import numpy as np
import pytest
import sympy as sp

from codegen.simulator import simulator
from phs import PHSystem
from phs.errors import DomainError
from phs.params import Condition, InputInfo, StateInfo
from phs.signals import square
from phs.workflows.cli import main


def integrator_with_a_ceiling():
    """q' = u with the validity condition q <= 1: under u = 1 from q = 0 the domain is left at t = 1 exactly, and the
    right-hand side stays finite (and harmless) beyond it, so only the domain check can stop the run."""
    q = sp.Symbol("q", real=True)
    return PHSystem("ceiling", [StateInfo("q", "1", (-2.0, 2.0))], H=q**2 / 2, J=[[0]], R=[[0]], G=[[1]],
                    inputs=[InputInfo("u", "1", output="u.y")],
                    conditions=[Condition("q <= 1", 1 - q, "the ceiling")])


def _reported_time(message: str) -> float:
    return float(re.search(r"left the validity domain at t=([0-9.e+-]+)", message).group(1))


def test_the_exit_is_named_where_it_happens_not_at_the_next_output_point():
    sim = simulator(integrator_with_a_ceiling())
    t = np.array([0.0, 5.0, 10.0])  # the exit at t = 1 lies inside the first output interval
    with pytest.raises(DomainError, match="left the validity domain at t=") as err:
        sim.run(t, u={"u": 1.0})
    # the first point outside among the shares of the failed interval (sixteenths of 5 s): 1.25 s; the check
    # at the output points alone says t=5
    assert 1.0 < _reported_time(str(err.value)) <= 1.25 + 1e-12, str(err.value)
    assert "q <= 1 (the ceiling)" in str(err.value)


def test_inside_the_domain_the_gate_changes_nothing(monkeypatch):
    """A run that stays inside gives the same numbers bit for bit with and without the gate: each condition
    gates rows whose Jacobian already depends on its states, so CVODES factors the same pattern and takes the
    same steps (gating every row with every condition gave differences of 1e-8 relative, CVODES's rtol, from
    the first step on: another sparsity of the Jacobian, another factorization)."""
    from systems.curling_hasel import curling_hasel

    system = curling_hasel(2)
    t = np.linspace(0.0, 0.02, 201)
    u = {"U": square(3000.0, 0.01)}
    gated = simulator(system).run(t, u=u)
    module = importlib.import_module("codegen.simulator")  # (codegen.simulator is also the name of a function)
    monkeypatch.setattr(module, "gated", lambda expr, conditions, x: expr)
    plain = simulator(system).run(t, u=u)  # another simulator: its integrators are built anew
    assert np.max(np.abs(plain.x[:, 0])) > 0.05  # it moved (0.078 rad in the first segment by 20 ms)
    assert np.array_equal(gated.x, plain.x) and np.array_equal(gated.quadratures["E_supplied"],
                                                               plain.quadratures["E_supplied"])


def test_a_step_of_ten_megavolts_on_the_curling_hasel_is_refused_in_seconds(tmp_path, capsys):
    """``phs simulate systems:curling_hasel --input 1e7`` over 5 s (2500 output steps).

    Bound: 15 s of this process's CPU time (wall time depends on the machine's load; CPU time does not count
    the waits). The refusal takes about 4 s here, most of it building the model and its functions; before,
    the integration alone took 24 s for 2 s of simulated time, growing with the time span (so about 60 s are
    expected for these 5 s), and 3*10^4 V, which leaves the domain less violently, 2 s.
    """
    start = time.process_time()
    code = main(["simulate", "systems:curling_hasel", "--input", "1e7", "--t-end", "5", "--dt", "2e-3", "--out",
                 str(tmp_path / "r.csv")])
    cpu = time.process_time() - start
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and lines[:-1] == ["phs: warning: input 'U' of 'curling_hasel4' reaches 1e+07 V, outside its declared "
                                        "range -10000 to 10000 V (--strict-ranges makes this an error)"], lines
    err = lines[-1]
    assert err.startswith("phs: error: simulation of 'curling_hasel4' left the validity domain at t="), err
    assert _reported_time(err) < 2e-3  # inside the first output step, where it happens
    assert cpu < 15.0, f"{cpu:.1f} s of CPU time"
    assert not (tmp_path / "r.csv").exists()
