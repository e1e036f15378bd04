"""Discovery finds passive corrections the library cannot express, names them and emits them as components.

The recordings come from ``examples/concealed_novel.py``: the electrostatic actuator with a fringe-field
capacitance, a leakage that heats, a one-sided spring engaging part-way through the stroke, a stiffness
softening exponentially with stroke, or a drive gain falling with stroke.  Fast tests run the discovery step alone on a short recording; the
whole diagnosis of every case (library and discovery) and the in-library cases run with ``-m slow``
(and ``bench/discover.py``); Silverbox without the cubic stiffness is in ``test_diagnose_real.py``.
"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from examples.concealed_novel import NOVEL, generate, truth_gain
from phs.errors import InputDataError, PHSError
from phs.workflows.cli import main
from phs.workflows.diagnose import diagnose, noise_level
from phs.workflows.diagnose.discover import Discovered, describe, dictionary, discover, select, source
from phs.workflows.diagnose.hypotheses import Data, _simulate
from phs.workflows.diagnose.nominal import fit_nominal
from systems.electrostatic_actuator import electrostatic_actuator

FREE = ["k", "b", "eps"]


def _data(effect, seconds):
    train, info = generate(effect, seconds=seconds, seed=1)
    val, vinfo = generate(effect, seconds=seconds, seed=2, validation=True)
    return Data(train, val, np.ones(len(val), bool), None, ["position", "current"], FREE, {}, [], None), info, vinfo


@pytest.fixture(scope="module")
def softening():
    """Discovery alone on the softening-stiffness case (2 s recordings)."""
    data, info, vinfo = _data("softening_stiffness", 2.0)
    nominal, data = fit_nominal(electrostatic_actuator(), data)
    noise = {ch: noise_level(data.recording[ch]) for ch in data.outputs}
    return discover(nominal, nominal, data, noise, n_jobs=1), nominal, data, info, vinfo


def test_every_dictionary_term_is_passive_at_its_bounds():
    import dataclasses

    from components.candidates import Scales

    s = electrostatic_actuator()
    terms = dictionary(s, dataclasses.replace(Scales.of(s), duration=20.0), outputs=["position", "current"])
    from phs.workflows.diagnose.discover.families import DEFAULT_KINDS

    assert {t.kind for t in terms} == {"energy", "damping", "memory", "input", "sensor", *DEFAULT_KINDS} and len(terms) > 15
    assert {"mode", "drift"} <= set(DEFAULT_KINDS)
    # sensor terms only on an output that reads one state (the position), never on the source current
    assert {t.state for t in terms if t.kind == "sensor"} == {"position"}
    for t in terms:
        # nonnegative terms (growing energies, every dissipation) at their largest coefficient; signed
        # energies at a typical one of either sign (the fit keeps them only where H stays bounded below);
        # input gains at both ends of their range
        gain = t.kind == "input" or t.shape == "drift_gain"
        thetas = t.bounds() if gain else (-1.0, 1.0) if t.signed else (t.bounds()[1],)
        for theta in thetas:
            aug = Discovered([t]).augment(s, t.state, None)
            values = {t.parameter: theta}
            # a heat state's sensitivity and time constant, a mode's frequency and damping, a drift's time
            # constant at their bounds too
            values.update({p.name: p.range[1] for p in t.params()[1:]})
            report = aug.system.with_params(values).check(samples=50)
            assert report.ok, (t.label, theta, str(report))


def test_heat_state_and_input_gain_keep_the_energy_balance():
    """A heated leakage and a drive gain on the actuator: the power balance closes, the heat follows its
    law, and the heat store receives exactly the extra power the network loses to the rise of the conductance."""
    from scipy.integrate import cumulative_trapezoid

    from codegen import Simulator, simulate
    from components.candidates import Scales
    from examples.concealed_effects import program

    s = electrostatic_actuator()
    t, U = program("none", 1.0)
    nominal = simulate(s, t, u={"U": U})
    X = np.column_stack([nominal[n] for n in s.state_names])
    terms = {t_.label: t_ for t_ in dictionary(s, Scales.of(s, t, X, U[:, None]))}
    mem, gain = terms["Q:heated"], terms["U:gain_square(x)"]
    start = {mem.parameter: 1.0, mem.parameters[1]: 3.0, mem.parameters[2]: 0.05, gain.parameter: -0.3}
    system = Discovered([mem, gain], start).augment(s, "Q", None).system
    assert system.check().ok
    res = Simulator(system, energy=True).run(t, u={"U": U})
    H, q = np.asarray(res.H), res.quadratures
    # whole balance: H(T) - H(0) = supplied - dissipated, to the quadrature's accuracy (1e-4 of the supplied energy)
    assert abs((H[-1] - H[0]) - (q["E_supplied"][-1] - q["E_dissipated"][-1])) <= 1e-4 * q["E_supplied"][-1]
    v = {p.name: p.value for p in system.params}
    z, Q, x = (np.asarray(res[n]) for n in (mem.heat_state, "Q", "x"))
    V = Q * (v["g0"] - x) / (v["eps"] * v["A"])
    g = v[mem.parameter] * v["discovered.Q_damping"]
    s_, E, tau = v[mem.parameters[1]], v["discovered.Q_heat"], v[mem.parameters[2]]
    u = s_ * z / E
    assert z.min() >= -1e-12 * z.max() and u.max() > 0.5  # the heat never goes negative; the rise is large enough to matter
    # the heat law, integrated independently on the 1 kHz grid (trapezoid: 1e-3 relative):
    # z(T) = ∫ G V² − z/τ with the conductance G = g (1 + s z / E)
    law = cumulative_trapezoid(g * (1 + u) * V**2 - z / tau, t)[-1]
    assert z[-1] == pytest.approx(law, rel=1e-3)
    # the power g u V² the network loses to the conductance's rise is what the heat store holds plus
    # what it has released (H_z = (E/s)(a − ln(1 + a)) − its value at 0, a = √(u² + δ²))
    into = cumulative_trapezoid(g * u * V**2, t)[-1]
    a = np.sqrt(u[-1] ** 2 + 1e-12)
    H_z = E / s_ * (a - np.log1p(a) - (1e-6 - np.log1p(1e-6)))
    assert H_z + q["E_dissipated[discovered@Q:heated:heat]"][-1] == pytest.approx(into, rel=1e-3)
    assert q["E_dissipated[discovered@Q:heated]"][-1] == pytest.approx(cumulative_trapezoid(g * V**2, t)[-1], rel=1e-3)


def test_discovery_recovers_a_softening_stiffness(softening):
    d, nominal, data, info, vinfo = softening
    assert d.found, d.reason
    gain = nominal.validation_rss - d.scored.validation_rss
    assert gain >= 0.7 * truth_gain(nominal.validation_rss, data.validation, vinfo["clean"])
    # conservative, on the displacement, and passive
    assert {x["state"] for x in d.described} == {info["state"]}
    assert {x["nature"] for x in d.described} == {info["nature"]}
    assert d.scored.system.check().ok
    assert 0.7 <= d.share <= 1.0
    assert "conservative" in d.text and "x" in d.text
    json.dumps(d.to_dict())


def test_emitted_source_imports_and_reproduces_the_fitted_model(softening, tmp_path):
    d, nominal, data, _, _ = softening
    path = tmp_path / "discovered_actuator.py"
    path.write_text(source(d, d.text, d.share))
    spec = importlib.util.spec_from_file_location("discovered_actuator", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cls = next(v for k, v in vars(mod).items() if k.startswith("Discovered") and isinstance(v, type))
    s = electrostatic_actuator().with_params(mod.FITTED)
    aug = cls().augment(s, cls().attach_points(s)[0], None)
    assert aug.system.check().ok and aug.free == [t.parameter for t in d.terms]
    sim = _simulate(aug.system, data.validation, d.scored.x0)
    for ch in data.outputs:
        ref = np.asarray(d.scored.simulated["validation"][ch])
        assert np.max(np.abs(np.asarray(sim[ch]) - ref)) <= 1e-6 * np.max(np.abs(ref)), ch


@pytest.fixture(scope="module")
def heating():
    """One discovered term on the heating-leakage case (2 s recordings)."""
    data, info, vinfo = _data("heating_resistance", 2.0)
    nominal, data = fit_nominal(electrostatic_actuator(), data)
    return select(nominal, data, max_terms=1), nominal, data, info, vinfo


def test_discovery_gives_the_heating_leakage_a_heat_state(heating):
    d, nominal, data, info, vinfo = heating
    assert d.found, d.reason
    (term,) = d.terms
    assert (term.kind, term.state) == ("memory", info["state"])
    # a single memoryless dissipation on Q recovers 0.68 of the truth's gain here (measured); the heat state 0.8
    gain = nominal.validation_rss - d.scored.validation_rss
    assert gain >= 0.75 * truth_gain(nominal.validation_rss, data.validation, vinfo["clean"])
    (said,) = describe(d.terms, d.values, nominal.system)
    assert said["nature"] == info["nature"] and said["memory"]["state"] == term.heat_state
    assert "rises with the heat it dissipates" in said["words"] and "τ ≈" in said["words"]
    assert d.scored.system.check().ok


def _load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod, next(v for k, v in vars(mod).items() if k.startswith("Discovered") and isinstance(v, type))


def test_emitted_source_with_a_heat_state_reproduces_the_fitted_model(heating, tmp_path):
    d, _, data, _, _ = heating
    path = tmp_path / "heated_actuator.py"
    path.write_text(source(d, "A heated leakage."))
    mod, cls = _load(path)
    aug = cls().augment(electrostatic_actuator().with_params(mod.FITTED), "Q", None)
    assert aug.system.check().ok and aug.x0 == {d.terms[0].heat_state: 0.0}
    assert set(aug.free) == set(d.values)
    sim = _simulate(aug.system.with_params(d.values), data.validation, d.scored.x0)
    for ch in data.outputs:  # the same model: agreement to the integrator's tolerance
        ref = np.asarray(d.scored.simulated["validation"][ch])
        assert np.max(np.abs(np.asarray(sim[ch]) - ref)) <= 1e-6 * np.max(np.abs(ref)), ch


def test_discovery_finds_a_drive_gain_falling_with_stroke():
    data, info, vinfo = _data("drive_gain", 2.0)
    nominal, data = fit_nominal(electrostatic_actuator(), data)
    d = select(nominal, data, max_terms=1)
    assert d.found, d.reason
    (term,) = d.terms
    assert (term.kind, term.state, term.via) == ("input", info["input"], info["state"])
    gain = nominal.validation_rss - d.scored.validation_rss
    assert gain >= 0.9 * truth_gain(nominal.validation_rss, data.validation, vinfo["clean"])
    # the gain at the largest stroke of the fit x_s: 1 + theta (the shape is 1 there) against the truth's
    # 1 / (1 + (x_s / x_g)²); a parabola fitted to that rational curve over the stroke is off by a few
    # per cent of the drop at its end, hence 0.03
    truth = 1 / (1 + (term.q_s / info["parameters"]["x_g"]) ** 2)
    assert 1 + d.values[term.parameter] == pytest.approx(truth, abs=0.03)
    (said,) = describe(d.terms, d.values, nominal.system)
    assert said["nature"] == "input map" and said["input"] == "U" and "falls with x²" in said["words"]
    aug = d.scored.system
    assert aug.check().ok and aug.J == nominal.system.J and aug.R == nominal.system.R


def test_discovery_does_not_run_when_a_library_effect_explains_the_residual():
    from codegen import simulate
    from components.candidates import Leakage, Offset
    from phs.workflows.recording import Recording
    from systems.examples import rc_circuit

    t = np.linspace(0, 0.02, 401)
    u = np.where((t % 0.01) > 0.005, 1.0, 0.0)
    y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05
    rec = Recording.from_arrays(t, {"U": u, "v_C": y})
    library = [Leakage(), Offset()]
    d = diagnose(rc_circuit(), rec, free=["R.R"], n_jobs=1, candidates=library)
    assert d.effect == "offset" and d.discovery is None
    assert d.verdict["explained_share"] == pytest.approx(1.0, abs=0.02)
    assert d.to_dict()["discovered"] is None
    with pytest.raises(PHSError, match="no correction was discovered"):
        d.discovered_source()
    forced = diagnose(rc_circuit(), rec, free=["R.R"], n_jobs=1, candidates=library, discover=True)
    assert forced.effect == "offset" and forced.discovery is not None


def test_a_correction_leads_only_where_the_library_explains_little():
    from types import SimpleNamespace as NS

    from phs.workflows.diagnose.discover import amend_verdict

    found = NS(found=True, share=0.9, text="Discovered correction: a heated leakage.", to_dict=lambda: {"found": True})
    lib = {"effect": "offset", "effects": ["offset"], "explanation": "Offset.", "confidence": 0.8, "failed": []}
    led = amend_verdict(lib, found, 1.0, library_share=0.47)
    assert led["effect"] == "discovered" and led["effects"] == ["discovered", "offset"] and led["confidence"] == 0.95
    assert led["explanation"].startswith("Discovered correction") and "47 %" in led["explanation"]
    # the library explains half or more, or the correction explains less than half of the rest: the library leads
    for share, extra in ((0.5, 0.9), (0.3, 0.4)):
        kept = amend_verdict(lib, NS(**{**vars(found), "share": extra}), 1.0, library_share=share)
        assert kept["effect"] == "offset" and kept["effects"] == ["offset", "discovered"] and kept["confidence"] == 0.8


def test_command_line_discover_flags(tmp_path):
    from phs.workflows.cli import build_parser

    args = build_parser().parse_args(["diagnose", "m:f", "d.csv", "--discover", "--discover-out", "x.py"])
    assert args.discover is True and args.discover_out == "x.py"
    out = tmp_path / "x.py"
    with pytest.raises(InputDataError, match="--no-discover"):
        from phs.workflows.diagnose.cli import run_diagnose

        run_diagnose(build_parser().parse_args(["diagnose", "m:f", "d.csv", "--no-discover", "--discover-out", str(out)]))
    assert not out.exists()


def test_command_line_writes_the_discovered_component(tmp_path):
    """``phs diagnose --discover-out``: a hardening spring outside a library holding only an offset."""
    from codegen import simulate
    from components.candidates import add_energy
    from systems.examples import mass_spring_damper

    msd = mass_spring_damper()
    q = msd.states[msd.state_names.index("k.l")].symbol
    truth = add_energy(msd, "stiffening", 2.0 * q**4 / 4, [], "stiffening")
    t = np.linspace(0.0, 12.0, 601)
    F = 3.0 * np.sin(2 * np.pi * 0.4 * t) * np.minimum(t / 4.0, 1.0)
    y = simulate(truth, t, u={"F": F})["position"] + 0.005 * np.random.default_rng(0).standard_normal(t.size)
    csv = tmp_path / "run.csv"
    np.savetxt(csv, np.column_stack([t, F, y]), delimiter=",", header="t,F,position", comments="")
    out, js = tmp_path / "correction.py", tmp_path / "d.json"
    assert main(["diagnose", "systems.examples:mass_spring_damper", str(csv), "--free", "k.K,b.b", "--effects", "offset",
                 "--discover-out", str(out), "--json", str(js), "--report", str(tmp_path / "report"), "--jobs", "1", "--quiet"]) == 0
    page = (tmp_path / "report" / "index.html").read_text()
    assert "Discovered correction" in page and "of what the nominal model misses" in page
    doc = json.loads(js.read_text())
    assert doc["verdict"]["effect"] == "discovered" and doc["discovered"]["terms"][0]["state"] == "k.l"
    assert doc["verdict"]["explained_share"] > 0.9
    spec = importlib.util.spec_from_file_location("correction", out)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cls = next(v for k, v in vars(mod).items() if k.startswith("Discovered") and isinstance(v, type))
    aug = cls().augment(mass_spring_damper().with_params(mod.FITTED), "k.l", None)
    assert aug.system.check().ok


# -- slow: whole diagnoses ----------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("effect", NOVEL)
def test_diagnosis_of_novel_effects(effect):
    data, info, vinfo = _data(effect, 3.0)
    d = diagnose(electrostatic_actuator(), data.recording, validation=data.validation, free=FREE)
    truth = truth_gain(d.nominal.validation_rss, data.validation, vinfo["clean"])
    for h in d.accepted:  # a library effect is named only when its fit reaches most of the truth's gain
        assert d.nominal.validation_rss - h.validation_rss >= 0.5 * truth, d.summary()
    assert d.structure_checks()["ok"]
    gain = d.nominal.validation_rss - d.final.validation_rss
    if info["nature"] == "conservative":
        assert gain >= 0.7 * truth, d.summary()
    if not d.accepted:  # then discovery names it (for an input map: on the input, with the state)
        assert d.effect == "discovered", d.summary()
        assert info["state"] in {x["state"] for x in d.discovery.described}
        assert info["nature"] in {x["nature"] for x in d.discovery.described}
        if info["input"]:
            assert info["input"] in {x.get("input") for x in d.discovery.described}
    doc = json.loads(json.dumps(d.to_dict(), default=str))
    assert 0.0 <= doc["verdict"]["explained_share"] <= 1.0


@pytest.mark.slow
def test_heating_leakage_discovered_after_the_library():
    """The 20 s heating leakage, whole diagnosis: the library's offset accepted first, then a leakage with its own
    heat state, next to which the offset does not earn its place (it stood for the leak's mean current)."""
    data, info, vinfo = _data("heating_resistance", 20.0)
    d = diagnose(electrostatic_actuator(), data.recording, validation=data.validation, free=FREE)
    truth = truth_gain(d.nominal.validation_rss, data.validation, vinfo["clean"])
    assert d.discovery is not None and d.discovery.found, d.summary()
    # the offset explains less than half, the heated leakage nearly all of it alone: the offset is dropped
    assert d.effect == "discovered" and d.verdict["effects"] == ["discovered"] and not d.accepted, d.summary()
    assert d.verdict["dropped"] == ["offset@current"], d.summary()
    heated = [t for t in d.discovery.terms if t.kind == "memory"]
    assert [t.state for t in heated] == [info["state"]], d.summary()
    assert d.nominal.validation_rss - d.final.validation_rss >= 0.7 * truth, d.summary()
    assert d.structure_checks()["ok"]
    # the heat state's time constant: the truth's is R_th C_th = 0.99 s; within a factor 2
    tau = d.discovery.values[heated[0].parameters[2]]
    assert 0.5 <= tau <= 2.0, tau


@pytest.mark.slow
@pytest.mark.parametrize("effect", ["cubic_stiffness", "leakage", "offset"])
def test_in_library_verdicts_stand(effect):
    from examples.concealed_effects import NOMINAL_FREE
    from examples.concealed_effects import generate as generate_library

    train, _ = generate_library(effect, seconds=3.0, seed=1)
    val, _ = generate_library(effect, seconds=3.0, seed=2, validation=True)
    d = diagnose(electrostatic_actuator(), train, validation=val, free=list(NOMINAL_FREE))
    assert d.effect == effect, d.summary()
    assert d.discovery is None or d.verdict["effects"][0] == effect



def test_a_rival_correction_replaces_a_library_effect_only_when_clearly_better():
    """``_beats``: the correction found from the nominal model must lower the validation residual by
    RIVAL_MARGIN and the BIC by MIN_BIC_GAIN against the library model; either short of it keeps the
    library's effect (the Silverbox case, where it replaces an imitating hysteresis, is a slow test in
    ``test_diagnose_real.py``)."""
    from types import SimpleNamespace

    from phs.workflows.diagnose.ranking import MIN_BIC_GAIN
    from phs.workflows.diagnose.run import RIVAL_MARGIN, _beats

    library = SimpleNamespace(validation_rss=1.0, bic=100.0)

    def rival(vrss, bic, found=True):
        return SimpleNamespace(found=found, scored=SimpleNamespace(validation_rss=vrss, bic=bic))

    clearly = 1 - RIVAL_MARGIN - 0.01
    assert _beats(rival(clearly, 100.0 - MIN_BIC_GAIN - 1), library)
    assert not _beats(rival(1 - RIVAL_MARGIN + 0.01, 100.0 - MIN_BIC_GAIN - 1), library)  # residual not low enough
    assert not _beats(rival(clearly, 100.0 - MIN_BIC_GAIN + 1), library)  # BIC not low enough
    assert not _beats(rival(0.1, 0.0, found=False), library) and not _beats(None, library)


def test_a_library_effect_must_earn_its_place_next_to_the_correction():
    """``_earns``: the model with the accepted library effects and the correction must pass the library's
    acceptance rule against the correction alone (BIC lower by MIN_BIC_GAIN and validation residual lower
    by MIN_VALIDATION_GAIN), else the effects are dropped (``verdict["dropped"]``)."""
    from types import SimpleNamespace

    from phs.workflows.diagnose.ranking import MIN_BIC_GAIN, MIN_VALIDATION_GAIN
    from phs.workflows.diagnose.run import _earns

    alone = SimpleNamespace(validation_rss=1.0, bic=100.0)

    def with_library(vrss, bic):
        return SimpleNamespace(validation_rss=vrss, bic=bic)

    better = 1 - MIN_VALIDATION_GAIN - 0.001
    assert _earns(with_library(better, 100.0 - MIN_BIC_GAIN - 1), alone)
    assert not _earns(with_library(better, 100.0 - MIN_BIC_GAIN + 1), alone)  # BIC not low enough
    assert not _earns(with_library(1 - MIN_VALIDATION_GAIN + 0.001, 100.0 - MIN_BIC_GAIN - 1), alone)  # residual
    assert not _earns(with_library(1.2, 90.0), alone)  # worse on validation


def test_the_screen_in_worker_processes_ranks_as_in_one_process(softening):
    """The dictionary's groups screened side by side (``n_jobs=2``, forked workers) give every term the same
    first-order share and coefficient as the groups screened one after the other: the same integrations,
    in other processes (equal to rounding)."""
    from phs.workflows.diagnose.discover.selection import _groups, screen
    from phs.workflows.diagnose.discover.selection import _scales as scales_of
    from phs.workflows.diagnose.discover.selection import _trajectory

    _, nominal, data, _, _ = softening
    res, traj = _trajectory(nominal, data)
    terms = dictionary(nominal.system, scales_of(nominal, data, res), traj, outputs=data.outputs)
    assert len(_groups(terms)) >= 2  # more than one group, so that the workers have something to share
    one = screen(nominal, [], terms, data, nominal.system, n_jobs=1)
    two = screen(nominal, [], terms, data, nominal.system, n_jobs=2)
    assert [t.label for t, _, _ in one] == [t.label for t, _, _ in two]
    np.testing.assert_allclose([g for _, g, _ in two], [g for _, g, _ in one], rtol=1e-12, atol=0)
    np.testing.assert_allclose([c for _, _, c in two], [c for _, _, c in one], rtol=1e-12, atol=0)
