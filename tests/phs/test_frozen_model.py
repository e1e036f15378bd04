"""A model is a frozen value: every way of editing a built PHSystem in place raises, and what its checks,
certificates and cached results say is always about the system that is simulated.  A parameter declared
outside its own range is refused where it is declared."""

from __future__ import annotations

import dataclasses
import functools
import pickle
import warnings
from functools import partial
from operator import delitem, setitem

import numpy as np
import pytest
import sympy as sp

from codegen import simulate
from codegen.passivity import certify
from components import Capacitor, Resistor, VoltageSource
from phs import ModelError, Param, ParameterError, PHSystem, StateInfo, interconnect, series
from phs.component import Component, Dissipator, Piece, Relation
from phs.errors import ParameterRangeWarning
from systems import (
    catheter_bender,
    curling_hasel,
    duffing_oscillator,
    electrostatic_actuator,
    hasel_platform,
    hydrogel_arm,
    manta_ray_fin,
    mass_spring_damper,
    msd_hasel,
    peano_swimmer,
    rc_circuit,
    rlc_circuit,
)

# name: (builder, constant inputs, initial state, end time) -- each run moves the state away from rest,
# so an edit of J, R or G that got through would change the trajectory
SMALL = {
    "rc": (rc_circuit, {"U": 1.0}, None, 5e-3),
    "rlc": (rlc_circuit, {"U": 1.0}, None, 1e-3),
    "msd": (mass_spring_damper, {"F": 1.0}, None, 5.0),
    "duffing": (duffing_oscillator, {}, {"s.q": 0.05}, 5.0),
    "electrostatic_actuator": (electrostatic_actuator, {"U": 10.0}, None, 0.05),
    "catheter_bender": (catheter_bender, {"q": 1e-7}, None, 0.05),
    "peano_swimmer": (peano_swimmer, {"V_L": 3000.0, "V_R": 0.0}, None, 0.02),
    "curling_hasel1": (lambda: curling_hasel(1), {"U": 1000.0}, None, 0.01),
    "manta_ray_fin1": (lambda: manta_ray_fin(1), {"U": 1000.0}, None, 0.01),
}
BIG = {  # seconds to tens of seconds to build: slow suite only
    "msd_hasel": (msd_hasel, {"V": 3000.0, "F_load": 0.0}, None, 0.01),
    "hasel_platform": (lambda: hasel_platform(1), None, None, None),
    "hydrogel_arm": (hydrogel_arm, None, None, None),
}
CASES = [pytest.param(k, v, id=k) for k, v in SMALL.items()] + [
    pytest.param(k, v, id=k, marks=pytest.mark.slow) for k, v in BIG.items()]

MATRICES = ("J", "R", "G", "P", "S", "N")
DERIVED_MATRICES = ("grad_H", "dynamics", "dynamics_jacobian", "port_output", "dissipation_matrix")
SEQUENCES = ("states", "inputs", "params", "measured", "conditions", "energy_terms", "dissipators", "definitions")


@functools.cache
def _reference(name: str):
    """A model built once and never touched, and its run (simulated before any edit is tried elsewhere)."""
    build, u, x0, t_end = {**SMALL, **BIG}[name]
    ref = build()
    run = None if t_end is None else simulate(ref, np.linspace(0.0, t_end, 21), u=u, x0=x0)
    return ref, run


def _first_nonzero(M):
    return next(((i, j) for (i, j), v in sorted(M.todok().items()) if v != 0), None)


def _edits(s: PHSystem) -> dict:
    """Every way of changing ``s`` in place a user can reach, by label (each looked up when it is tried)."""
    edits = {}
    for name in MATRICES + DERIVED_MATRICES:
        M = getattr(s, name)
        at = _first_nonzero(M) or ((0, 0) if M.rows and M.cols else None)
        if at is not None:  # the sign of the entry flipped (a negative damping, a reversed coupling)
            edits[f"{name}[{at}] = -{name}[{at}]"] = partial(setitem, M, at, -M[at] if M[at] != 0 else 1)
            edits[f"{name}.fill(1)"] = lambda M=M: M.fill(1)
    for name in SEQUENCES:
        seq = getattr(s, name)
        edits[f"{name}.append"] = lambda seq=seq: seq.append(seq[0] if seq else None)
        if seq:
            edits[f"{name}[0] = ..."] = partial(setitem, seq, 0, seq[-1])
            edits[f"del {name}[0]"] = partial(delitem, seq, 0)
    for label, entries in s.dissipators[:1]:
        key = next(iter(entries), (0, 0))
        edits[f"dissipators[{label!r}][{key}] = -..."] = partial(setitem, entries, key, -entries.get(key, 1))
        edits[f"dissipators[{label!r}].clear()"] = lambda entries=entries: entries.clear()
        edits[f"dissipators[{label!r}].update"] = lambda entries=entries: entries.update({(0, 0): 1})
    for key, value in list(s.structure.items())[:2]:
        edits[f"structure[{key!r}] = ..."] = partial(setitem, s.structure, key, ())
        edits[f"structure[{key!r}].append"] = lambda value=value: value.append("extra")
    edits["structure.pop"] = lambda: s.structure.pop(next(iter(s.structure), "components"), None)
    edits["power_balance['dissipated'] = 0"] = partial(setitem, s.power_balance, "dissipated", 0)
    edits["measured_expressions.append"] = lambda: s.measured_expressions.append(sp.Integer(0))
    if s.measured_expressions:
        edits["measured_expressions[0] = 0"] = partial(setitem, s.measured_expressions, 0, sp.Integer(0))
    # attributes: every public one, plain or cached
    names = {k for k in vars(s) if not k.startswith("_")} | set(DERIVED_MATRICES) | {"power_balance", "measured_expressions"}
    for name in sorted(names):
        edits[f"s.{name} = ..."] = partial(setattr, s, name, getattr(s, name))
        edits[f"del s.{name}"] = partial(delattr, s, name)
    # the frozen records it holds
    edits["params[0].value = ..."] = partial(setattr, s.params[0], "value", -1.0)
    edits["states[0].range[0] = ..."] = partial(setitem, s.states[0].range, 0, 0.0)
    if s.inputs and s.inputs[0].range is not None:
        edits["inputs[0].range[0] = ..."] = partial(setitem, s.inputs[0].range, 0, 0.0)
    edits["params[0].range[1] = ..."] = partial(setitem, s.params[0].range, 1, 0.0)
    return edits


