"""The bounded search of an input element's parameters (``element_search``): the whole grid, and the local
search of a joint fit's later rounds, which falls back to the whole grid when its bracket does not hold the
minimum.  Costs with a known minimum, counted evaluations."""

from __future__ import annotations

import math

import numpy as np

from phs.workflows.diagnose.element_search import element_search, extrapolate

SPECS = [("tau_d", 0.5, 0.0, 8.0)]  # a delay's range: 0 to 8 s, log-spaced grid from 8 ms


def _counted(minimum: float, floor: float = 0.0):
    calls = []

    def cost(theta):
        calls.append(float(theta[0]))
        return float(np.log(max(theta[0], 1e-9) / minimum) ** 2) + floor

    return cost, calls


def test_whole_grid_search_finds_the_minimum():
    cost, calls = _counted(2.0)
    found = element_search(cost, SPECS, [0.5])[0]
    # Brent's bounded method within the bracket of grid points around 2 s (1.42 to 3.37 s), at most 8 steps
    assert math.isclose(found, 2.0, rel_tol=1e-2)
    assert len(calls) >= 10  # the grid: 0 and nine log-spaced points


def test_local_search_refines_a_nearby_start_without_the_grid():
    cost, calls = _counted(2.0)
    found = element_search(cost, SPECS, [1.7], local=True)[0]
    assert math.isclose(found, 2.0, rel_tol=1e-2)
    # the start, the points an eighth of a grid step either side, one step on downhill and two parabolic
    # steps: no grid (the whole search costs ten more) and no Brent refinement inside the grid's bracket
    # (eight more)
    assert len(calls) <= 6


def test_local_search_falls_back_to_the_grid_when_the_minimum_is_far():
    cost, calls = _counted(6.0)
    found = element_search(cost, SPECS, [0.05], local=True)[0]
    # the bracket around 0.05 s ends at its upper edge with the cost still falling: the grid from there up
    # (not below it) then finds 6 s
    assert math.isclose(found, 6.0, rel_tol=1e-2)
    assert len(calls) > 18


def test_local_search_in_a_linear_range_and_at_its_start():
    # a parameter whose range crosses zero is searched in itself; a start at the minimum stays, in three
    # evaluations and one parabolic step
    specs = [("U", 0.0, -10.0, 10.0)]
    calls = []

    def cost(theta):
        calls.append(float(theta[0]))
        return (theta[0] - 1.3) ** 2

    assert math.isclose(element_search(cost, specs, [1.0], local=True)[0], 1.3, rel_tol=1e-9)
    calls.clear()
    assert element_search(cost, specs, [1.3], local=True) == [1.3] and len(calls) <= 4


def test_search_never_ends_above_its_start():
    # a cost that the grid and the bracket cannot improve on: the start is kept
    def cost(theta):
        return 0.0 if theta[0] == 1.234 else 1.0

    assert element_search(cost, SPECS, [1.234], local=True) == [1.234]
    assert element_search(cost, SPECS, [1.234]) == [1.234]


def _valley(th, v):
    """A narrow valley along ``theta = b`` with its minimum at (1, 1): alternating searches of ``theta``
    and ``b`` zigzag along it."""
    return (th[0] - v["b"]) ** 2 + 0.01 * (th[0] + v["b"] - 2) ** 2


def _alternate(theta, b, rounds, step):
    """Rounds of exact minimisation in ``b`` then in ``theta``, with or without the step along each move."""
    for _ in range(rounds):
        start = ([theta], {"b": b})
        b = (0.99 * theta + 0.02) / 1.01       # argmin over b of the valley
        theta = (0.99 * b + 0.02) / 1.01       # argmin over theta
        if step:
            moved = extrapolate(_valley, [("a", 0.5, 0.0, 5.0)], ["b"], None, start, ([theta], {"b": b}), _valley([theta], {"b": b}))
            if moved is not None:
                (theta,), b = moved[0], moved[1]["b"]
    return theta, b


