"""Closed-loop runs of an IDA-PBC controller start where the plant rests (codegen.idapbc.closed_loop).

The default start of ``Controller.simulate`` is :func:`codegen.idapbc.closed_loop.start_state`: the declared
rest of every state (the default of the open-loop ``codegen.simulate``), or, under a load that moves it, the
equilibrium the plant settles at; ``phs control --t-end`` starts from the same state.
"""

from __future__ import annotations

import numpy as np
import pytest

from codegen import simulate
from codegen.idapbc import design
from codegen.idapbc.closed_loop import simulate_closed_loop, start_state
from components import Damper, ForceSource, LinearSpring, Mass
from phs import interconnect, series
from phs.errors import InputDataError
from phs.workflows.cli import main

L0, TARGET = 0.3, 0.5  # m: the spring's rest length (its declared rest) and the length to hold


def spring_at_rest_length(name: str = "msd_l0", load: bool = False):
    """A mass on a spring of rest length 0.3 m (so its declared initial state k.l = 0.3 is not zero), optionally
    with a second force input ``W`` (a load held constant)."""
    comps = [ForceSource("F"), Mass("m", m=1.0), LinearSpring("k", K=4.0, L0=L0), Damper("b", b=0.4)]
    members = ["F", "m", "k", "b"]
    if load:
        comps.insert(1, ForceSource("W"))
        members.insert(1, "W")
    return interconnect(name, comps, [series(*members)])


@pytest.fixture(scope="module")
def ctrl():
    return design(spring_at_rest_length(), {"k.l": TARGET}, stiffness={"k.l": 6.0}, damping=2.0)


def test_default_start_is_the_declared_rest_of_open_loop_simulate(ctrl):
    plant = ctrl.system
    t = np.linspace(0.0, 1.0, 3)
    open_loop = simulate(plant, t)
    res = ctrl.simulate(t)
    assert plant.states[plant.state_names.index("k.l")].initial == L0  # a nonzero declared initial state
    assert res.x[0].tolist() == open_loop.x[0].tolist() == [0.0, L0]
    assert res.info["loaded"] == ""


def test_closed_loop_from_the_declared_rest_reaches_the_target_and_H_d_never_rises(ctrl):
    res = ctrl.simulate(np.linspace(0.0, 15.0, 1501))
    # closed loop: stiffness 4 + 6 N/m, damping 0.4 + 2 kg/s on a 1 kg mass: slowest time constant 2/2.4 = 0.83 s;
    # after 15 s (18 time constants) the error is below 1e-7 m (rtol 1e-9 of the integrator)
    assert res["k.l"][0] == L0
    assert abs(res["k.l"][-1] - TARGET) < 1e-6
    assert abs(res["m.p"][-1]) < 1e-6
    # H_d is the closed loop's Lyapunov function: H_d(x0) = (4 + 6) (0.3 - 0.5)^2 / 2 = 0.2 J, falling to 0.
    # Its samples may rise only by the integration error: CVODES rtol 1e-9 on states of 0.3 m gives errors in
    # H_d of order 1e-9 * 0.2 J; 1e-9 J allows that with margin and is 2e-10 of the 0.2 J it dissipates.
    assert res.H_d[0] == pytest.approx(0.2, rel=1e-9)
    assert res.max_increase("H_d") <= 1e-9
    assert res.H_d[-1] < 1e-10


def test_x0_by_name_equals_x0_as_an_array(ctrl):
    t = np.linspace(0.0, 2.0, 41)
    by_name = ctrl.simulate(t, x0={"k.l": 0.2, "m.p": -0.1})
    as_array = ctrl.simulate(t, x0=np.array([-0.1, 0.2]))  # state order m.p, k.l
    assert ctrl.system.state_names == ["m.p", "k.l"]
    assert np.array_equal(by_name.x, as_array.x)
    assert np.array_equal(by_name.H_d, as_array.H_d)
    partial = ctrl.simulate(t, x0={"k.l": 0.2})  # the other state from the default start (m.p at rest: 0)
    assert partial.x[0].tolist() == [0.0, 0.2]


@pytest.mark.parametrize(("x0", "match"), [
    ({"k.q": 0.2}, "has no state 'k.q'"),
    ({"k.l": float("nan")}, "value nan of state 'k.l' is not a finite number"),
    ({"k.l": "far"}, "value 'far' of state 'k.l' is not a number"),
    ([0.0, np.inf], "value inf of state 'k.l' is not a finite number"),
    ([0.0, 0.1, 0.2], "expected 2 values for 'msd_l0' (m.p, k.l), got 3"),
])
def test_a_bad_x0_is_refused_in_one_line_naming_the_state(ctrl, x0, match):
    with pytest.raises(InputDataError) as info:
        ctrl.simulate([0.0, 1.0], x0=x0)
    assert match in str(info.value) and "\n" not in str(info.value)


