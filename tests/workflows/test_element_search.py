"""The bounded search of an input element's parameters (``_element_search``): the whole grid, and the local
search of a joint fit's later rounds, which falls back to the whole grid when its bracket does not hold the
minimum.  Costs with a known minimum, counted evaluations."""

from __future__ import annotations

import math

import numpy as np

from phs.workflows.diagnose.hypotheses import _element_search

SPECS = [("tau_d", 0.5, 0.0, 8.0)]  # a delay's range: 0 to 8 s, log-spaced grid from 8 ms


def _counted(minimum: float, floor: float = 0.0):
    calls = []

    def cost(theta):
        calls.append(float(theta[0]))
        return float(np.log(max(theta[0], 1e-9) / minimum) ** 2) + floor

    return cost, calls


def test_whole_grid_search_finds_the_minimum():
    cost, calls = _counted(2.0)
    found = _element_search(cost, SPECS, [0.5])[0]
    # Brent's bounded method within the bracket of grid points around 2 s (1.42 to 3.37 s), at most 8 steps
    assert math.isclose(found, 2.0, rel_tol=1e-2)
    assert len(calls) >= 10  # the grid: 0 and nine log-spaced points


def test_local_search_refines_a_nearby_start_without_the_grid():
    cost, calls = _counted(2.0)
    found = _element_search(cost, SPECS, [1.7], local=True)[0]
    assert math.isclose(found, 2.0, rel_tol=1e-2)
    # the refinement (at most 8), the bracket's two ends and the start's own cost, no grid (the whole
    # search costs the grid's ten more)
    assert len(calls) <= 11


def test_local_search_falls_back_to_the_grid_when_the_minimum_is_far():
    cost, calls = _counted(6.0)
    found = _element_search(cost, SPECS, [0.05], local=True)[0]
    # the bracket around 0.05 s ends at its upper edge: the whole grid then finds 6 s
    assert math.isclose(found, 6.0, rel_tol=1e-2)
    assert len(calls) > 18


def test_search_never_ends_above_its_start():
    # a cost that the grid and the bracket cannot improve on: the start is kept
    def cost(theta):
        return 0.0 if theta[0] == 1.234 else 1.0

    assert _element_search(cost, SPECS, [1.234], local=True) == [1.234]
    assert _element_search(cost, SPECS, [1.234]) == [1.234]
