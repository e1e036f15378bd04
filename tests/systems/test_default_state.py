"""Every ready-made system starts, by default, at rest inside its validity domain.

A simulation without ``x0`` starts from each state's ``StateInfo.initial`` (the declared rest value,
e.g. a spring's rest length, else 0 moved into the state's range); that state must satisfy every
validity condition of the model under zero input, as the simulator checks them.
"""

from __future__ import annotations

import numpy as np
import pytest

import systems
from codegen import generate, simulate
from codegen._inputs import initial_state
from phs import load as load_system
from phs.io import save_system


@pytest.mark.parametrize("name", systems.MODELS)
def test_default_initial_state_satisfies_every_validity_condition(name):
    s = getattr(systems, name)()
    x = initial_state(s, None)
    g = np.asarray(generate(s).conditions(x, np.zeros(len(s.inputs)), s.param_vector()), dtype=float).reshape(-1)
    bad = [f"{c.label} = {v:.3g}" for c, v in zip(s.conditions, g) if not v >= -1e-12]
    assert not bad, f"{name}: default initial state {dict(zip(s.state_names, x.tolist()))} violates {bad}"


def test_curling_hasel_runs_from_its_default_state():
    res = simulate(systems.curling_hasel(2), np.linspace(0.0, 0.02, 21), u={"U": 1000.0})
    assert res["seg1.l_p"][0] == pytest.approx(0.015) and res["seg1.theta"][-1] > 0


def test_rest_values_survive_saving(tmp_path):
    s = systems.curling_hasel(1)
    save_system(s, tmp_path / "m.json")
    back = load_system(tmp_path / "m.json")
    assert [st.rest for st in back.states] == [st.rest for st in s.states]
