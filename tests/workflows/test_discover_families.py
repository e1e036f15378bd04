"""Discovery's families that append states (a mode, a drift, a limit at a port): each checked against
an independent integration of the physics it stands for, passive by the structural checks, and
reproduced by the source it emits."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
from types import SimpleNamespace as NS

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from codegen import Simulator
from components.candidates import Scales
from phs.workflows.diagnose.discover.dictionary import Discovered, Term, dictionary
from phs.workflows.diagnose.discover.emission import source
from phs.workflows.diagnose.discover.families import DEFAULT_KINDS, DRIFT_SLOWER, DRIFT_TAU, KINDS, refine_mode, retuned, slowest_decay
from phs.workflows.diagnose.discover.families import added_terms as _added
from systems.examples import mass_spring_damper, rc_circuit

T = np.linspace(0.0, 4.0, 2001)


def added_terms(system, scales, span=None):
    """Every family's terms (the port limit too, which the default dictionary leaves out)."""
    return _added(system, scales, span, kinds=KINDS, make=Term)


def _force(t):
    """A smooth-edged force pulse train (what the body and its mode are driven with)."""
    return 2.0 * (np.tanh(20 * (np.sin(2 * np.pi * 0.7 * t) - 0.2)) + 1.0)


def _scales(system):
    """The system's typical magnitudes on a recording of 60 s, long enough for a drift slower than ten times
    the slowest decay of the models here (5 s for the mass-spring-damper)."""
    return dataclasses.replace(Scales.of(system), duration=60.0)


def _term(system, kind, span=None, **match):
    return next(t for t in added_terms(system, _scales(system), span)
                if t.kind == kind and all(getattr(t, k) == v for k, v in match.items()))


def _run(system, values, u, x0=None):
    sim = Simulator(system.with_params(values), energy=False, rtol=1e-10)
    return sim.run(T, u=u, x0=x0)


def test_every_family_is_in_the_dictionary_and_passive():
    s = mass_spring_damper()
    terms = dictionary(s, _scales(s))
    assert not {t.kind for t in terms} & set(KINDS) - set(DEFAULT_KINDS)  # only the default families join the dictionary
    assert not any(t.kind == "limit" for t in added_terms(s, _scales(s)))  # a force input is not an electrical port
    rc = rc_circuit()
    assert [t.label for t in added_terms(rc, _scales(rc)) if t.kind == "limit"] == ["U:current_limit"]
    for sysm in (s, rc):
        for t in added_terms(sysm, _scales(sysm)):
            # at a typical size, not only at the neutral point: the checks must hold where fits go
            start = {t.parameter: 0.5}
            aug = Discovered([t], start).augment(sysm, t.state, None)
            assert aug.system.check().ok, t.label
            assert set(aug.x0) == set(t.new_states) and all(v == 0.0 for v in aug.x0.values())
            assert set(t.log_parameters) <= set(aug.free)


def test_a_mode_moves_the_body_as_a_second_mass_on_a_spring_does():
    s = mass_spring_damper()
    t = retuned(_term(s, "mode"), 3.0)
    mu, f, zeta = 0.4, 3.0, 0.05
    values = {t.parameter: mu, t.parameters[1]: f, t.parameters[2]: zeta}
    aug = Discovered([t], values).augment(s, t.state, None)
    out = _run(aug.system, values, {"F": _force})
    m, k, b = 1.0, 4.0, 0.4
    m_s = t.amplitude  # the mode's mass is mu times the body's mass scale (momentum over velocity along the fit)
    m2, w = mu * m_s, 2 * math.pi * f
    k2, c2 = m2 * w**2, 2 * zeta * m2 * w

    def rhs(tt, y):  # two masses: the body on its spring and damper, the mode on the body
        x1, v1, x2, v2 = y
        f12 = k2 * (x2 - x1) + c2 * (v2 - v1)
        return [v1, (_force(tt) - k * x1 - b * v1 + f12) / m, v2, -f12 / m2]

    ref = solve_ivp(rhs, (T[0], T[-1]), [0, 0, 0, 0], t_eval=T, method="Radau", rtol=1e-10, atol=1e-12)
    # both integrate the same linear ODE to rtol 1e-10: agreement far below the motion (1e-6 of its range)
    assert np.max(np.abs(out["position"] - ref.y[0])) <= 1e-6 * np.ptp(ref.y[0])
    # and the mode matters: without it the body moves differently by more than a per cent of its range
    plain = _run(s, {}, {"F": _force})
    assert np.max(np.abs(plain["position"] - ref.y[0])) >= 1e-2 * np.ptp(ref.y[0])