@pytest.mark.parametrize(("name", "case"), CASES)
def test_every_edit_in_place_raises_and_changes_nothing(name, case):
    ref, run = _reference(name)
    s = case[0]()
    before = s.model_hash()
    assert before == ref.model_hash()
    got_through = []
    for label, edit in _edits(s).items():
        try:
            edit()
        except (TypeError, AttributeError):  # dataclasses.FrozenInstanceError is an AttributeError
            continue
        got_through.append(label)
    assert got_through == [], f"{name}: these edits changed the model in place: {got_through}"
    assert s.model_hash() == before
    assert s.param_values() == ref.param_values() and s.state_names == ref.state_names
    assert all(st.range == r.range for st, r in zip(s.states, ref.states, strict=True))
    if run is not None:  # the same generated functions, inputs and grid: bitwise the same run
        _, u, x0, t_end = case
        again = simulate(s, np.linspace(0.0, t_end, 21), u=u, x0=x0)
        np.testing.assert_array_equal(again.x, run.x)


def test_the_errors_say_the_model_is_frozen_and_how_to_make_a_new_one():
    s = mass_spring_damper()
    for edit in (lambda: setattr(s, "R", sp.zeros(2, 2)), lambda: delattr(s, "grad_H"),
                 lambda: s.structure.__setitem__("components", ()), lambda: s.power_balance.update({}),
                 lambda: s.dissipators[0][1].clear()):
        with pytest.raises((TypeError, AttributeError)) as err:
            edit()
        text = str(err.value)
        assert "\n" not in text and "frozen" in text and "with_params()" in text, text
    with pytest.raises(TypeError, match="Cannot set values of .*ImmutableDenseMatrix"):  # sympy's own one line
        s.R[0, 0] = -s.R[0, 0]


def test_check_and_certificate_after_an_attempted_edit_describe_the_simulated_system():
    """The reproduction: negating the damping in place used to go through; ``check()`` and ``certify``
    still passed it (the dissipation matrix was cached at construction) while the simulation ran the
    negative damping and the oscillation grew (energy 1.25e-3 J -> 4.1 J in 20 s)."""
    s = mass_spring_damper()
    try:
        s.R[0, 0] = -s.R[0, 0]
    except TypeError:
        pass
    report, cert = s.check(), certify(s, samples=64, starts=1)
    run = simulate(s, np.linspace(0.0, 20.0, 201), u={"F": 0.0}, x0={"k.l": 0.025})
    assert report.ok and cert.passive
    # what both say holds for the run: without input the stored energy never rises (beyond the integrator's
    # relative tolerance 1e-8 of the start) and decays (b = 0.4: about exp(-0.4 * 20) = 3.4e-4 of the start
    # in 20 s, far below the 1e-2 asserted)
    assert np.all(np.diff(run.H) <= 1e-8 * run.H[0]) and run.H[-1] < 1e-2 * run.H[0]
    assert s.R[0, 0] == sp.Symbol("b.b", positive=True)


