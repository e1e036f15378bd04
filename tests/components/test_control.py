"""Controllers as components: closed-loop responses against the analytic ones, the measured
controller force against an independent computation, and the energy balance along simulations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal as sps

from codegen import simulator
from components import Damper, LinearSpring, Mass, PositionLoop, VelocityLoop
from phs import interconnect, series
from phs.errors import ModelError

M, KP, KD = 2.0, 200.0, 8.0  # omega_n = 10 rad/s, zeta = 0.2
# The simulated response is accurate to the integrator's tolerance (~1e-8 relative), the overshoot
# and period are read from a 0.2 ms grid (peak by parabolic interpolation, period from linearly
# interpolated crossings): 0.5 % covers the reading, far below what a wrong gain would change.
RESPONSE_TOL = 5e-3


def _servo(**kw):
    return interconnect("servo", [Mass("m", m=M), PositionLoop("pd", K_p=KP, K_d=KD, **kw)], [series("m", "pd")])


def _crossings(t, e):
    i = np.nonzero(np.sign(e[:-1]) != np.sign(e[1:]))[0]
    return t[i] - e[i] * (t[i + 1] - t[i]) / (e[i + 1] - e[i])


def test_pd_step_response_is_the_second_order_one():
    s = _servo()
    t = np.arange(0.0, 3.0, 2e-4)
    r = 0.05
    res = simulator(s).run(t, u={"r": r})
    x = res["pd.x"]
    wn, zeta = math.sqrt(KP / M), KD / (2 * math.sqrt(KP * M))
    assert (wn, zeta) == pytest.approx((10.0, 0.2))
    k = int(np.argmax(x))
    y0, y1, y2 = x[k - 1:k + 2]
    peak = y1 - (y2 - y0) ** 2 / (8 * (y2 - 2 * y1 + y0))
    overshoot = peak / r - 1
    assert overshoot == pytest.approx(math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2)), rel=RESPONSE_TOL)
    zc = _crossings(t, x - r)
    period = 2 * float(np.mean(np.diff(zc[:6])))
    assert period == pytest.approx(2 * math.pi / (wn * math.sqrt(1 - zeta**2)), rel=RESPONSE_TOL)
    # settles on the reference inside the decay envelope
    assert abs(x[-1] - r) <= r * math.exp(-zeta * wn * t[-1]) / math.sqrt(1 - zeta**2)


def _reference(t):
    return 0.02 * (t >= 0.2) - 0.03 * (t >= 1.1) + 0.01 * np.sin(2 * np.pi * 1.5 * t)


@pytest.mark.parametrize("tau", [None, 0.02])
def test_measured_force_is_the_control_law(tau):
    """pd.F against K_p (r_f - x) + K_d (r_f' - v) computed from the simulated states; the filtered
    reference against scipy's simulation of the filter 1/(tau s + 1)."""
    s = interconnect("servo", [Mass("m", m=M), LinearSpring("k", K=30.0), Damper("b", b=0.5),
                               PositionLoop("pd", K_p=KP, K_d=KD, tau=tau, position="k.l")], [series("m", "k", "b", "pd")])
    t = np.arange(0.0, 2.0, 1e-3)
    r = _reference(t)
    res = simulator(s).run(t, u={"r": r})
    x, v = res["k.l"], res["m.p"] / M
    if tau is None:
        expected = KP * (r - x) - KD * v
    else:
        rf = res["pd.r_f"]
        _, rf_ref, _ = sps.lsim(([1.0], [tau, 1.0]), r, t)
        assert np.max(np.abs(rf - rf_ref)) < 1e-6
        expected = KP * (rf - x) + KD * ((r - rf) / tau - v)
    F = res["pd.F"]
    assert np.max(np.abs(F - expected)) <= 1e-9 * np.max(np.abs(expected))
    # the plant's momentum rate is the controller force plus the plant's own forces
    dp = np.gradient(res["m.p"], t)
    plant = -30.0 * x - 0.5 * v
    assert np.median(np.abs(dp - (F + plant))) < 1e-2 * np.max(np.abs(F))


@pytest.mark.parametrize("kw", [{}, {"tau": 0.02}], ids=["pd", "pd_filtered"])
def test_energy_balance_along_a_simulation(kw):
    """H(T) - H(0) = integral of y^T u - grad H^T R grad H (trapezoid on a 0.1 ms grid)."""
    s = _servo(**kw)
    t = np.arange(0.0, 1.5, 1e-4)
    res = simulator(s).run(t, u={"r": 0.03 * np.sin(2 * np.pi * 2.0 * t) + 0.02 * (t > 0.5)})
    net = res["supplied"] - res["dissipated"]
    gained = res["H"] - res["H"][0]
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (net[1:] + net[:-1]) * np.diff(t))])
    exchanged = np.concatenate([[0.0], np.cumsum(np.abs(net[1:]) * np.diff(t))])
    assert np.max(np.abs(gained - integral)) <= 1e-3 * exchanged[-1]
    assert np.all(res["dissipated"] >= -1e-12)


