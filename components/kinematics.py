"""Kinematic chains: storages whose inertia depends on the configuration.

A planar serial chain of rigid links stores the kinetic energy (eqs. 11-12
of the curling HASEL paper)

    H = 1/2 p^T M(q)^-1 p,   M(q) = sum_i ( m_i J_v^i^T J_v^i + I_i J_w^i^T J_w^i ),

where ``q`` are the relative joint angles (states owned by the joints'
springs), ``p`` the conjugate generalized momenta (states owned by the
chain) and ``J_v^i``, ``J_w^i`` the Jacobians of the velocity of link i's
centre of mass and of its angular velocity with respect to ``q'``.

M(q) is built symbolically, but it is never inverted symbolically: the energy
is the sympy function :class:`InverseQuadraticForm` of the entries of M and
of p.  Its derivatives are the companion functions :class:`LinearSolve`
(``(M^-1 p)_k``) and :class:`InverseEntry` (``(M^-1)_kj``), a family closed
under differentiation, so sympy's chain rule through the entries of M gives
the exact gradient.  Each function evaluates numerically with
``numpy.linalg`` (sympy's ``_imp_`` hook, used by ``lambdify`` and
``evalf``) and translates to CasADi with ``casadi.solve`` (the ``_casadi``
hook of :mod:`codegen.translate`); casadi is imported only when translating.

:class:`KinematicChain` builds M(q) from the links; :class:`ConfigurationInertia`
takes any symmetric M(q), e.g. a closed chain's :func:`reduced_inertia` in
independent coordinates.
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from sympy.core.function import ArgumentIndexError

from components._base import require_positive
from phs.component import Component, Piece
from phs.errors import ModelError
from phs.params import EnergyTerm, Param, check_name, state_symbol
from phs.stored_expressions import register_function

# -- M^-1 without symbolic inversion -----------------------------------------------------------------------


def _upper(n: int) -> list[tuple[int, int]]:
    """Index pairs of the upper triangle of an n x n matrix, row by row."""
    return [(i, j) for i in range(n) for j in range(i, n)]


def _order(count: int, vector: bool) -> int:
    """n such that ``count`` arguments hold the upper triangle of M (and p if ``vector``)."""
    n = 1
    while n * (n + 1) // 2 + (n if vector else 0) < count:
        n += 1
    if n * (n + 1) // 2 + (n if vector else 0) != count:
        raise ModelError(f"{count} arguments do not hold the upper triangle of a square matrix"
                         + (" and a vector" if vector else ""))
    return n


class _InverseFunction(sp.Function):
    """Arguments: ``nindex`` integer indices, the upper triangle of M row by row, then p if ``vector``.

    Subclasses give the exact value (:meth:`_exact`), the numpy value
    (``_imp_``), the value from ``v = M^-1 p`` in CasADi (:meth:`_from_solve`)
    and the derivatives with respect to one entry ``M_ab`` of a non-symmetric
    M (:meth:`_d_entry`) and to ``p_j`` (:meth:`_d_vector`); :meth:`fdiff`
    adds both triangles for an off-diagonal entry.
    """

    nindex = 0
    vector = True

    @classmethod
    def _layout(cls, args) -> tuple[list[int], int, tuple, tuple]:
        """(indices, n, entries of M, entries of p)."""
        n = _order(len(args) - cls.nindex, cls.vector)
        k = cls.nindex + n * (n + 1) // 2
        return [int(i) for i in args[: cls.nindex]], n, args[cls.nindex: k], args[k:]

    @classmethod
    def eval(cls, *args) -> sp.Expr | None:
        n = _order(len(args) - cls.nindex, cls.vector)
        if any(not (sp.sympify(i).is_Integer and 0 <= i < n) for i in args[: cls.nindex]):
            raise ModelError(f"{cls.__name__}: indices {args[: cls.nindex]} are not integers in [0, {n})")
        if all(sp.sympify(a).is_Number for a in args):
            idx, n, m, p = cls._layout(args)
            entry = dict(zip(_upper(n), m, strict=True))
            return cls._exact(idx, sp.Matrix(n, n, lambda i, j: entry[min(i, j), max(i, j)]), sp.Matrix(p))
        return None

    @classmethod
    def _numpy(cls, *args) -> tuple[list[int], np.ndarray, np.ndarray | None]:
        vals = np.broadcast_arrays(*[np.asarray(a, dtype=float) for a in args[cls.nindex:]])
        n = _order(len(vals), cls.vector)
        M = np.empty(vals[0].shape + (n, n))
        for (i, j), v in zip(_upper(n), vals, strict=False):
            M[..., i, j] = M[..., j, i] = v
        p = np.stack(vals[n * (n + 1) // 2:], axis=-1) if cls.vector else None
        return [int(i) for i in args[: cls.nindex]], M, p

    def _casadi(self, *args):
        import casadi as ca

        idx, n, _, _ = self._layout(self.args)
        entries = dict(zip(_upper(n), args[self.nindex:], strict=False))
        M = ca.blockcat([[entries[min(i, j), max(i, j)] for j in range(n)] for i in range(n)])
        p = ca.vertcat(*args[self.nindex + n * (n + 1) // 2:]) if self.vector else ca.SX.eye(n)[:, idx[-1]]
        return self._from_solve(idx, p, ca.solve(M, p))

    def _dimension(self, dims):
        """Dimension from the arguments' dimensions (tuples of exponents), for :mod:`phs.units`."""
        idx, n, _, _ = self._layout(self.args)
        m = dict(zip(_upper(n), dims[self.nindex:], strict=False))
        p = dims[self.nindex + len(m):]
        if not self.vector:  # (M^-1)_kj
            return tuple(-x for x in m[idx[0], idx[1]])
        k = idx[0] if idx else 0  # (M^-1 p)_k, or p_0**2 / M_00 for the quadratic form
        return tuple((1 if idx else 2) * a - b for a, b in zip(p[k], m[k, k], strict=True))

    def fdiff(self, argindex=1):
        idx, n, _, _ = self._layout(self.args)
        t, size = argindex - 1 - self.nindex, n * (n + 1) // 2
        if t < 0:
            raise ArgumentIndexError(self, argindex)
        if t >= size:
            return self._d_vector(idx, t - size)
        a, b = _upper(n)[t]
        return self._d_entry(idx, a, b) + (self._d_entry(idx, b, a) if a != b else 0)

    def _v(self, k):  # (M^-1 p)_k
        _, _, m, p = self._layout(self.args)
        return LinearSolve(k, *m, *p)

    def _w(self, k, j):  # (M^-1)_kj
        _, _, m, _ = self._layout(self.args)
        return InverseEntry(k, j, *m)


