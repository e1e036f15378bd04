"""Passivity certificates for nonlinear port-Hamiltonian models.

A system ``x' = (J - R) dH/dx + (G - P) u``, ``y = (G + P)^T dH/dx + (S + N) u``
is passive with storage ``H - min H`` when ``J = -J^T``, ``N = -N^T``, H is
bounded below and the dissipation matrix ``D = [[R, P], [P^T, S]]`` is positive
semidefinite: then ``dH/dt = -z^T D z + y^T u <= y^T u`` with
``z = [dH/dx; u]``.  :func:`certify` checks each of these over a box of states
(and optionally parameters) and reports, for a failure, the point and the
element responsible:

``interconnection``
    J and N skew-symmetric (symbolic; the model is refused at construction
    otherwise, so this records the proof).
``dissipation``
    D ⪰ 0: symbolically where decidable (every principal minor of each block,
    or of each resistive element's form when they sum to D, is a sum of
    products of positive parameters), and numerically over the box: the
    minimum eigenvalue over a dense sample and from several starts of CasADi
    ``nlpsol`` (IPOPT) minimising the Rayleigh quotient ``w^T D(x, p) w /
    w^T w`` jointly over the point and the direction.  The worst point, the
    eigenvector and the resistive element with the most negative share of
    ``w^T D w`` are reported.
``feedthrough``
    For the full form with P, S, N: N skew, S ⪰ 0 and P in the range that
    ``[[R, P], [P^T, S]] ⪰ 0`` requires (``P (I - S S^+) = 0``).
``storage``
    H bounded below on the box: its minimum (dense sample + ``nlpsol``) and argmin.
``trajectory`` (optional)
    The dissipation inequality ``∫ y^T u dt - (H(T) - H(0)) >= 0`` along a
    simulation, with the dissipated energy split per resistive element
    (:func:`dissipation_inequality`).
``local`` (optional)
    Input- and output-strict passivity indices of the linearisation at an
    equilibrium, with conserved directions of J removed (:func:`local_passivity`).

Points outside the model's validity domain (its conditions, e.g. an arcsin
argument above 1) are not part of the box: samples are drawn uniformly from
the valid part (rejection per group of coupled coordinates) and the
optimisations carry the conditions as constraints.

The margin
----------
``margin`` (:attr:`PassivityReport.margin`, :func:`dissipation_margin`) is the
smallest eigenvalue over the box of the state block R of D, made
dimensionless: coordinate ``i`` is divided by ``sqrt(d_i)``, where ``d_i`` is
the root mean square of ``D_ii`` over a fixed 64-point reference sample of the
state box at the system's own parameter values (so overrides and swept
parameters change the margin, the scale does not), and directions in which D
vanishes identically (a source in series with a resistor: the rc circuit's
``z = (1, 1)``) are removed.  A lone resistive element at its declared value
scores 1, half its value 0.5, 0 means a lossless direction somewhere in the
box.  When the full form ``[[R, P], [P^T, S]]`` has a negative eigenvalue
anywhere in the box, the margin is that (scaled, negative) eigenvalue instead,
so its sign is the verdict.  The full form is not used for a positive margin:
the HASEL models' input map ``gamma1 cos(gamma2 theta)`` vanishes at the edge
of their validity domain, where the port's row of D vanishes for every
parameter set.  Coordinates on which D has no entry at all (pure storage) are
not counted: they are lossless by construction.

Modules
-------
:mod:`~codegen.passivity.structural` (interconnection, dissipation, feedthrough),
:mod:`~codegen.passivity.storage` (H bounded below), :mod:`~codegen.passivity.margin`
(:func:`dissipation_margin`), :mod:`~codegen.passivity.energy` (:func:`dissipation_inequality`),
:mod:`~codegen.passivity.local` (:func:`local_passivity`), :mod:`~codegen.passivity.report`
(:class:`PassivityReport`) and :mod:`~codegen.passivity.certify` (:func:`certify`), on the box,
sampling and ``nlpsol`` machinery of the private modules.
"""

from codegen.passivity._box import EIGENVALUE_TOL  # noqa: F401  (re-exported)
from codegen.passivity._equilibrium import EQUILIBRIUM_TOL  # noqa: F401  (re-exported)
from codegen.passivity._figures import plot_box, plot_energy, plot_local  # noqa: F401  (re-exported)
from codegen.passivity._frequency import _hamiltonian_crossings  # noqa: F401  (re-exported)
from codegen.passivity._result import PassivityTest
from codegen.passivity.certify import certify
from codegen.passivity.energy import ENERGY_TOL, dissipation_inequality  # noqa: F401  (ENERGY_TOL re-exported)
from codegen.passivity.local import LocalPassivity, local_passivity
from codegen.passivity.margin import dissipation_margin
from codegen.passivity.report import PassivityReport

__all__ = ["certify", "dissipation_margin", "dissipation_inequality", "local_passivity", "PassivityReport",
           "PassivityTest", "LocalPassivity"]
