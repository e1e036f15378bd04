"""Batched simulation (codegen.batch) against the simulator it batches.

A run of a batch chains the simulator's own integrators, so its trajectory,
inputs, energy accounts and derived signals must equal those of
``Simulator.run`` with the same arguments *bitwise* (same arithmetic, in any
number of threads), and a failed run must carry the very error
``Simulator.run`` raises for it.  Pickling ships the generated functions in
CasADi's serialization: a process that unpickles the batch must not translate
the model again.
"""

from __future__ import annotations

import pickle
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from codegen import Simulator, generate, simulate
from codegen.batch import BatchSimulator, default_threads, deserialize_functions, serialize_functions
from phs import DomainError, InputDataError, ParameterError, SimulationError
from phs.signals import Sampled, sine, square, step

FAST = settings(max_examples=12, deadline=None, database=None, derandomize=True)


def _same(a, b, what):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, f"{what}: shapes {a.shape} vs {b.shape}"
    assert np.array_equal(a, b), f"{what}: max difference {np.max(np.abs(a - b)):.3g}"


def _assert_run_equals(batch_run, ref, energy=True):
    _same(batch_run.x, ref.x, "states")
    _same(batch_run.u, ref.u, "inputs")
    _same(batch_run.p, ref.p, "parameters")
    for name in ref.system.measured_names:
        _same(batch_run[name], ref[name], name)
    _same(batch_run.supplied, ref.supplied, "supplied power")
    _same(batch_run.H, ref.H, "H")
    if energy:
        assert set(batch_run.quadratures) == set(ref.quadratures)
        for k in ref.quadratures:
            _same(batch_run.quadratures[k], ref.quadratures[k], k)


@pytest.mark.parametrize("threads", [1, 2])
def test_runs_equal_simulator_bitwise_with_restarts_and_off_grid_edges(electromechanical, threads):
    """Square-wave edges between grid points (restarts, integrator outputs off the grid), energy accounts."""
    s = electromechanical
    t = np.linspace(0.0, 0.05, 101)  # edges every 1/60 s fall between the 0.5 ms grid points
    u = {"U": square(2.0, 30.0), "F": sine(0.2, 15.0)}
    params = [{"k.K": k, "R.R": r} for k, r in [(20.0, 1e3), (15.0, 2e3), (25.0, 500.0), (18.0, 1.5e3)]]
    batch = BatchSimulator(s, t, rtol=1e-9, threads=threads)
    res = batch.run(params, u=u, signals=("measured", "power", "hamiltonian"))
    assert res.ok.all(), res.errors
    assert res.stats["shapes"] == 1 and res.x.shape == (4, len(t), len(s.states))
    sim = Simulator(s, rtol=1e-9)
    for k, p in enumerate(params):
        _assert_run_equals(res[k], sim.run(t, u=u, params=p))


def test_thread_counts_and_pickled_copies_agree_bitwise(msd):
    t = np.linspace(0.0, 2.0, 201)
    params = [{"k.K": 1.0 + 0.5 * k, "b.b": 0.1 + 0.05 * k} for k in range(9)]
    u = {"F": square(1.0, 2.0, offset=0.5)}
    one = BatchSimulator(msd, t, threads=1).run(params, u=u, signals=("measured", "power"))
    two = BatchSimulator(msd, t, threads=2).run(params, u=u, signals=("measured", "power"))
    copy = pickle.loads(pickle.dumps(BatchSimulator(msd, t, threads=2))).run(params, u=u, signals=("measured",))
    for other in (two, copy):
        _same(one.x, other.x, "states")
        _same(one.quadratures, other.quadratures, "quadratures")
        _same(one.signals["measured"], other.signals["measured"], "measured")


def test_per_run_inputs_of_one_shape_share_the_run_function(rc):
    """Steps of different amplitudes and square waves of different levels: one shape, constants per run."""
    t = np.linspace(0.0, 4e-3, 81)
    inputs = [{"U": step(a, 1e-3)} for a in (0.5, 1.0, 2.0)]
    batch = BatchSimulator(rc, t, threads=2)
    res = batch.run([{}] * 3, u=inputs)
    assert res.stats["shapes"] == 1
    sim = Simulator(rc)
    for k, u in enumerate(inputs):
        _assert_run_equals(res[k], sim.run(t, u=u))
    # final capacitor voltages scale with the amplitude (linear circuit), to the integrator's accuracy:
    # rtol 1e-8 per step, ~1e-7 over the run; 1e-6 still catches constants of another run (factor 2)
    v = [res[k]["v_C"][-1] for k in range(3)]
    assert v[1] == pytest.approx(2 * v[0], rel=1e-6) and v[2] == pytest.approx(4 * v[0], rel=1e-6)


