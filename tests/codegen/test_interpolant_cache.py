"""The process-wide cache of sampled inputs' interpolants: a simulation through a cached interpolant equals
one that builds its own, and the cache stays bounded."""

from __future__ import annotations

import sys

import numpy as np

import codegen._interpolants  # noqa: F401
from codegen._interpolants import _digest, _interpolant
from codegen.simulator import Simulator
from systems.examples import rc_circuit

SIM = sys.modules["codegen._interpolants"]
SIMULATOR = sys.modules["codegen.simulator"]


def _forget():
    """No interpolant kept, and no integrator either (simulators share theirs: ``SHARED_INTEGRATORS``), so
    that the next run builds its interpolants."""
    SIM._INTERPOLANTS.clear()
    SIMULATOR._SHARED.clear()


def test_cached_interpolant_gives_the_same_run_and_the_cache_is_bounded(monkeypatch):
    t = np.linspace(0.0, 0.02, 2001)
    u = np.sin(2 * np.pi * 150 * t) + 0.2 * np.sin(2 * np.pi * 900 * t)  # smooth: a B-spline in windows
    _forget()
    first = Simulator(rc_circuit(), energy=False).run(t, u={"U": u})["v_C"]
    assert SIM._INTERPOLANTS  # the run's interpolants were kept
    again = Simulator(rc_circuit(R=1e3), energy=False).run(t, u={"U": u})  # another simulator, same samples
    fresh_cache = dict(SIM._INTERPOLANTS)
    _forget()
    rebuilt = Simulator(rc_circuit(R=1e3), energy=False).run(t, u={"U": u})
    # the same interpolant, whether cached or built anew: identical runs (bitwise)
    assert np.array_equal(np.asarray(again["v_C"]), np.asarray(rebuilt["v_C"]))
    assert set(fresh_cache) == set(SIM._INTERPOLANTS)
    assert np.all(np.isfinite(first))
    # other samples while the cache holds the first ones: their own interpolant, not a cached one
    other = np.cos(2 * np.pi * 120 * t)
    cached = Simulator(rc_circuit(), energy=False).run(t, u={"U": other})["v_C"]
    _forget()
    alone = Simulator(rc_circuit(), energy=False).run(t, u={"U": other})["v_C"]
    assert np.array_equal(np.asarray(cached), np.asarray(alone))
    assert not np.allclose(np.asarray(cached), np.asarray(first))
    monkeypatch.setattr(SIM, "_INTERPOLANTS_KEPT", 3)
    for k in range(5):
        v = np.full(8, float(k))
        _interpolant(np.arange(8.0), v, "linear", _digest((np.arange(8.0), v)))
    assert len(SIM._INTERPOLANTS) == 3
