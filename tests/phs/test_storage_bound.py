"""H bounded below: decided symbolically where possible, numerically over the box otherwise, and never
"pass" for a Hamiltonian that is unbounded below."""

from __future__ import annotations

import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from phs import PHSystem, StateInfo
from phs.storage_bound import bounded_below

q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)


def oscillator(V, q_range=(-1.0, 1.0)) -> PHSystem:
    """A unit mass in the potential V(q), lossless."""
    return PHSystem("osc", [StateInfo("q", range=q_range), StateInfo("p", kind="I")], H=V + p**2 / 2,
                    J=[[0, 1], [-1, 0]], R=[[0, 0], [0, 0]])


@pytest.mark.parametrize("V, why", [
    (-q**4, "quartic well upside down: minimum on the box's face, falling faster outward"),
    (-q**2 / 2, "saddle"),
    (-q**3, "odd cubic: falls on one side"),
    (-sp.log(1 + q**2), "logarithmic: falls by the same amount at every doubling"),
])
def test_unbounded_hamiltonians_fail(V, why):
    system = oscillator(V)
    bound = bounded_below(system)
    assert bound.verdict == "fail", (why, bound)
    assert "unbounded below" in bound.detail
    report = system.check()
    assert report["H bounded below"].verdict == "fail" and not report.ok


def test_bounded_on_the_stated_box_only_is_said_plainly():
    """q² - q⁴/100: minimum 0 inside the box (-1, 1), unbounded beyond |q| = 7: never a pass."""
    bound = bounded_below(oscillator(q**2 - q**4 / 100))
    assert bound.verdict == "undecided" and "stated box only" in bound.detail
    assert bound.minimum == pytest.approx(0.0, abs=1e-9)


def test_the_old_sampled_pass_is_gone():
    """The sampled check used to report 'minimum -0.93 J ... pass' for this H."""
    assert oscillator(-q**4).check()["H bounded below"].verdict == "fail"


@pytest.mark.parametrize("V, method", [
    (q**4 / 4 - q**2 / 2, "symbolic"),            # double well: even polynomial, positive leading coefficient
    (q**2 / 2, "symbolic"),
    (-sp.tanh(q), "numeric"),                    # minimum on the face, but H levels off outside
    (-sp.cos(q), "numeric"),                     # pendulum-like: interior minimum
    (-sp.exp(-q**2), "numeric"),
])
def test_bounded_hamiltonians_pass(V, method):
    bound = bounded_below(oscillator(V))
    assert bound.verdict == "pass", bound
    assert bound.method.startswith(method)


def test_numeric_minimum_is_the_true_one():
    """-cos(q) + p²/2 over q in (-1, 1): minimum -1 at q = 0 (tolerance: L-BFGS-B's default 1e-8 relative)."""
    bound = bounded_below(oscillator(-sp.cos(q)))
    assert bound.minimum == pytest.approx(-1.0, abs=1e-7)
    assert bound.point["q"] == pytest.approx(0.0, abs=1e-3)


def test_an_edge_where_the_model_ends_is_not_a_failure():
    """H = -sqrt(1 - q²)·… is undefined outside |q| <= 1: the box edge is the model's edge."""
    bound = bounded_below(oscillator(-sp.sqrt(1 - q**2) - q, q_range=(-1.0, 1.0)))
    assert bound.verdict == "pass"


@settings(max_examples=12)
@given(coeffs=st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=1, max_size=4),
       lead=st.floats(0.1, 3.0), degree=st.integers(1, 3))
def test_polynomial_potentials(coeffs, lead, degree):
    """A polynomial potential is bounded below iff its degree is even and its leading coefficient positive:
    the first passes (symbolically), the others never pass (``fail`` when the box's minimum lies on a face
    that H keeps falling through, ``undecided`` -- bounded on the stated box only -- when it lies inside)."""
    n = 2 * degree
    V = sum(sp.Float(c) * q**k for k, c in enumerate(coeffs[: n - 1], start=1)) + sp.Float(lead) * q**n
    bound = bounded_below(oscillator(V))
    assert bound.verdict == "pass" and bound.method == "symbolic"
    for unbounded in (-V, V + sp.Float(lead) * q**(n + 1)):
        bound = bounded_below(oscillator(unbounded))
        assert bound.verdict in ("fail", "undecided") and "unbounded below" in bound.detail, (unbounded, bound)