def test_sampled_inputs_and_initial_states_per_run(msd):
    t = np.linspace(0.0, 3.0, 151)
    force = Sampled(tuple(t), tuple(np.sin(3 * t)))
    x0s = [{"m.p": 0.1 * k, "k.l": -0.05 * k} for k in range(3)]
    res = BatchSimulator(msd, t, threads=2).run([{}] * 3, u={"F": force}, x0=x0s)
    sim = Simulator(msd)
    for k, x0 in enumerate(x0s):
        _assert_run_equals(res[k], sim.run(t, u={"F": force}, x0=x0))


@FAST
@given(freq=st.floats(0.7, 9.0), n=st.integers(5, 60), t_end=st.floats(0.3, 2.0), duty=st.floats(0.2, 0.8))
def test_any_grid_and_breakpoints_give_the_simulators_trajectory(rlc, freq, n, t_end, duty):
    """Grids and square-wave edges in any relation (on grid points, between them, several per interval)."""
    t = np.linspace(0.0, t_end * 1e-3, n)
    u = {"U": square(1.0, freq * 1e3, duty=duty)}
    res = BatchSimulator(rlc, t, threads=2).run([{}, {"R.R": 20.0}], u=u)
    sim = Simulator(rlc)
    for k, p in enumerate([{}, {"R.R": 20.0}]):
        _assert_run_equals(res[k], sim.run(t, u=u, params=p))


def _rc_square_exact(t, amplitude, freq, tau):
    """Capacitor voltage of an RC low-pass driven by a bipolar square wave from rest, sampled on ``t``."""
    half = 0.5 / freq
    edges = np.arange(half, t[-1] + half, half)
    v, t0, out = 0.0, 0.0, np.empty(len(t))
    level = amplitude
    k = 0
    for i, ti in enumerate(t):
        while k < len(edges) and edges[k] <= ti * (1 + 1e-12):
            v = level + (v - level) * np.exp(-(edges[k] - t0) / tau)
            t0, level, k = edges[k], -level, k + 1
        out[i] = level + (v - level) * np.exp(-(ti - t0) / tau)
    return out


# grids as the command line builds them (np.arange(0, t_end + dt / 2, dt): edges fall on grid points up to
# rounding) and as np.linspace builds them; 200 Hz on these grids puts every edge on a grid point
@pytest.mark.parametrize("freq", [150.0, 200.0, 250.0, 333.0, 1000.0])
@pytest.mark.parametrize("grid", ["arange 1e-5", "arange 2e-5", "arange 1e-4", "linspace 1001"])
def test_square_wave_batches_equal_simulate_with_edges_on_and_between_grid_points(rc, freq, grid):
    """Batch vs ``codegen.simulate`` run by run, bitwise (tolerance zero: the same integrator calls);
    both vs the exact RC response to within 1e-6 V (an amplitude of 1 V, rtol 1e-8 per step)."""
    kind, arg = grid.split()
    t = np.arange(0.0, 0.01 + float(arg) / 2, float(arg)) if kind == "arange" else np.linspace(0.0, 0.01, int(arg))
    u = {"U": square(1.0, freq)}
    params = [{"R.R": r} for r in (500.0, 1000.0, 2000.0)]
    res = BatchSimulator(rc, t, threads=2).run(params, u=u, signals=("measured",))
    assert res.ok.all(), res.errors
    for k, p in enumerate(params):
        ref = simulate(rc, t, u=u, params=p)
        _assert_run_equals(res[k], ref)
        exact = _rc_square_exact(t, 1.0, freq, p["R.R"] * 1e-6)
        np.testing.assert_allclose(res[k]["v_C"], exact, rtol=0, atol=1e-6)


@FAST
@given(freq=st.floats(1.0, 5e3), dt=st.sampled_from([1e-6, 2e-6, 5e-6, 1e-5, 2e-5, 5e-5, 1e-4]),
       t_end=st.sampled_from([1e-3, 3e-3, 1e-2, 0.1]), duty=st.sampled_from([0.5, 0.25, 0.2]))
