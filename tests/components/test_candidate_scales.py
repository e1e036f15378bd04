"""The force a body feels (``Scales.force``), from which friction-like candidates take their start and range.

A position loop's virtual spring to the origin (``½K_p x²``) and its reference force ``K_p r`` are each far
larger than what the body feels, ``K_p (r − x)``: a scale from the spring's coenergy alone started a
friction 3 to 4 decades above the forces in the recording.  The scale is checked against the forces
computed by hand from the simulated states (an independent formula: the closed-loop equations).
"""

from __future__ import annotations

import numpy as np

from codegen import Simulator
from components.candidates import CoulombFriction
from components.candidates.base import Scales
from systems.examples import mass_spring_damper, pd_servo


def _run(system, t, u):
    res = Simulator(system, energy=False).run(t, u={system.input_names[0]: u})
    X = np.asarray(res.x)
    return X, np.asarray(res[system.input_names[0]]).reshape(-1, 1)


def _rms(v):
    return float(np.sqrt(np.mean(np.square(v))))


def test_stiff_loop_scale_is_the_net_force_not_the_virtual_spring():
    m, k, b, K_p, K_d = 0.5, 40.0, 1.0, 1e5, 600.0  # a loop 2500 times stiffer than the plant's spring
    s = pd_servo(m=m, k=k, b=b, K_p=K_p, K_d=K_d, tau=None)
    t = np.arange(0.0, 2.0, 1e-3)
    r = 0.01 * np.clip(np.sin(2 * np.pi * t), -0.7, 0.7)  # moves with flat tops
    X, U = _run(s, t, r)
    sc = Scales.of(s, t, X, U)
    ip, il = s.state_names.index("m.p"), s.state_names.index("k.l")
    x, v = X[:, il], X[:, ip] / m
    # by hand: the spring's and the loop's conservative and source forces on the mass, and its inertia
    f_cons = -k * x + K_p * (U[:, 0] - x)
    pdot = np.gradient(X[:, ip], t)
    idx = np.linspace(0, len(t) - 1, min(len(t), 400)).astype(int)  # the points Scales samples
    expect = max(_rms(f_cons[idx]), _rms(pdot))
    assert abs(sc.force["m.p"] - expect) <= 1e-6 * expect
    # far below the loop's spring force alone, and of the order of what moves and damps the mass
    assert sc.force["m.p"] < 0.05 * K_p * _rms(x)
    assert sc.force["m.p"] > 0.5 * _rms((b + K_d) * v)
    # the friction candidate starts at 2 % of it and its range spans it
    aug = CoulombFriction().augment(s, "m.p", sc)
    (name,) = aug.free
    start = aug.system.with_params({}).params[aug.system.param_names.index(name)].value
    assert abs(start - 0.02 * sc.force["m.p"]) <= 1e-9 * start
    lo, hi = aug.bounds[name]
    assert lo < 1e-3 * sc.force["m.p"] and hi > 5 * sc.force["m.p"]


def test_open_plant_scale_is_drive_minus_spring_or_inertia():
    s = mass_spring_damper()
    k = s.params[s.param_names.index("k.K")].value
    t = np.arange(0.0, 6.0, 1e-3)
    u = np.sign(np.sin(2 * np.pi * 0.5 * t))
    X, U = _run(s, t, u)
    sc = Scales.of(s, t, X, U)
    ip, il = s.state_names.index("m.p"), s.state_names.index("k.l")
    idx = np.linspace(0, len(t) - 1, min(len(t), 400)).astype(int)
    expect = max(_rms((U[:, 0] - k * X[:, il])[idx]), _rms(np.gradient(X[:, ip], t)))
    assert abs(sc.force["m.p"] - expect) <= 1e-6 * expect
    # without a trajectory there is no table, and candidates keep the spring's coenergy
    assert Scales.of(s).force == {}
