"""The run function of one input shape: a simulator's integrator calls chained into one CasADi function.

For an input specification on a time grid, :func:`plan_shape` plans the integrator calls of
:meth:`codegen.simulator.Simulator.run` (restarts at every breakpoint, runs of equal spacing, step
windows of sampled inputs) and collects the per-run constants: segment starts and steps, input
constants.  :func:`run_function` chains those calls into ``(z0, p, c) -> (Z, [Q], [Z_off])``, so runs
whose inputs differ only in their constants share one function, mapped over a batch in threads.
"""

from __future__ import annotations

import dataclasses
import hashlib

import casadi as ca
import numpy as np

from codegen._inputs import input_signals, run_sampled
from codegen._output import check_covered, energy_columns
from codegen._plan import plan_for


@dataclasses.dataclass
class Step:
    """One integrator call of a run: ``n`` output steps, which of them are grid points."""

    F: ca.Function
    n_c: int  # entries of the constant vector c used by this call
    on: np.ndarray  # bool (n,): output step lands on the grid
    j: np.ndarray  # grid indices of the steps on the grid


@dataclasses.dataclass
class Shape:
    """An input specification evaluated on the grid: the integrator calls and the per-run constants."""

    key: str
    steps: list
    c: np.ndarray  # constants of every call, concatenated
    U: np.ndarray  # (nt, nu) inputs as stored in results (right-continuous at breakpoints)
    U_check: np.ndarray  # (nt, nu) inputs with which the simulator checks the validity domain
    t_off: np.ndarray  # output times of the integrator that are not grid points (segment ends)
    U_off: np.ndarray


def plan_shape(sim, t: np.ndarray, u) -> Shape:
    """Plan the integrator calls of :meth:`Simulator.run` of ``sim`` for the input ``u`` on the grid ``t``.

    Raises
    ------
    SimulationError
        When the planned output steps do not cover the grid once each.

    Examples
    --------
    >>> from codegen.simulator import Simulator
    >>> from phs.signals import step
    >>> from systems.examples import rc_circuit
    >>> shape = plan_shape(Simulator(rc_circuit()), np.linspace(0.0, 1e-3, 11), {"U": step(1.0, at=2.5e-4)})
    >>> [st.on.tolist() for st in shape.steps]   # restarted at the step, between grid points 2 and 3
    [[True, True], [False], [True], [True, True, True, True, True, True, True]]
    >>> shape.t_off.tolist()
    [0.00025]
    """
    plan = plan_for(t, input_signals(sim.system, u, t))  # the simulator's own plan, time counted from t[0]
    nt, nu = len(t), len(plan.sigs)
    U = plan.U.copy()
    U_check = np.zeros((nt, nu))  # the initial state is checked with zero input, as the simulator does
    runs, steps, cs, t_off, u_off, key = [], [], [], [], [], []
    for r in plan.runs:
        # without the domain's gate: a run of a batch that leaves the domain integrates on and is failed by the
        # check of its grid points (BatchSimulator._violations); gated, its integrator failure failed the whole
        # map call, which was bisected and every failed run simulated again alone (a design grid of the MSD HASEL
        # with 51 of 81 runs leaving the domain: 8 s became 105 s).  Inside the domain both are the same bit for bit.
        F, layout = sim._integrator(r.n, plan.slots, run_sampled(plan.sampled, r.choice, r), r.max_step, gate=False)
        c = sim._pvec(np.zeros(0), r.start, r.step, layout, r.choice)
        r.store(U_check, r.u)
        t_off.extend(r.times[~r.on] + plan.origin)
        u_off.extend(r.u[~r.on])
        runs.append(r)
        steps.append(Step(F, len(c), r.on, r.j[r.on]))
        cs.append(c)
        key.append((id(F), len(c), r.on.tobytes(), r.j[r.on].tobytes()))
    check_covered(runs, nt, "batch evaluation")
    return Shape(key=hashlib.sha1(repr(key).encode()).hexdigest(), steps=steps,
                 c=np.concatenate(cs) if cs else np.zeros(0), U=U, U_check=U_check,
                 t_off=np.asarray(t_off, dtype=float), U_off=np.asarray(u_off, dtype=float).reshape(-1, nu))


def run_function(sim, shape: Shape, name: str) -> ca.Function:
    """Chain the integrator calls of ``shape`` into one function ``(z0, p, c) -> (Z, [Q], [Z_off])``."""
    nx, npar = len(sim.system.states), len(sim.system.params)
    nq = len(energy_columns(sim.system)) if sim.energy else 0
    z0 = ca.MX.sym("z0", nx)
    p = ca.MX.sym("p", npar)
    c = ca.MX.sym("c", len(shape.c))
    z = z0
    grid, qgrid, off = [z0], [ca.MX.zeros(nq, 1)], []
    qacc = ca.MX.zeros(nq, 1)
    k = 0
    for st in shape.steps:
        out = st.F(x0=z, p=ca.vertcat(p, c[k:k + st.n_c]))
        k += st.n_c
        xf = out["xf"]
        on = [int(i) for i in np.nonzero(st.on)[0]]
        offi = [int(i) for i in np.nonzero(~st.on)[0]]
        grid.append(xf if len(on) == len(st.on) else xf[:, on])
        if offi:
            off.append(xf[:, offi])
        if nq:
            qf = out["qf"]
            qgrid.append(ca.repmat(qacc, 1, len(on)) + (qf if len(on) == len(st.on) else qf[:, on]))
            qacc = qacc + qf[:, -1]
        z = xf[:, -1]
    outs, names = [ca.horzcat(*grid)], ["Z"]
    if nq:
        outs.append(ca.horzcat(*qgrid))
        names.append("Q")
    if off:
        outs.append(ca.horzcat(*off))
        names.append("Z_off")
    return ca.Function(name, [z0, p, c], outs, ["z0", "p", "c"], names)