def test_output_steps_cover_every_grid_point_once(freq, dt, t_end, duty):
    """Planning alone (no integration): whatever the edges' rounding, each grid point is one output step."""
    from codegen._inputs import plan_segments
    from codegen._output import check_covered, output_runs

    t = np.arange(0.0, t_end + dt / 2, dt)
    sigs = [square(1.0, freq, duty=duty)]
    segs, _ = plan_segments(sigs, t)
    U = np.zeros((len(t), 1))
    check_covered(list(output_runs(t, sigs, segs, lambda c, tt, ms: np.zeros((len(tt), 1)), U)), len(t), "plan")


def test_failed_runs_carry_the_simulators_errors_and_do_not_affect_others(electromechanical, msd):
    """Domain exits, an integrator failure, invalid parameters: each run fails alone, with its error."""
    s = electromechanical
    t = np.linspace(0.0, 0.05, 51)
    u = {"U": 1.0, "F": step(8.0, 0.01)}  # a large force pulls the arm past the arcsin domain
    params = [{}, {"L": 0.05}, {"k.K": 400.0}, {"L": 0.02}, {}]
    res = BatchSimulator(s, t, threads=2).run(params, u=u)
    sim = Simulator(s)
    failed = 0
    for k, p in enumerate(params):
        try:
            ref = sim.run(t, u=u, params=p)
        except DomainError as exc:
            failed += 1
            assert isinstance(res.errors[k], DomainError) and str(res.errors[k]) == str(exc)
            assert np.all(np.isnan(res.x[k]))
            with pytest.raises(DomainError):
                res[k]
        else:
            assert res.errors[k] is None
            _assert_run_equals(res[k], ref)
    assert 0 < failed < len(params), "the case must mix failing and successful runs"

    # a massless body (refused: the mass is declared positive) amid good runs; a non-finite parameter
    t2 = np.linspace(0.0, 1.0, 21)
    res2 = BatchSimulator(msd, t2, threads=2).run([{}, {"m.m": 0.0}, {"k.K": float("nan")}, {"k.K": 2.0}],
                                                  u={"F": 1.0})
    assert res2.ok.tolist() == [True, False, False, True]
    with pytest.raises(ParameterError) as ref_err:
        Simulator(msd).run(t2, u={"F": 1.0}, params={"m.m": 0.0})
    assert str(res2.errors[1]) == str(ref_err.value) and "m.m" in str(ref_err.value)
    assert isinstance(res2.errors[2], ParameterError) and "k.K" in str(res2.errors[2])
    _assert_run_equals(res2[3], Simulator(msd).run(t2, u={"F": 1.0}, params={"k.K": 2.0}))


def test_generated_functions_survive_serialization(electromechanical):
    s = electromechanical
    f = generate(s)
    g = deserialize_functions(s, serialize_functions(f), install=False)
    rng = np.random.default_rng(0)
    x = np.array([np.mean(st_.range) for st_ in s.states]) + 0.01 * rng.standard_normal(len(s.states))
    u, p = np.array([0.5, 0.1]), s.param_vector()
    for a, b in zip(f.all(), g.all()):
        for ra, rb in zip(a(x, u, p) if a.n_out() > 1 else [a(x, u, p)], b(x, u, p) if b.n_out() > 1 else [b(x, u, p)]):
            _same(np.asarray(ra), np.asarray(rb), a.name())
    with pytest.raises(SimulationError, match="CasADi"):
        deserialize_functions(s, {**serialize_functions(f), "casadi": "0.0"})


UNPICKLE_WITHOUT_TRANSLATION = """
import pickle, sys
import codegen.functions as fn

class Refuse:
    def __init__(self, *args, **kwargs):
        raise AssertionError("the model was translated again")

fn.Translator = Refuse  # generate() would now fail: the functions must come from the pickle
batch = pickle.loads(sys.stdin.buffer.read())
res = batch.run([{"k.K": 1.0}, {"k.K": 9.0}], u={"F": 1.0}, signals=("measured",))
assert res.ok.all(), res.errors
sys.stdout.buffer.write(pickle.dumps((res.x, res.signals["measured"])))
"""


def test_unpickled_batch_runs_without_translating_the_model(msd):
    """What a Dask worker does: load the serialized functions, rebuild integrators only."""
    t = np.linspace(0.0, 1.0, 11)
    batch = BatchSimulator(msd, t, threads=1)
    proc = subprocess.run([sys.executable, "-c", UNPICKLE_WITHOUT_TRANSLATION], input=pickle.dumps(batch),
                          capture_output=True, timeout=120)
    assert proc.returncode == 0, proc.stderr.decode()[-2000:]
    x, measured = pickle.loads(proc.stdout)
    here = batch.run([{"k.K": 1.0}, {"k.K": 9.0}], u={"F": 1.0}, signals=("measured",))
    _same(x, here.x, "states in the other process")
    _same(measured, here.signals["measured"], "measured in the other process")