def test_nothing_given_to_a_model_or_its_components_can_change_it_afterwards():
    q = sp.Symbol("q", real=True)
    k = Param("k", 2.0, "N/m")
    R, rng, structure = sp.Matrix([[0.5]]), [-1.0, 1.0], {"notes": ["given"]}
    s = PHSystem("spring", [StateInfo("q", "m", rng)], H=k.symbol * q**2 / 2, J=[[0]], R=R, params=[k],
                 structure=structure)
    before = s.model_hash()
    R[0, 0], rng[0] = -0.5, 0.5
    structure["notes"].append("later")
    assert (s.R[0, 0], s.states[0].range, s.structure["notes"]) == (0.5, (-1.0, 1.0), ("given",))
    assert s.model_hash() == before
    # components are ordinary objects: changing one after the build leaves the built system alone
    src, res = VoltageSource("U", range=[-5.0, 5.0]), Resistor("R", R=1e3)
    rc = interconnect("rc", [src, res, Capacitor("C", C=1e-6)], [series("U", "R", "C")])
    res.R = 1.0
    rc2 = interconnect("rc", [src, res, Capacitor("C", C=1e-6)], [series("U", "R", "C")])
    assert rc.param("R.R").value == 1e3 and rc2.param("R.R").value == 1.0
    assert isinstance(rc.inputs[0].range, tuple) and isinstance(rc.structure["components"], tuple)


def test_a_frozen_model_pickles_saves_and_loads_as_one(tmp_path):
    s = rc_circuit()
    _ = s.power_balance, s.measured_expressions  # cached values travel with the object
    for copy in (pickle.loads(pickle.dumps(s)), PHSystem.load(_saved(s, tmp_path / "rc.json"))):
        assert copy.model_hash() == s.model_hash()
        with pytest.raises(TypeError):
            copy.R[0, 0] = 0
        with pytest.raises(TypeError):
            copy.dissipators[0][1].clear()


def _saved(s, path):
    s.save(path)
    return path


def test_the_hash_covers_which_port_output_a_measured_output_reads():
    """Generated functions are shared between models of one hash: two models whose only difference is
    which input a port-output name belongs to must not share them."""
    from phs import InputInfo, Measured

    q = sp.Symbol("q", real=True)
    k = Param("k", 1.0, "N/m")

    def model(first, second):
        return PHSystem("two", [StateInfo("q")], H=k.symbol * q**2 / 2, J=[[0]], R=[[0]], G=[[1, 2]], params=[k],
                        inputs=[InputInfo("u1", output=first), InputInfo("u2", output=second)],
                        measured=[Measured("y", sp.Symbol("a", real=True))])

    a, b = model("a", "b"), model("b", "a")
    assert a.measured_expressions != b.measured_expressions
    assert a.model_hash() != b.model_hash()


# -- parameters declared outside their own range -------------------------------------------------------------
@pytest.mark.parametrize(("value", "rng"), [(5.0, (0.0, 1.0)), (-0.5, (0.0, 1.0)), (1e3, (1.0, 100.0))])
def test_a_param_declared_outside_its_range_is_refused_naming_it(value, rng):
    with pytest.raises(ParameterError) as err:
        Param("k", value, "N/m", "stiffness", range=rng, positive=False)
    text = str(err.value)
    assert "\n" not in text and "'k'" in text and f"{value:g}" in text and f"[{rng[0]:g}, {rng[1]:g}]" in text
    assert isinstance(err.value, ModelError)


def test_a_component_declaring_a_value_outside_its_range_is_refused_where_it_is_declared():
    class Damper01(Component):
        def __init__(self, name, b):
            super().__init__(name)
            self.b = b

        def piece(self):
            port = self._port("p", "translational")
            b, params = self._param("b", self.b, "N*s/m", "damping", (0.0, 1.0))
            return Piece(self.name, ports=(port,), relations=(Relation(port.effort - b * port.flow, self.name, "resistive"),),
                         dissipators=(Dissipator(self.name, (port,)),), params=params)

    from components import Mass

    with pytest.raises(ParameterError, match=r"'d\.b' = 5 \[N\*s/m\] is outside its declared range \[0, 1\]"):
        interconnect("m", [Mass("m"), Damper01("d", 5.0)], [series("m", "d")])
    assert interconnect("m", [Mass("m"), Damper01("d", 0.5)], [series("m", "d")]).param("d.b").value == 0.5


def test_an_override_outside_the_range_still_warns_keeps_the_declared_range_and_survives_a_save(tmp_path):
    with pytest.warns(ParameterRangeWarning, match=r"'R.R' = 1e\+09 is outside its declared range \[100, 10000\]"):
        s = rc_circuit().with_params({"R.R": 1e9})
    p = s.param("R.R")
    assert (p.value, p.range) == (1e9, (100.0, 10000.0))
    assert p.renamed("R2.R").value == 1e9  # untying an overridden parameter keeps its value
    with pytest.warns(ParameterRangeWarning, match="'R.R'"):
        loaded = PHSystem.load(_saved(s, tmp_path / "rc.json"))
    assert loaded.param("R.R") == p
    with pytest.raises(ParameterError, match="declared positive"):  # the sign is still refused
        s.with_params({"R.R": -1.0})


def test_frozen_records_keep_their_ranges_as_tuples():
    st = StateInfo("x", "m", [0, 2])
    assert st.range == (0.0, 2.0) and isinstance(st.range, tuple)
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.range = (0.0, 1.0)
    with pytest.raises(ModelError, match="'x'"):
        StateInfo("x", "m", "wide")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Param("k", 1.0, "N/m", range=[0.5, 2]).range == (0.5, 2.0)