@register_function  # saved models may name it (phs.safe_parse)
class InverseQuadraticForm(_InverseFunction):
    """``1/2 p^T M^-1 p`` of a symmetric positive definite M given by its upper triangle.

    Arguments: ``M[0,0], M[0,1], ..., M[0,n-1], M[1,1], ..., M[n-1,n-1], p[0], ..., p[n-1]``.
    Derivatives: ``d/dp_j = (M^-1 p)_j``, ``d/dM_ab = -v_a v_b / 2`` per triangle (``v = M^-1 p``).

    Examples
    --------
    >>> a, b, c, p, q = sp.symbols("a b c p q", real=True)
    >>> InverseQuadraticForm(2, 1, 2, 3, 0)
    3
    >>> sp.diff(InverseQuadraticForm(a, b, c, p, q), p)
    LinearSolve(0, a, b, c, p, q)
    """

    @staticmethod
    def _exact(idx, M, p):
        return (p.T * M.LUsolve(p))[0, 0] / 2

    @staticmethod
    def _imp_(*args):
        _, M, p = InverseQuadraticForm._numpy(*args)
        v = np.linalg.solve(M, p[..., None])[..., 0]
        return 0.5 * np.sum(p * v, axis=-1)[()]

    @staticmethod
    def _from_solve(idx, p, v):
        return 0.5 * (p.T @ v)

    def _d_vector(self, idx, j):
        return self._v(j)

    def _d_entry(self, idx, a, b):
        return -self._v(a) * self._v(b) / 2