def test_a_drift_is_never_faster_than_the_models_own_decay():
    """A drift is slower than ``DRIFT_SLOWER`` times the fitted model's slowest decay, whose transient it
    would otherwise stand for; a recording shorter than that gets no drift."""
    s = mass_spring_damper()  # m = 1, b = 0.4: poles -0.2 ± 1.99j, a decay in 1/0.2 = 5 s
    assert slowest_decay(s) == pytest.approx(5.0, rel=1e-9)
    rc = rc_circuit()  # one pole, -1/(RC)
    R, C = (rc.param_values()[n] for n in ("R.R", "C.C"))
    assert slowest_decay(rc) == pytest.approx(R * C, rel=1e-9)
    for length, present in ((0.9 * DRIFT_SLOWER * 5.0, False), (1.1 * DRIFT_SLOWER * 5.0, True), (30 * DRIFT_SLOWER * 5.0, True)):
        sc = dataclasses.replace(Scales.of(s), duration=length)
        drifts = [t for t in added_terms(s, sc) if t.kind == "drift"]
        assert bool(drifts) == present, length
        for t in drifts:  # the time constant's range starts at the floor, or at DRIFT_TAU's share of a long recording
            lo, hi = t.params({})[1].range
            assert lo == pytest.approx(max(DRIFT_SLOWER * 5.0, DRIFT_TAU[0] * length)) and hi == pytest.approx(DRIFT_TAU[1] * length)
            assert lo <= t.params({})[1].value <= hi


@pytest.mark.filterwarnings("ignore::phs.errors.ParameterRangeWarning")  # τ = 1.5 s: the physics, below a fit's floor
def test_a_drifting_stiffness_is_a_spring_whose_constant_relaxes_to_its_drifted_value():
    s = mass_spring_damper()
    # scaled as along a fit: the largest |x| reached (0.73 m here) is about the scale q_s = 1 m
    t = _term(s, "drift", span=lambda q: (1.0, 1.0, -1.0), shape="drift_stiffness")
    dk, tau = -1.2, 1.5  # the stiffness 4 N/m falls by 30 %
    theta = dk * t.q_s**2 / t.amplitude  # the added energy θ s E_s (q/q_s)²/2 is a stiffness θ E_s/q_s² times s
    values = {t.parameter: theta, t.parameters[1]: tau}
    aug = Discovered([t], values).augment(s, t.state, None)
    out = _run(aug.system, values, {"F": _force})

    def rhs(tt, y):
        x, v = y
        k_t = 4.0 + dk * (1 - math.exp(-tt / tau))
        return [v, _force(tt) - k_t * x - 0.4 * v]

    ref = solve_ivp(rhs, (T[0], T[-1]), [0, 0], t_eval=T, method="Radau", rtol=1e-10, atol=1e-12)
    # the clock feels the spring's energy through its own gradient, 1/CLOCK_ENERGY of its drive
    # (|θ| z²/2e4 of its course, z = x/q_s ≤ 0.73), a stiffness error of 30 % of that: agreement to 1e-4 of the range
    assert abs(theta) * 0.73**2 / 2e4 * 0.3 <= 1e-4
    assert np.max(np.abs(out["position"] - ref.y[0])) <= 1e-4 * np.ptp(ref.y[0])
    plain = _run(s, {}, {"F": _force})  # and the drift is seen: the plain spring's course differs by more than 1 %
    assert np.max(np.abs(plain["position"] - ref.y[0])) >= 1e-2 * np.ptp(ref.y[0])