def test_velocity_loop_reaches_the_damped_reference_speed():
    b, kv, rv = 0.5, 4.0, 0.3
    s = interconnect("cruise", [Mass("m", m=M), Damper("b", b=b), VelocityLoop("vc", K_v=kv)], [series("m", "b", "vc")])
    t = np.linspace(0.0, 3.0, 3001)
    res = simulator(s).run(t, u={"r_v": rv})
    v = res["m.p"] / M
    expected = kv * rv / (kv + b) * (1 - np.exp(-(kv + b) / M * t))
    assert np.max(np.abs(v - expected)) < 1e-6 * rv
    assert np.max(np.abs(res["vc.F"] - kv * (rv - v))) < 1e-9 * kv * rv


@pytest.mark.parametrize("kw, culprit", [({"K_p": -1.0}, "K_p"), ({"K_d": -0.1}, "K_d"),
                                          ({"K_d": 0.0, "tau": 0.01}, "K_d"), ({"tau": 0.0, "K_d": 1.0}, "tau")])
def test_invalid_gains_are_refused(kw, culprit):
    with pytest.raises(ModelError, match=culprit):
        PositionLoop("pd", **kw)


def test_proportional_control_alone_passes_the_structural_checks():
    # K_d = 0 (P control) is allowed; its parameter's range stays nonnegative, so the sampled checks pass
    # (with the default range of a zero value, (-1, 1), they sampled a negative damping and failed)
    pd = PositionLoop("pd", K_p=400.0, K_d=0.0, position="k.l", effort="u_c")
    s = interconnect("servo", [Mass("m", m=0.5), LinearSpring("k", K=40.0), Damper("b", b=1.0), pd], [series("m", "k", "b", "pd")])
    assert s.check().ok
    assert dict((p.name, p.range) for p in s.params)["pd.K_d"] == (0.0, 1.0)


@pytest.mark.parametrize("tau", [None, 0.02])
def test_feedforward_pushes_the_body_and_is_recorded_with_the_command(tau):
    """A signal added after the control law (``feedforward=``, gain 3 N/V): the same motion as the loop
    beside a separate force source of 3·w, the measured effort is the law plus 3·w, and the energy
    balance holds with the extra port."""
    from components import ForceSource

    t = np.arange(0.0, 1.5, 1e-4)
    r, w = _reference(t), 0.4 * (t > 0.3) - 0.6 * (t > 0.9)
    ff = interconnect("servo", [Mass("m", m=M), PositionLoop("pd", K_p=KP, K_d=KD, tau=tau, feedforward="w",
                                                             feedforward_gain=3.0, feedforward_unit="V")], [series("m", "pd")])
    apart = interconnect("servo", [Mass("m", m=M), PositionLoop("pd", K_p=KP, K_d=KD, tau=tau), ForceSource("f")],
                         [series("m", "pd", "f")])
    a = simulator(ff).run(t, u={"r": r, "w": w})
    b = simulator(apart).run(t, u={"r": r, "f": 3.0 * w})
    assert np.max(np.abs(a["m.p"] - b["m.p"])) <= 1e-6 * np.max(np.abs(b["m.p"]))
    assert np.max(np.abs(a["pd.F"] - (b["pd.F"] + 3.0 * w))) <= 1e-6 * np.max(np.abs(b["pd.F"]))
    net = a["supplied"] - a["dissipated"]
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (net[1:] + net[:-1]) * np.diff(t))])
    exchanged = np.concatenate([[0.0], np.cumsum(np.abs(net[1:]) * np.diff(t))])
    assert np.max(np.abs(a["H"] - a["H"][0] - integral)) <= 1e-3 * exchanged[-1]
    assert ff.check().ok