@register_function  # saved models may name it (phs.safe_parse)
class LinearSolve(_InverseFunction):
    """Component ``k`` of ``v = M^-1 p``; arguments ``k``, the upper triangle of M, then p.

    Derivatives: ``dv_k/dp_j = (M^-1)_kj``, ``dv_k/dM_ab = -(M^-1)_ka v_b`` per triangle.

    Examples
    --------
    >>> LinearSolve(1, 2, 1, 2, 3, 0)
    -1
    """

    nindex = 1

    @staticmethod
    def _exact(idx, M, p):
        return M.LUsolve(p)[idx[0]]

    @staticmethod
    def _imp_(*args):
        (k,), M, p = LinearSolve._numpy(*args)
        return np.linalg.solve(M, p[..., None])[..., k, 0][()]

    @staticmethod
    def _from_solve(idx, p, v):
        return v[idx[0]]

    def _d_vector(self, idx, j):
        return self._w(idx[0], j)

    def _d_entry(self, idx, a, b):
        return -self._w(idx[0], a) * self._v(b)


@register_function  # saved models may name it (phs.safe_parse)
class InverseEntry(_InverseFunction):
    """Entry ``(k, j)`` of ``W = M^-1``; arguments ``k, j`` and the upper triangle of M.

    Derivatives: ``dW_kj/dM_ab = -W_ka W_bj`` per triangle.

    Examples
    --------
    >>> InverseEntry(1, 0, 2, 1, 2)
    -1/3
    """

    nindex = 2
    vector = False

    @classmethod
    def eval(cls, *args) -> sp.Expr | None:
        if len(args) > 2 and sp.sympify(args[0]).is_Integer and sp.sympify(args[1]).is_Integer and args[0] > args[1]:
            return cls(args[1], args[0], *args[2:])  # M^-1 is symmetric: keep k <= j
        return super().eval(*args)

    @staticmethod
    def _exact(idx, M, p):
        return M.inv()[idx[0], idx[1]]

    @staticmethod
    def _imp_(*args):
        (k, j), M, _ = InverseEntry._numpy(*args)
        return np.linalg.inv(M)[..., k, j][()]

    @staticmethod
    def _from_solve(idx, p, v):  # p is the unit vector e_j, v column j of M^-1
        return v[idx[0]]

    def _d_entry(self, idx, a, b):
        return -self._w(idx[0], a) * self._w(b, idx[1])


def inverse_quadratic_form(M: sp.Matrix, p) -> sp.Expr:
    """``1/2 p^T M^-1 p`` as an :class:`InverseQuadraticForm` of the entries of a symmetric M.

    Examples
    --------
    >>> x = sp.Symbol("x", real=True)
    >>> inverse_quadratic_form(sp.Matrix([[2, 0], [0, 4]]), [x, 2])
    InverseQuadraticForm(2, 0, 4, x, 2)
    """
    M = sp.Matrix(M)
    return InverseQuadraticForm(*[M[i, j] for i, j in _upper(M.rows)], *p)


# -- inertia of planar chains ------------------------------------------------------------------------------