def test_a_current_limit_holds_the_source_current_below_it():
    s = rc_circuit()
    step = lambda tt: 5.0 * np.tanh(50 * np.sin(2 * np.pi * 2.0 * tt))  # noqa: E731 - ±5 V squares with smooth edges
    plain = _run(s, {}, {"U": step})
    # scaled along the plain circuit's course, as along a fit
    scales = Scales.of(s, T, np.asarray(plain["C.Q"]).reshape(-1, 1), step(T).reshape(-1, 1))
    t = next(x for x in added_terms(s, scales) if x.kind == "limit")
    i_peak = float(np.max(np.abs(np.gradient(plain["C.Q"], T))))
    theta = 2.0 * t.amplitude / i_peak  # the limit at half the peak current the plain circuit draws
    values = {t.parameter: theta}
    aug = Discovered([t], values).augment(s, t.state, None)
    out = _run(aug.system, values, {"U": step})
    i = np.gradient(out["C.Q"], T)
    limit = t.amplitude / theta
    # i = I tanh(e/e_k) never exceeds I; the finite-difference current of the sampled charge by at most
    # its own error (a few per cent at the sharpest turn)
    assert np.max(np.abs(i)) <= 1.05 * limit
    assert np.max(np.abs(i)) >= 0.9 * limit  # and the limit is reached: the squares demand twice it
    # far below the limit the element is a small series resistance: with a limit 100 times the peak,
    # the charge follows the plain circuit's to 1e-3 of its range
    far = {t.parameter: 0.01 * t.amplitude / i_peak}
    loose = _run(Discovered([t], far).augment(s, t.state, None).system, far, {"U": step})
    assert np.max(np.abs(loose["C.Q"] - plain["C.Q"])) <= 1e-3 * np.ptp(plain["C.Q"])


def test_refine_mode_finds_the_peak_of_a_share_between_grid_points():
    s = mass_spring_damper()
    t = retuned(_term(s, "mode"), 10.0)
    # a share peaked at 13 Hz in log f (the screen's shape near a mode's resonance)
    best, g = refine_mode(t, lambda c: math.exp(-(math.log(c.c / 13.0) / 0.3) ** 2))
    assert best.c == pytest.approx(13.0, rel=0.05) and g >= 0.99
    assert best.parameter != t.parameter and best.label.endswith("Hz")


@pytest.mark.parametrize("kind,system", [("mode", mass_spring_damper), ("drift", mass_spring_damper), ("drift", rc_circuit),
                                         ("limit", rc_circuit)])
def test_the_emitted_source_builds_the_same_model(kind, system, tmp_path):
    s = system()
    for t in [x for x in added_terms(s, _scales(s)) if x.kind == kind][:3]:
        values = {n: p.value for n, p in zip(t.parameters, t.params({t.parameter: 0.3}), strict=True)}
        d = NS(scored=NS(values=values), base=NS(system=s), terms=(t,), values=values)
        path = tmp_path / f"emitted_{kind}_{t.parameter.split('.')[-1]}.py"
        path.write_text(source(d, "A test correction."))
        spec = importlib.util.spec_from_file_location(path.stem, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        cls = next(v for k, v in vars(mod).items() if k.startswith("Discovered") and isinstance(v, type))
        aug = cls().augment(s, cls().attach_points(s)[0], None)
        mine = Discovered([t], values).augment(s, t.state, None)
        assert aug.free == mine.free and aug.x0 == mine.x0 and aug.system.state_names == mine.system.state_names
        u = {"F": _force} if "F" in s.input_names else {"U": lambda tt: 3.0 * np.sin(2 * np.pi * tt)}
        a, b = _run(aug.system, values, u), _run(mine.system, values, u)
        for ch in s.measured_names:  # the same equations: agreement to the integrator's tolerance
            assert np.max(np.abs(a[ch] - b[ch])) <= 1e-8 * (np.max(np.abs(b[ch])) or 1.0), (t.label, ch)


def test_families_are_named_in_words():
    s = mass_spring_damper()
    for t in added_terms(s, _scales(s)):
        assert t.kind in KINDS
        words = t.words(s, 1.0, {n: 0.2 for n in t.parameters})
        assert words and "{" not in words
    t = retuned(_term(s, "mode"), 12.0)
    assert "mode at 12 Hz" in t.words(s, 1.0, {t.parameter: 0.25, t.parameters[1]: 12.0, t.parameters[2]: 0.05})
