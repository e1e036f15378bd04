"""An input element's parameter search (``hypotheses._element_search``): the whole grid, or, from a known
value (a later round of a joint fit, a refit from its screening), a refinement between the grid points
around it that falls back to the whole grid when the minimum lies outside that bracket."""

import pytest

from phs.workflows.diagnose.hypotheses import _element_search

SPECS = [("tau", 0.01, 0.0, 0.1)]  # a delay in [0, 0.1] s


def _counted(best):
    calls = []

    def cost(theta):
        calls.append(theta[0])
        return (theta[0] - best) ** 2

    return cost, calls


@pytest.mark.parametrize("start", [0.01, 0.0133])
def test_local_search_refines_near_a_known_value_with_fewer_simulations(start):
    cost, calls = _counted(0.0123)
    assert _element_search(cost, SPECS, [start], local=True)[0] == pytest.approx(0.0123, rel=1e-3)
    local = len(calls)
    cost, calls = _counted(0.0123)
    assert _element_search(cost, SPECS, [start])[0] == pytest.approx(0.0123, rel=1e-3)
    assert local < len(calls) / 2  # measured 7 against 17 cost evaluations


def test_local_search_falls_back_to_the_grid_when_the_minimum_is_outside_its_bracket():
    cost, calls = _counted(0.0123)
    # from 0.09 the bracket is [0.042, 0.1]: its refinement ends at the inner edge, so the whole grid runs
    assert _element_search(cost, SPECS, [0.09], local=True)[0] == pytest.approx(0.0123, rel=1e-3)
    assert min(calls) == 0.0  # the grid (it starts at the range's 0) was searched


def test_search_never_ends_above_its_start():
    # a cost the refinement cannot improve on: the start is kept
    assert _element_search(lambda th: 0.0 if th[0] == 0.05 else 1.0, SPECS, [0.05], local=True) == [0.05]