def planar_chain_inertia(angles, lengths, masses, com=None, inertia=None) -> sp.Matrix:
    """Inertia matrix M(q) of a planar serial chain in relative joint angles (eq. 12).

    Link i turns by ``angles[i]`` relative to link i-1 (absolute angle
    ``phi_i = sum_{j<=i} q_j``); its centre of mass lies ``com[i]`` from its
    joint.  Column k of ``J_v^i`` is ``sum_{j=k..i} d_j (-sin phi_j, cos phi_j)``
    with ``d_j = lengths[j]`` for j < i and ``d_i = com[i]``; ``J_w^i`` has ones
    in columns ``k <= i``.  The dot products of those columns are written as
    ``d_j d_l cos(phi_j - phi_l)``, so no trigonometric simplification is needed.

    Parameters
    ----------
    angles : sequence of sympy expressions
        Relative joint angles q_1..q_n [rad].
    lengths, masses : sequences of sympy expressions or numbers
        Link lengths a_i [m] and masses m_i [kg].
    com : sequence, optional
        Distance joint -> centre of mass per link [m]; default ``a_i/2``.
    inertia : sequence, optional
        Inertia about the centre of mass [kg*m**2]; default ``m_i a_i**2/12``.

    Returns
    -------
    sympy.Matrix (n x n), symmetric

    Examples
    --------
    >>> q1, q2, a, m = sp.symbols("q1 q2 a m", positive=True)
    >>> planar_chain_inertia([q1, q2], [a, a], [m, m])[0, 1]
    a**2*m*cos(q2)/2 + a**2*m/3
    """
    n = len(angles)
    lengths, masses = [sp.sympify(v) for v in lengths], [sp.sympify(v) for v in masses]
    com = [a / 2 for a in lengths] if com is None else [sp.sympify(c) for c in com]
    if inertia is None:
        inertia = [m * a**2 / 12 for m, a in zip(masses, lengths, strict=True)]
    inertia = [sp.sympify(i) for i in inertia]
    q = [sp.sympify(a) for a in angles]

    def rel(j, l):  # phi_j - phi_l
        lo, hi = min(j, l), max(j, l)
        return sp.Add(*q[lo + 1: hi + 1])

    M = sp.zeros(n, n)
    for k in range(n):
        for l in range(k, n):
            e = sp.Integer(0)
            for i in range(l, n):
                d = lengths[:i] + [com[i]]
                e += masses[i] * sp.Add(*[d[j] * d[r] * sp.cos(rel(j, r)) for j in range(k, i + 1)
                                          for r in range(l, i + 1)])
                e += inertia[i]
            M[k, l] = M[l, k] = sp.expand(e)
    return M


def reduced_inertia(M: sp.Matrix, T: sp.Matrix) -> sp.Matrix:
    """Inertia ``T^T M T`` in independent coordinates of a closed chain.

    With the joint angles of the open chain written as functions of
    independent coordinates, ``theta = phi(s)``, and ``T = d phi / d s``, the
    kinetic energy ``1/2 theta'^T M theta'`` equals ``1/2 s'^T (T^T M T) s'``.
    Substitute ``theta = phi(s)`` in M (before or after) to have it in s only.

    Raises
    ------
    ModelError
        If M is not square or T has not as many rows as M.

    Examples
    --------
    >>> s = sp.Symbol("s", real=True)
    >>> reduced_inertia(sp.diag(2, 3), sp.Matrix([1, -1]))
    Matrix([[5]])
    """
    M, T = sp.Matrix(M), sp.Matrix(T)
    if M.rows != M.cols or T.rows != M.rows:
        raise ModelError(f"reduced_inertia: M is {M.shape} and T is {T.shape}; need M n x n and T n x k")
    return (T.T * M * T).applyfunc(sp.expand)


# -- components -------------------------------------------------------------------------------------------

_MOMENTUM_UNIT = {"rotational": "kg*m**2/s", "translational": "kg*m/s"}


