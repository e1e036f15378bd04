"""IDA-PBC: interconnection and damping assignment passivity-based control of a PHSystem.

``ctrl = idapbc.design(sys, target={"tip": 0.03})`` assigns the equilibrium at
which the target holds, chooses the desired structure ``J_d = J + J_a``,
``R_d = R + R_a`` and energy ``H_d = H + H_a``, solves the matching equations
(Ortega, van der Schaft, Maschke, Escobar, Automatica 2002)::

    g_perp(x) [ (J_d - R_d) dH_d/dx - (J - R) dH/dx ] = 0

and returns the control law ``u = g^+ [(J_d - R_d) dH_d/dx - (J - R) dH/dx]`` as a
CasADi function (exportable to C), optionally with integral action, together
with its certificates (:meth:`Controller.certify`) and closed-loop simulation
with plant/controller mismatch (:meth:`Controller.simulate`).

Steps
-----
1. *Equilibrium assignment* (:mod:`codegen.idapbc.target`): the state ``x*``
   and constant input ``u*`` at rest with the targets met, on the leaf of the
   conserved quantities through ``x0``, or an :class:`~phs.errors.EquilibriumError`
   saying why none exists (an input beyond its declared range, the validity
   domain, a fold of the branch).
2. *Structure and matching* (:mod:`codegen.idapbc.matching`): ``"ansatz"``
   (polynomial basis reduced to linear equations) for inputs acting on
   momenta; ``"electromechanical"`` when the inputs reach only storages with
   quadratic energy (charges): the actuated efforts are held where ``u*`` would
   hold them for every configuration, and a momentum-charge coupling in ``J_d``
   and ``R_d`` matches the mechanical rows when that depends on the
   configuration.  Damping injection ``R_a += r g g^T`` is always matched.
3. *Integral action* (optional): ``"passive"`` integrates the passive output
   ``y_d = g^T dH_d/dx`` (``u -= K_i xi``; the closed loop stays port-Hamiltonian
   with ``H_d + xi^T K_i xi / 2``; rejects disturbances entering through the
   input, such as the retained charge of a neglected drift branch);
   ``"output"`` integrates the target error (``u += K_i xi``; removes any
   steady-state error, including unmatched parameter mismatch, certified by
   its linearisation).

Modules
-------
Each imports only the ones listed before it: :mod:`~codegen.idapbc.model` (design
model, numeric functions, names), :mod:`~codegen.idapbc.leaf` (the leaf of the
conserved quantities), :mod:`~codegen.idapbc.target` (equilibrium assignment),
:mod:`~codegen.idapbc.matching` (the two constructions, ``pdsolve``),
:mod:`~codegen.idapbc.shaping` (which construction, damping injection),
:mod:`~codegen.idapbc.law` (the law in CasADi), :mod:`~codegen.idapbc.linear`
(linearisation on the leaf), :mod:`~codegen.idapbc.closed_loop` (simulation),
:mod:`~codegen.idapbc.certificates`, :mod:`~codegen.idapbc.export` (C export) and
:mod:`~codegen.idapbc.controller` (:class:`Controller` and :func:`design`, whose
methods hand the controller to the modules below).

Storages can be left out of the design (``neglect=["seg*.Q1"]``: the curling
HASEL's charge-retention capacitor shorted); the controller then ignores them
and the plant keeps them.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> ctrl = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
>>> float(ctrl.u_star[0]), [round(float(v), 6) for v in ctrl.law([0.0, 0.5])]   # at rest at x*: u = u* = k q*
(2.0, [2.0])
"""

from __future__ import annotations

from codegen.idapbc.certificates import Certificate, CertificateReport, certify
from codegen.idapbc.closed_loop import ClosedLoopResult, simulate_closed_loop, start_state
from codegen.idapbc.controller import Controller, design
from codegen.idapbc.export import export_c
from codegen.idapbc.leaf import Leaf
from codegen.idapbc.linear import closed_loop_modes, integral_gain, leaf_hessian, static_gain
from codegen.idapbc.matching import (
    Structure,
    actuated_split,
    ansatz,
    electromechanical,
    electromechanical_applies,
    quadratic_basis,
)
from codegen.idapbc.model import Numeric, input_vector, match_names, neglect_states, state_vector
from codegen.idapbc.target import Assignment, Target, assign, resolve_targets

__all__ = [
    "design", "Controller",
    "Numeric", "input_vector", "match_names", "neglect_states", "state_vector",
    "Leaf",
    "Target", "Assignment", "assign", "resolve_targets",
    "Structure", "actuated_split", "ansatz", "electromechanical", "electromechanical_applies", "quadratic_basis",
    "closed_loop_modes", "static_gain", "leaf_hessian", "integral_gain",
    "ClosedLoopResult", "simulate_closed_loop", "start_state",
    "Certificate", "CertificateReport", "certify",
    "export_c",
]

_state_vector = state_vector  # the earlier, private name of state_vector