def test_the_step_along_a_zigzag_reaches_the_valley_floor():
    # alternating alone creeps: each round closes about 4 % of the way to (1, 1)
    slow = _alternate(0.2, 0.2, 8, step=False)
    fast = _alternate(0.2, 0.2, 8, step=True)
    assert abs(slow[0] - 1) > 0.4
    assert abs(fast[0] - 1) < 0.4 * abs(slow[0] - 1) and _valley([fast[0]], {"b": fast[1]}) < _valley([slow[0]], {"b": slow[1]})


def test_no_step_beyond_a_minimum_and_none_outside_the_bounds():
    # a move that ended at the minimum: going on only climbs
    assert extrapolate(_valley, [("a", 0.5, 0.0, 5.0)], ["b"], None, ([0.5], {"b": 0.5}), ([1.0], {"b": 1.0}), 0.0) is None
    # the fit's bounds and the element's range hold: b may not pass 0.6, theta not 0.7
    th, vals, _ = extrapolate(_valley, [("a", 0.5, 0.0, 0.7)], ["b"], {"b": (0.0, 0.6)}, ([0.3], {"b": 0.3}), ([0.4], {"b": 0.4}),
                              _valley([0.4], {"b": 0.4}))
    assert th[0] <= 0.7 and vals["b"] <= 0.6


def test_local_search_beyond_its_bracket_reads_only_the_grid_the_cost_falls_toward():
    # the minimum near the range's lower end (a delay of 12 ms from a start at 0.5 s; the bracket is the grid
    # points 0.25 and 1.42 s either side of the start): the grid points above the bracket (1.42, 3.37, 8 s)
    # are never evaluated, and of those below it only the ones the cost falls toward
    cost, calls = _counted(0.012)
    found = element_search(cost, SPECS, [0.5], local=True)[0]
    assert math.isclose(found, 0.012, rel_tol=1e-2)
    assert max(calls) < 1.4


def test_local_search_toward_the_ranges_end_stops_there():
    # the cost falls all the way to the range's upper end (a saturation limit above every command): the
    # local search walks up to the last grid point and takes it, without the whole grid (nine points more
    # and Brent's refinement); the start, the points either side, the walk's steps
    cost, calls = _counted(50.0)  # beyond the range's end at 8 s
    found = element_search(cost, SPECS, [5.0], local=True)[0]
    assert found == 8.0
    assert len(calls) <= 6 and min(calls) > 3.3  # never below the grid point under the start (3.37 s)


def test_a_parabolic_step_promising_less_than_the_resolution_is_not_taken():
    # a quadratic cost in the parameter itself: its parabola is exact, so a step is skipped only when its
    # whole gain lies below the resolution, and the point kept is within the resolution of the minimum
    specs = [("U", 0.0, -10.0, 10.0)]
    calls = []

    def cost(theta):
        calls.append(float(theta[0]))
        return 100.0 + (theta[0] - 1.3) ** 2

    exact = element_search(cost, specs, [1.2], local=True)[0]
    n_exact = len(calls)
    calls.clear()
    resolution = 0.05  # the start's excess over the minimum is 0.01: below it
    coarse = element_search(cost, specs, [1.2], local=True, resolution=resolution)[0]
    assert math.isclose(exact, 1.3, rel_tol=1e-9)
    assert coarse == 1.2 and len(calls) < n_exact
    assert cost([coarse]) - 100.0 <= resolution
    calls.clear()
    # from farther away the walk brackets the minimum with its best point 0.035 above it: within a resolution
    # of 0.05 that point is kept, with 0.01 the parabolic step is taken, to the minimum
    far = element_search(cost, specs, [0.8], local=True, resolution=resolution)[0]
    assert far != 1.3 and cost([far]) - 100.0 <= resolution
    assert math.isclose(element_search(cost, specs, [0.8], local=True, resolution=0.01)[0], 1.3, rel_tol=1e-9)