class ConfigurationInertia(Component):
    """Storage ``H = 1/2 p^T M(q)^-1 p`` for a given symmetric inertia matrix M(q).

    It owns one momentum per coordinate (``{name}.p1``, ... unless
    ``momenta`` names them), each with a port ``{name}.p{i}`` whose effort is
    ``p_i'`` and whose flow is the generalized velocity ``dH/dp_i``: connect
    it in a ``series(...)`` with the springs and dampers acting on coordinate
    i, like a :class:`components.RotationalInertia`.

    Parameters
    ----------
    name : str
    coordinates : sequence of str
        State names of the coordinates q_i (owned by other components).
    inertia_matrix : sympy Matrix (n x n)
        M(q) in terms of the coordinates' symbols (:func:`phs.symbol_of_state`) and parameters.
    params : sequence of Param
        Parameters used in ``inertia_matrix`` that no other component declares.
    momenta : sequence of str, optional
        State names of the momenta; default ``{name}.p{i}`` (i from 1).
    range : (float, float), optional
        Range of every momentum; default 10 (rad or m)/s times the largest diagonal of M(0).
    scale : float, optional
        Typical momentum for solvers.
    domain : {"rotational", "translational"}
        Domain of the ports; momenta are in kg*m**2/s or kg*m/s.

    Raises
    ------
    ModelError
        If the coordinates repeat, the momenta are not one per coordinate, or
        M is not square, symmetric, of the coordinates' size and free of the momenta.

    Examples
    --------
    >>> from phs import symbol_of_state
    >>> q = symbol_of_state("j.theta")
    >>> c = ConfigurationInertia("rod", ["j.theta"], sp.Matrix([[1 + sp.cos(q) ** 2]]))
    >>> c.piece().energy[0].expr
    InverseQuadraticForm(cos(j.theta)**2 + 1, rod.p1)
    """

    def __init__(self, name: str, coordinates, inertia_matrix, params=(), momenta=None, range=None, scale=None,
                 domain: str = "rotational"):
        super().__init__(name)
        if domain not in _MOMENTUM_UNIT:
            raise ModelError(f"component {name!r}: domain must be one of {sorted(_MOMENTUM_UNIT)}, not {domain!r}")
        self.domain = domain
        self.coordinates = [check_name(c, "state") for c in coordinates]
        n = len(self.coordinates)
        if n == 0 or len(set(self.coordinates)) != n:
            raise ModelError(f"component {name!r}: coordinates must be distinct state names, got {coordinates}")
        self.momenta = [f"{name}.p{i}" for i, _ in enumerate(self.coordinates, 1)] if momenta is None else list(momenta)
        if len(self.momenta) != n:
            raise ModelError(f"component {name!r}: momenta has {len(self.momenta)} names for {n} coordinates")
        if set(self.momenta) & set(self.coordinates):
            raise ModelError(f"component {name!r}: a momentum has the name of a coordinate")
        self._matrix, self._extra, self.range, self.scale = inertia_matrix, tuple(params), range, scale

    def _inertia(self) -> tuple[sp.Matrix, tuple[Param, ...]]:
        n = len(self.coordinates)
        if self._matrix is None:
            raise ModelError(f"component {self.name!r}: give the {n} x {n} inertia matrix")
        M = sp.Matrix(self._matrix)
        if M.shape != (n, n) or any(sp.expand(M[i, j] - M[j, i]) != 0 for i, j in _upper(n)):
            raise ModelError(f"component {self.name!r}: the inertia matrix must be symmetric {n} x {n}, got {M.shape}")
        return M, self._extra

    def inertia_matrix(self) -> sp.Matrix:
        """M(q) in terms of the coordinates' state symbols and the parameters' symbols."""
        return self._inertia()[0]

    def _default_range(self, M, params) -> tuple[float, float]:
        vals = {q.symbol: q.value for q in params} | {state_symbol(c): 0 for c in self.coordinates}
        try:
            big = max(float(M[i, i].xreplace(vals)) for i in range(M.rows))
        except (TypeError, ValueError):
            return (-1.0, 1.0)
        return (-10.0 * big, 10.0 * big) if big > 0 else (-1.0, 1.0)

    def piece(self) -> Piece:
        M, params = self._inertia()
        own = {state_symbol(m) for m in self.momenta}
        if M.free_symbols & own:
            raise ModelError(f"component {self.name!r}: the inertia matrix depends on the chain's own momenta")
        rng = self.range if self.range is not None else self._default_range(M, params)
        storages = tuple(
            self._state(f"p{i + 1}", mom, _MOMENTUM_UNIT[self.domain], rng, f"generalized momentum conjugate to {c}",
                        "I", self.domain, self.scale)
            for i, (mom, c) in enumerate(zip(self.momenta, self.coordinates, strict=True)))
        H = inverse_quadratic_form(M, [s.state.symbol for s in storages])
        return Piece(self.name, storages=storages, energy=(EnergyTerm(self.name, H),),
                     ports=tuple(s.port for s in storages), params=tuple(params))


