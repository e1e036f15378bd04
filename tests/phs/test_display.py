"""Display: LaTeX for Jupyter and the printed summary name what a reader needs."""

from phs.display import param_table
from systems.curling_hasel import curling_hasel
from systems.examples import rc_circuit


def test_latex_shows_structure_and_names():
    tex = rc_circuit()._repr_latex_()
    assert tex.startswith("$$") and tex.endswith("$$")
    for part in (r"\nabla H", r"\dot x", "Q^{\\mathrm{C}}", "R^{\\mathrm{R}}", "y &="):
        assert part in tex, part


def test_summary_lists_states_inputs_parameters_and_conditions():
    text = str(curling_hasel(1))
    for part in ("seg1.theta", "[rad]", "U ", "-> output U.i [A]", "K_b", "N*m/rad", "tip", "validity conditions"):
        assert part in text, part


def test_parameter_table_is_generated_from_the_declarations():
    table = param_table(curling_hasel(1))
    assert "| `gamma1` | 2 | 1 |" in table
    assert table.count("\n") == len(curling_hasel(1).params) + 1