@pytest.mark.parametrize(("call", "error", "match"), [
    (lambda b: b.run([{}, {}], u=[{"U": 1.0}]), InputDataError, "different lengths"),
    (lambda b: b.run([{}], signals=("bogus",)), InputDataError, "bogus"),
    (lambda b: BatchSimulator(b.system, [0.0, 1.0, 0.5]), InputDataError, "strictly increasing at index 2"),
    (lambda b: BatchSimulator(b.system, [0.0]), InputDataError, "at least 2 points"),
    (lambda b: BatchSimulator(b.system, [0.0, 1.0], threads=0), InputDataError, "threads"),
])
def test_invalid_arguments_name_the_culprit(rc, call, error, match):
    with pytest.raises(error, match=match):
        call(BatchSimulator(rc, [0.0, 1e-3]))


def test_unknown_parameter_fails_only_that_run(rc):
    res = BatchSimulator(rc, [0.0, 1e-3]).run([{"R.R": 2e3}, {"bogus": 1.0}], u={"U": 1.0})
    assert res.ok.tolist() == [True, False]
    assert isinstance(res.errors[1], ParameterError) and "bogus" in str(res.errors[1])


def test_default_threads_and_repr(rc):
    b = BatchSimulator(rc, [0.0, 1e-3])
    assert b.threads == default_threads() >= 1
    assert "rc" in repr(b) and "BatchResult" in repr(b.run([{}]))


def test_static_network_runs_through_the_simulator():
    """A network without storage: nothing to integrate; each run is the simulator's static evaluation."""
    from components import Resistor, VoltageSource
    from phs import interconnect, series

    divider = interconnect("divider", [VoltageSource("U"), Resistor("R1", R=1.0), Resistor("R2", R=3.0)],
                           [series("U", "R1", "R2")])
    t = np.linspace(0.0, 1.0, 11)
    res = BatchSimulator(divider, t).run([{"R1.R": 1.0}, {"R1.R": 7.0}], u={"U": 2.0})
    assert res.ok.all() and res.x.shape == (2, 11, 0)
    for k, r1 in enumerate((1.0, 7.0)):
        ref = Simulator(divider).run(t, u={"U": 2.0}, params={"R1.R": r1})
        _assert_run_equals(res[k], ref)
        assert res[k].quadratures["E_supplied"][-1] == pytest.approx(4.0 / (r1 + 3.0))  # U^2 / R over 1 s


def test_single_measured_outputs_evaluated_for_the_batch(electromechanical):
    """Only the measured outputs asked for are evaluated for the chunk; the others stay available on demand."""
    s = electromechanical
    t = np.linspace(0.0, 0.02, 41)
    u = {"U": step(1.0, 0.005), "F": 0.5}
    res = BatchSimulator(s, t).run([{}, {"k.K": 15.0}], u=u, signals=("angle",))
    assert set(res.signals) == {"angle"} and res.signals["angle"].shape == (2, len(t))
    sim = Simulator(s)
    for k, p in enumerate([{}, {"k.K": 15.0}]):
        ref = sim.run(t, u=u, params=p)
        run = res[k]
        assert np.shares_memory(run["angle"], res.signals["angle"])  # the batch's evaluation, not a new one
        _assert_run_equals(run, ref)  # every measured output, also those computed on demand


def test_concurrent_batches_from_python_threads(msd):
    """Threads of one process (a Dask worker with several threads) share a batch simulator: runs take turns
    (building CasADi functions is not thread-safe; each run still uses its own CasADi threads) and the console
    survives."""
    import threading

    t = np.linspace(0.0, 1.0, 51)
    batch = BatchSimulator(msd, t, threads=1)
    params = [[{"k.K": 1.0 + k + j} for j in range(3)] + [{"m.m": 0.0}] for k in range(4)]
    out = [None] * 4
    stdout, stderr = sys.stdout, sys.stderr

    def work(k):
        out[k] = batch.run(params[k], u={"F": square(1.0, 3.0)})

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert sys.stdout is stdout and sys.stderr is stderr
    sim = Simulator(msd)
    for k in range(4):
        assert out[k].ok.tolist() == [True, True, True, False]
        for j in range(3):
            _same(out[k][j].x, sim.run(t, u={"F": square(1.0, 3.0)}, params=params[k][j]).x, f"thread {k} run {j}")