class KinematicChain(ConfigurationInertia):
    """Planar serial chain of rigid links: ``H = 1/2 p^T M(q)^-1 p`` with M from eq. 12.

    Link i (from 1) turns by the relative angle ``angles[i-1]`` at its joint;
    ``M(q) = sum_i m_i J_v^i^T J_v^i + I_i J_w^i^T J_w^i`` is built by
    :func:`planar_chain_inertia` and the energy is an
    :class:`InverseQuadraticForm` (never a symbolic inverse).  Gravity is not
    included: add a :class:`components.Gravity` with the links' heights.

    The chain owns the momenta ``p_i`` (``{name}.p{i}`` unless ``momenta``
    names them) with rotational ports ``{name}.p{i}`` (effort ``p_i'``, flow
    ``theta_i' = dH/dp_i``); put each in a ``series(...)`` with its joint's
    spring and damper.  Closed chains (four-bars, platforms) are reduced by
    choosing independent coordinates: build the open chain's M with
    :func:`planar_chain_inertia`, write the joint angles as ``phi(s)``, take
    :func:`reduced_inertia` with ``T = d phi/d s`` and use it in a
    :class:`ConfigurationInertia` on s.

    Parameters
    ----------
    name : str
    angles : sequence of str
        State names of the relative joint angles (owned by e.g. TorsionalSpring).
    lengths, masses : sequences of float, Param or sympy expression
        Link lengths ``{name}.a{i}`` [m] and masses ``{name}.m{i}`` [kg].
    com : sequence, optional
        Joint -> centre of mass distance ``{name}.c{i}`` [m]; default ``a_i/2``.
    inertia : sequence, optional
        Inertia about the centre of mass ``{name}.I{i}`` [kg*m**2];
        default ``m_i a_i**2/12`` (the paper prints ``a_i m_i/12``).
    momenta, range, scale
        As in :class:`ConfigurationInertia`.

    Raises
    ------
    ModelError
        If the per-link sequences differ in length or a length, mass or
        inertia is not positive.

    Examples
    --------
    A double pendulum on torsional springs with damped joints:

    >>> from phs import interconnect, series
    >>> from components import RotationalDamper, TorsionalSpring
    >>> arm = KinematicChain("arm", ["j1.theta", "j2.theta"], lengths=[0.1, 0.1], masses=[0.05, 0.05])
    >>> arm.inertia_matrix()[1, 1]
    arm.a2**2*arm.m2/3
    >>> parts = [arm, TorsionalSpring("j1", K=0.04, state="j1.theta"), RotationalDamper("b1", b=1e-3),
    ...          TorsionalSpring("j2", K=0.04, state="j2.theta"), RotationalDamper("b2", b=1e-3)]
    >>> s = interconnect("arm", parts, [series("arm.p1", "j1", "b1"), series("arm.p2", "j2", "b2")])
    >>> s.state_names
    ['arm.p1', 'arm.p2', 'j1.theta', 'j2.theta']
    >>> omega = s.lambdify(s.grad_H)([1e-3, 0.0, 0.0, 0.0])  # joint velocities dH/dp at p = (1e-3, 0)
    >>> [round(float(w), 3) for w in omega[:2, 0]]
    [3.429, -8.571]
    """

    def __init__(self, name: str, angles, lengths, masses, com=None, inertia=None, momenta=None, range=None,
                 scale=None):
        super().__init__(name, angles, None, momenta=momenta, range=range, scale=scale)
        n = len(self.coordinates)
        per_link = {"lengths": lengths, "masses": masses, "com": com, "inertia": inertia}
        for key, seq in per_link.items():
            if seq is not None and len(seq) != n:
                raise ModelError(f"component {name!r}: {key} has {len(seq)} entries for {n} joint angles")
        for key in ("lengths", "masses", "inertia"):
            for v in per_link[key] or ():
                require_positive(name, key, v)
        self.lengths, self.masses, self.com, self.inertia = list(lengths), list(masses), com, inertia

    def _inertia(self):
        params: list[Param] = []

        def resolve(key, values, unit, what):
            out = []
            for i, v in enumerate(values):
                sym, decl = self._param(f"{key}{i + 1}", v, unit, f"{what} of link {i + 1}")
                out.append(sym)
                params.extend(decl)
            return out

        a = resolve("a", self.lengths, "m", "length")
        m = resolve("m", self.masses, "kg", "mass")
        c = None if self.com is None else resolve("c", self.com, "m", "distance from the joint to the centre of mass")
        inertia = None if self.inertia is None else resolve("I", self.inertia, "kg*m**2", "inertia about the centre")
        q = [state_symbol(x) for x in self.coordinates]
        return planar_chain_inertia(q, a, m, c, inertia), tuple(params)


__all__ = ["KinematicChain", "ConfigurationInertia", "InverseQuadraticForm", "LinearSolve", "InverseEntry",
           "inverse_quadratic_form", "planar_chain_inertia", "reduced_inertia"]
