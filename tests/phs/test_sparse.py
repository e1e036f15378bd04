"""The sparse passes over model matrices give exactly what the dense passes they replace gave."""

from __future__ import annotations

import hashlib
import itertools

import casadi as ca
import numpy as np
import pytest
import sympy as sp

from codegen.translate import Translator
from components import CosseratRod
from phs import interconnect
from phs._sparse import nonzero_entries, srepr_matrix
from phs.checks import _blocks
from phs.interconnect import _second_derivative

a, b, c = sp.symbols("a b c", real=True)

MATRICES = [
    sp.zeros(0, 0), sp.zeros(0, 3), sp.zeros(2, 0), sp.zeros(3, 3), sp.eye(3),
    sp.Matrix([[0, a], [-a, 0]]), sp.Matrix([[sp.Rational(1, 2), 0, 0], [0, 0, sp.sin(b) * c]]),
    sp.ImmutableMatrix([[1, 0], [0, a**2]]), sp.Matrix([[sp.Float(0.5), 0], [0, -3]]),
]


@pytest.mark.parametrize("M", MATRICES, ids=range(len(MATRICES)))
def test_srepr_and_entries_match_the_dense_passes(M):
    assert srepr_matrix(M) == sp.srepr(M)
    dense = [(i, j, M[i, j]) for i in range(M.rows) for j in range(M.cols) if M[i, j] != 0]
    assert nonzero_entries(M) == dense


def _rod(**kw):
    return interconnect("rod", [CosseratRod("rod", 3, gravity=True, c_v=0.1, **kw)])


def _dense_hash(s) -> str:
    """``PHSystem.model_hash`` as it was computed before, with ``sympy.srepr`` of every matrix."""
    h = hashlib.sha256()
    for part in (
        s.name, [x.name for x in s.states], [i.name for i in s.inputs], s.param_names,
        [i.output for i in s.inputs],
        [sp.srepr(t.expr) for t in s.energy_terms], *(sp.srepr(M) for M in (s.J, s.R, s.G, s.P, s.S, s.N)),
        [(m.name, sp.srepr(m.expr)) for m in s.measured], [(cd.label, sp.srepr(cd.expr)) for cd in s.conditions],
        [(label, sorted((k, sp.srepr(v)) for k, v in entries.items())) for label, entries in s.dissipators],
    ):
        h.update(repr(part).encode())
    return h.hexdigest()[:16]


@pytest.mark.parametrize("damping", ["stiffness_proportional", "kelvin_voigt"])
def test_rod_hash_and_dissipation_forms_match_the_dense_computation(damping):
    s = _rod(tau=0.01, damping=damping)
    assert s.model_hash() == _dense_hash(s)
    # each dissipator's form is half the Hessian of its power, as sympy's own second derivative gives it
    piece = CosseratRod("rod", 3, gravity=True, c_v=0.1, tau=0.01, damping=damping).piece()
    for d in piece.dissipators[:2]:  # the elements at the clamp and inside the rod (sympy's diff is slow)
        zs = sorted((v for v in d.power.free_symbols if v.name.startswith("f[")), key=str)  # the velocities
        first = {v: sp.diff(d.power, v) for v in zs}
        for p, q in itertools.product(zs, zs):
            assert _second_derivative(d.power, first, p, q) == sp.diff(d.power, p, q)
    assert len(s.dissipators) == 6  # three elements, three nodes with drag


def test_second_derivative_matches_sympy_on_general_expressions():
    f = sp.Function("f")
    for e in (a**2 * sp.cos(b) * c + a * b / c, sp.exp(a * b) - sp.log(c) * a * b, (a - b) ** 3 * c, f(a) * b):
        first = {v: sp.diff(e, v) for v in (a, b, c)}
        for p, q in itertools.product((a, b, c), repeat=2):
            assert _second_derivative(e, first, p, q) == sp.diff(e, p, q)


def test_blocks_match_a_dense_union_find():
    rng = np.random.default_rng(3)
    for _ in range(20):
        n = int(rng.integers(1, 12))
        M = sp.zeros(n, n)
        for _ in range(int(rng.integers(0, n + 3))):
            i, j = (int(k) for k in rng.integers(0, n, 2))
            M[i, j] = M[j, i] = a
        # dense reference: components of the pattern, listing only rows with an entry
        comp = list(range(n))
        for i in range(n):
            for j in range(n):
                if M[i, j] != 0:
                    ci, cj = comp[i], comp[j]
                    comp = [ci if k == cj else k for k in comp]
        groups: dict[int, list[int]] = {}
        for i in range(n):
            if any(M[i, j] != 0 for j in range(n)):
                groups.setdefault(comp[i], []).append(i)
        assert sorted(_blocks(M)) == sorted(groups.values())


def test_translated_matrix_matches_entrywise_translation():
    s = _rod(tau=0.01)
    x = ca.SX.sym("x", len(s.x))
    p = ca.SX.sym("p", len(s.p))
    symbols = {**{v: x[k] for k, v in enumerate(s.x)}, **{v: p[k] for k, v in enumerate(s.p)}}
    sparse = Translator(dict(symbols))(s.R)
    dense = ca.SX(s.R.rows, s.R.cols)
    tr = Translator(dict(symbols))
    for i in range(s.R.rows):
        for j in range(s.R.cols):
            if s.R[i, j] != 0:
                dense[i, j] = tr(s.R[i, j])
    f = ca.Function("f", [x, p], [sparse, dense])
    xv = np.linspace(-0.1, 0.1, len(s.x))
    A, B = (np.array(m.full()) for m in f(xv, s.param_vector()))
    assert np.count_nonzero(A) > 0 and np.array_equal(A, B)  # the same entries, bit for bit
