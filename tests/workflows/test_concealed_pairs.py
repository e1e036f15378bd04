"""Pairs of concealed effects in one truth (``examples/concealed_truths.py``, ``examples/concealed_effects.py``).

A pair's truth is the composition the generator promises: effects that add a force on the plate, a
current around the gap or a term of the measured position add their contributions (the pair's vector
field and outputs are the sum of the two single-effect truths' minus the plain actuator's); dielectric
layers in series with the RC ladder carry the loop current Kirchhoff's law gives; an amplifier effect
acts on the command of the other effect's truth, two of them one after the other.  Every listed pair
builds and simulates; the pair that cannot be combined is refused in one line; the random draw of
pairs is deterministic.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import sympy as sp

from phs.errors import InputDataError

ce = importlib.import_module("examples.concealed_effects")
ct = importlib.import_module("examples.concealed_truths")


def _evaluator(system):
    """``f(state by name, U)``: the time derivative of every state (``d<name>``) and every measured output."""
    field = system.lambdify(system.dynamics)
    outputs = system.lambdify(sp.Matrix(system.measured_expressions))

    def at(state, U):
        x = [state[n] for n in system.state_names]
        d = np.asarray(field(x, [U]), dtype=float).reshape(-1)
        y = np.asarray(outputs(x, [U]), dtype=float).reshape(-1)
        return {**{f"d{n}": v for n, v in zip(system.state_names, d)}, **dict(zip(system.measured_names, y))}
    return at


@pytest.mark.parametrize("a, b", [("coulomb_friction", "hysteresis"), ("charge_retention", "viscoelastic_creep"),
                                  ("charge_retention", "leakage"), ("quadratic_drag", "added_mass"),
                                  ("cubic_stiffness", "offset"), ("leakage", "hysteresis")])
def test_additive_pair_is_the_sum_of_its_effects(a, b):
    """Forces on the plate's junction, currents around the gap capacitor and terms of the measured
    position add: at any state, pair = truth(a) + truth(b) - plain actuator, entry by entry (each single
    truth evaluated on its own states).  With the drag, the pair keeps the drag truth's weaker linear
    damping, which the sum reproduces (drag truth's b, the added-mass truth's b minus the plain one's)."""
    pair = ct.pair_truth(a, b).system
    single = {e: ct.truth(e).system for e in (a, b, "none")}
    f = {e: _evaluator(s) for e, s in single.items()}
    fp = _evaluator(pair)
    for x in pair.sample_box(12, seed=5):
        state = dict(zip(pair.state_names, x))
        for U in (-14.0, 3.0, 21.0):
            got = fp(state, U)
            want = {e: f[e](state, U) for e in single}
            for key, value in got.items():
                parts = [want[a].get(key, 0.0), want[b].get(key, 0.0), -want["none"].get(key, 0.0)]
                # the same terms summed in another order: rounding of the largest term (relative 1e-12)
                assert value == pytest.approx(sum(parts), rel=1e-9, abs=1e-12 * max(map(abs, parts))), (key, state, U)


def test_dielectric_layers_in_series_with_the_ladder_carry_the_loop_current():
    """charge_retention + series_resistance: the source, R_s, both dielectric layers and the ladder's first
    resistor carry one current, i = (U - Q1/C1 - Q2/C2 - Q/(f C(x))) / (R_s + R1); the second section
    charges through R2: dQb/dt = (Q/(f C) - Qb/((1 - f) C)) / R2."""
    tr = ct.truth("series_resistance+charge_retention")
    s, cr, sr = tr.system, tr.parameters["charge_retention"], tr.parameters["series_resistance"]
    assert sorted(s.state_names) == sorted(["x", "m.p", "Q", "Qb", "D1.Q", "D2.Q"])
    f = _evaluator(s)
    B, frac = ct.BASE, sr["fraction"]
    for x in s.sample_box(15, seed=2):
        st = dict(zip(s.state_names, x))
        C = B["eps"] * B["A"] / (B["g0"] - st["x"])
        Va, Vb = st["Q"] / (frac * C), st["Qb"] / ((1 - frac) * C)
        for U in (-10.0, 18.0):
            i = (U - st["D1.Q"] / cr["C1"] - st["D2.Q"] / cr["C2"] - Va) / (B["R_s"] + sr["R1"])
            got = f(st, U)
            assert got["current"] == pytest.approx(i, rel=1e-9, abs=1e-20), st  # same terms, other order
            assert got["dQb"] == pytest.approx((Va - Vb) / sr["R2"], rel=1e-9, abs=1e-20), st


def test_amplifier_pair_drives_the_other_truth_with_the_applied_voltage():
    """The mechanical+amplifier pair driven by U is the mechanical truth driven by the delayed U (simulated
    on its own, through the framework's simulator with the delay's applied map); two amplifier effects
    act one after the other: saturation (tanh formula written out here), then the slew limit."""
    from codegen.simulator import simulate
    from phs.signals import Sampled

    t, U = ce.program("time_delay", 1.0)
    got = ce.simulate_truth(ct.truth("cubic_stiffness+time_delay"), t, U)
    times, values = ct.truth("time_delay").applied(t, U)
    res = simulate(ct.truth("cubic_stiffness").system, t, u={"U": Sampled(tuple(times), tuple(values))}, rtol=1e-9)
    for ch in ("position", "current"):
        ref = np.asarray(res[ch], dtype=float)
        # the same equations integrated at rtol 1e-9: agreement far inside 1e-7 of the channel's range
        assert np.max(np.abs(got[ch] - ref)) <= 1e-7 * np.ptp(ref), ch
    assert not np.allclose(got["current"], ce.simulate_truth(ct.truth("cubic_stiffness"), t, U)["current"], rtol=1e-3)
    up, un = ct.SIZES["input_saturation"]["U_pos"], ct.SIZES["input_saturation"]["U_neg"]
    t, U = ce.program("slew_rate_limit", 2.0)
    sat = np.where(U >= 0, up * np.tanh(U / up), un * np.tanh(U / un))
    want = ct._rate_limited(t, sat, ct.SIZES["slew_rate_limit"]["S"])
    for name in ("input_saturation+slew_rate_limit", "slew_rate_limit+input_saturation"):
        tt, y = ct.truth(name).applied(t, U)
        assert np.array_equal(tt, want[0]) and np.array_equal(y, want[1]), name


def test_every_listed_pair_builds_and_simulates():
    """Each pair of PAIRS builds, runs 0.5 s of its program and leaves the single effects' truths as they
    were; the listing is every combinable pair whose program reveals both effects alone."""
    assert len(ce.PAIRS) == len(set(ce.PAIRS)) == 64
    for name in ce.PAIRS:
        a, b = name.split("+")
        assert ct.pair_problem(a, b) is None and {a, b} <= set(ce.EXCITES[ce.program_kind(name)]), name
        tr = ct.truth(name)
        assert set(tr.parameters) == {a, b} and tr.system.name == f"truth_{a}_and_{b}"
        t, U = ce.program(name, 0.5)
        clean = ce.simulate_truth(tr, t, U)
        assert all(np.all(np.isfinite(clean[ch])) for ch in ("position", "current")), name
        assert np.ptp(clean["position"]) > 1e-7, name  # the plate moved (of the order of um)
    # the name's order changes neither the system nor the recording
    assert ct.truth("offset+leakage").system.model_hash() == ct.truth("leakage+offset").system.model_hash()
    r1, i1 = ce.generate("offset+leakage", seconds=0.5)
    r2, i2 = ce.generate("leakage+offset", seconds=0.5)
    assert np.array_equal(r1["position"], r2["position"]) and i1["effects"] == ["offset", "leakage"]
    assert i2["effects"] == ["leakage", "offset"] and i1["program"] == "steps"


def test_pairs_that_cannot_be_combined_are_refused_in_one_line(tmp_path, capsys):
    cases = {("series_resistance", "leakage"): ["'series_resistance'", "'leakage'", "gap capacitor"],
             ("leakage", "series_resistance"): ["'leakage'", "'series_resistance'", "replaces"],
             ("leakage", "leakage"): ["'leakage' twice"], ("none", "offset"): ["'none' is no effect"],
             ("offset", "stiction"): ["unknown effect 'stiction'", "offset+stiction"]}
    for (a, b), words in cases.items():
        for call, arg in ((ct.pair_truth, (a, b)), (ct.truth, (f"{a}+{b}",)), (ce.generate, (f"{a}+{b}",))):
            with pytest.raises(InputDataError) as err:
                call(*arg)
            msg = str(err.value)
            assert "\n" not in msg and all(w in msg for w in words), msg
        assert f"{a}+{b}" not in ce.PAIRS and f"{b}+{a}" not in ce.PAIRS
    with pytest.raises(SystemExit):  # the command line refuses before writing anything
        ce.main(["--out", str(tmp_path / "bad"), "--seconds", "0.5", "--effects", "none,series_resistance+leakage", "--quiet"])
    assert "cannot combine 'series_resistance' and 'leakage'" in capsys.readouterr().err and not (tmp_path / "bad").exists()
    assert ce.main(["--out", str(tmp_path / "ok"), "--seconds", "0.5", "--effects", "leakage+offset", "--quiet"]) == 0
    assert sorted(p.name for p in (tmp_path / "ok").iterdir()) == ["cases.json", "leakage+offset_train.csv",
                                                                   "leakage+offset_validation.csv"]
    with pytest.raises(InputDataError, match="one effect or a pair"):
        ct.truth("leakage+offset+hysteresis")
    with pytest.raises(InputDataError, match="must be positive"):
        ct.pair_truth("leakage", "offset", size=0.0)


def test_random_pairs_are_deterministic_distinct_and_listed():
    a, b = ce.random_pairs(12, seed=3), ce.random_pairs(12, seed=3)
    assert a == b and len(set(a)) == 12 and set(a) <= set(ce.PAIRS)
    assert ce.random_pairs(12, seed=4) != a
    assert sorted(ce.random_pairs(len(ce.PAIRS), seed=0)) == sorted(ce.PAIRS)
    for bad in (0, len(ce.PAIRS) + 1, 2.5, True):
        with pytest.raises(InputDataError, match="random_pairs: n must be"):
            ce.random_pairs(bad)
    # every case, seed and split has its own noise stream: a pair's never repeats a single effect's
    seeds = [tuple(ce._case_seed(c, s, v)) for c in ce.EFFECTS + ce.PAIRS for s in range(3) for v in (False, True)]
    assert len(seeds) == len(set(seeds))