def test_a_loaded_plant_starts_where_the_load_holds_it_as_phs_control_does(tmp_path, capsys):
    """W = 1 N held constant moves the declared rest k.l = 0.3 to 0.3 - 1/4 = 0.05 m (spring force K (l - L0) = -W
    with the force sources in series); Python and the command line start there."""
    ctrl = design(spring_at_rest_length("msd_w", load=True), {"k.l": TARGET}, inputs=["F"], fixed_inputs={"W": 1.0},
                  damping=2.0)
    x, loaded = start_state(ctrl)
    res = simulate_closed_loop(ctrl, np.linspace(0.0, 20.0, 201))
    assert res.x[0] == pytest.approx(x, abs=1e-12)
    assert abs(res.x[0][1] - L0) > 0.2  # moved by the load: 1/4 m away from the rest length
    assert abs(res.x[0][0]) < 1e-12 and np.all(np.abs(res.x[:2, :]).max() < 1.0)
    model = tmp_path / "model.py"
    model.write_text("from components import Damper, ForceSource, LinearSpring, Mass\nfrom phs import interconnect, series\n"
                     "def plant():\n"
                     "    return interconnect('msd_w', [ForceSource('F'), ForceSource('W'), Mass('m', m=1.0), "
                     f"LinearSpring('k', K=4.0, L0={L0}), Damper('b', b=0.4)], [series('F', 'W', 'm', 'k', 'b')])\n")
    code = main(["control", f"{model}:plant", "--target", f"k.l={TARGET}", "--controlled", "F", "--fixed", "W=1",
                 "--damping", "2", "--t-end", "20", "--rays", "4", "--simulations", "1", "--report", str(tmp_path / "r")])
    out = capsys.readouterr().out
    assert code == 0, out
    assert f"from the loaded rest state ({loaded})" in out
    first = np.loadtxt(tmp_path / "r" / "closed_loop.csv", delimiter=",", skiprows=1)[0]
    header = (tmp_path / "r" / "closed_loop.csv").read_text().splitlines()[0].split(",")
    assert [first[header.index(nm)] for nm in ctrl.system.state_names] == pytest.approx(list(x), abs=1e-12)
    assert res["k.l"][-1] == pytest.approx(TARGET, abs=1e-4)


def test_a_run_over_its_cpu_budget_stops_with_one_line(ctrl):
    """``seconds`` bounds the integration's CPU time: 200001 outputs at rtol 1e-12 take far more than 1 ms."""
    from phs.errors import SimulationError

    with pytest.raises(SimulationError) as info:
        ctrl.simulate(np.linspace(0.0, 2000.0, 200001), rtol=1e-12, seconds=1e-3)
    msg = str(info.value)
    assert "did not finish in 0.001 CPU seconds" in msg and "\n" not in msg
    assert ctrl.simulate(np.linspace(0.0, 1.0, 11), seconds=30.0).x.shape == (11, 2)  # a short run is unaffected


def test_a_certificate_run_over_the_step_limit_is_undecided_and_says_so(ctrl, monkeypatch):
    """A run stopped by its step limit is not finished: its outcome is unknown, so it neither passes nor fails the
    runs' certificate; the set is shrunk below its start (three rounds), after which the runs and the region are
    undecided."""
    import codegen.idapbc.certificates as certificates

    assert ctrl.certify(rays=4, simulations=1).passed
    monkeypatch.setattr(certificates, "RUN_STEPS", 3)  # fewer steps than any output interval needs
    items = {c.name: c for c in ctrl.certify(rays=4, simulations=1).items}
    sims, region = items["simulations"], items["region"]
    assert sims.verdict == "undecided" and region.verdict == "undecided"
    assert "maximum number of internal steps (3)" in sims.summary and "not finished within the runs' budget" in sims.summary
    assert sims.numbers["failed"] == 0 and len(sims.numbers["unfinished"]) == 1
    # three rounds, each from a start below UNFINISHED_SHRINK of the last unfinished one's level
    levels = region.numbers["unfinished_levels"]
    assert len(levels) == 3 and all(b <= certificates.UNFINISHED_SHRINK * a * (1 + 1e-12) for a, b in zip(levels, levels[1:]))
    assert region.numbers["c"] == pytest.approx(certificates.UNFINISHED_SHRINK * levels[-1])


def test_runs_that_cannot_be_finished_shrink_the_set_until_the_runs_pass(ctrl, monkeypatch):
    """Starts above a level whose runs stop at the budget (as against a material's steep wall) leave the set
    shrunk below them; the runs from inside the smaller set finish, reach x*, and both certificates pass on it."""
    import codegen.idapbc.certificates as certificates
    from phs.errors import SimulationError

    full = {c.name: c for c in ctrl.certify(rays=4, simulations=2).items}["region"].numbers["c"]
    wall = 0.2 * full  # runs from above a fifth of the estimated set's level cannot be finished
    real = certificates.simulate_closed_loop

    def budgeted(c, t, x0=None, **kw):
        if c.H_d(x0) > wall:
            err = SimulationError("closed-loop simulation of 'msd_l0': it took its maximum number of internal steps")
            err.out_of_budget = True
            raise err
        return real(c, t, x0=x0, **kw)

    monkeypatch.setattr(certificates, "simulate_closed_loop", budgeted)
    items = {c.name: c for c in ctrl.certify(rays=4, simulations=2).items}
    region, sims = items["region"], items["simulations"]
    assert sims.verdict == "pass" and region.verdict == "pass"
    assert region.numbers["unfinished_levels"] and min(region.numbers["unfinished_levels"]) > wall
    assert region.numbers["c"] < full and "could not be finished within the runs' budget" in region.summary


def test_the_step_limit_marks_the_error_as_unfinished(ctrl):
    from phs.errors import SimulationError

    with pytest.raises(SimulationError) as info:
        simulate_closed_loop(ctrl, np.linspace(0.0, 1.0, 3), max_steps=2)
    assert info.value.out_of_budget is True
