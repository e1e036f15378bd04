"""The diagnosis' constants: one table lists them all, and none is justified by a held-out case.

``docs/reference/diagnosis_constants.md`` holds one row per UPPER_CASE numeric module constant of
``phs/workflows/diagnose/`` (its sub-packages ``discover/`` and ``locate/`` included) and of any
``phs/workflows/discover*/``: a number, or a
tuple or dict of numbers.  The row names the constant and its module and shows its current value as
:func:`_shown` writes it, so a constant added, removed or changed without the table fails here.

The held-out cases (``calibration.is_held_out``: the stored diagnoses of noise seed
``calibration.HELD_OUT_SEED``) are never cited to justify a constant: no constant's docstring, and no
"chosen on" cell of the table, names one (by ``calibration.case_name`` or as "seed N").
"""

from __future__ import annotations

import ast
import importlib
import os
import re
from pathlib import Path

import pytest

from phs.workflows.diagnose.calibration import HELD_OUT_SEED, case_name, is_held_out, load_rows

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "phs" / "workflows" / "diagnose"
TABLE = ROOT / "docs" / "reference" / "diagnosis_constants.md"


def _numeric(v) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return True
    if isinstance(v, (tuple, list)):
        return len(v) > 0 and all(_numeric(x) for x in v)
    if isinstance(v, dict):
        return len(v) > 0 and all(_numeric(x) for x in v.values())
    return False


def _shown(v) -> str:
    """How the table writes a value: integers as they are, floats to four significant digits, tuples in
    parentheses, dicts as ``key: value; key: value``."""
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (tuple, list)):
        return "(" + ", ".join(_shown(x) for x in v) + ")"
    return "; ".join(f"{k}: {_shown(x)}" for k, x in v.items())


def _module_constants():
    """(module, name, value, docstring) of every UPPER_CASE module-level assignment under the package."""
    out = []
    # the discovery lives in diagnose/discover/; a discover* package beside diagnose/ would be walked too
    paths = sorted(PACKAGE.rglob("*.py")) + sorted(p for d in PACKAGE.parent.glob("discover*") for p in d.rglob("*.py"))
    for path in paths:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        for k, node in enumerate(tree.body):
            target = node.targets[0] if isinstance(node, ast.Assign) and len(node.targets) == 1 else getattr(node, "target", None)
            if not isinstance(node, (ast.Assign, ast.AnnAssign)) or not isinstance(target, ast.Name):
                continue
            if not re.fullmatch(r"[A-Z][A-Z0-9_]*", target.id):
                continue
            nxt = tree.body[k + 1] if k + 1 < len(tree.body) else None
            doc = nxt.value.value if (isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                                      and isinstance(nxt.value.value, str)) else ""
            out.append((module, target.id, getattr(importlib.import_module(module), target.id), doc))
    return out


CONSTANTS = _module_constants()
NUMERIC = [(m, n, v, d) for m, n, v, d in CONSTANTS if _numeric(v)]


def _table_rows() -> dict:
    """The table's rows by (module, constant): the cells of each row."""
    rows = {}
    for line in TABLE.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        m = re.fullmatch(r"`([A-Z][A-Z0-9_]*)`", cells[0]) if line.startswith("|") else None
        if m and len(cells) >= 6:
            rows[(cells[1].strip("`"), m.group(1))] = cells
    return rows


def test_values_are_shown_as_the_table_writes_them():
    assert [_shown(v) for v in (1 / 3, 1e-6, 30.0, 5000, (1 / 50, 100.0))] == ["0.3333", "1e-06", "30", "5000", "(0.02, 100)"]
    assert _shown({"effect": ((0.401, 0.75),), "none": ((0.63, 0.5),)}) == "effect: ((0.401, 0.75)); none: ((0.63, 0.5))"
    assert not _numeric(True) and not _numeric("x") and not _numeric(()) and _numeric({"a": (1, 2.0)})


def test_the_constants_are_found():
    names = {n for _, n, _, _ in NUMERIC}
    # a few from each part of the package, so a broken walk cannot pass with an empty list
    assert {"RIVAL_MARGIN", "DISCOVER_BELOW", "SCREEN_ITER", "SCREEN_REFINE_ITER", "LAG_SAMPLES", "TIGHT_REFITS",
            "CALIBRATION", "HELD_OUT_CALIBRATION", "N_SURROGATES", "MAX_TERMS", "RESEMBLES"} <= names
    assert len(NUMERIC) >= 50
    assert "REFUSED" not in names and "KINDS" not in names  # strings are not numeric constants


@pytest.mark.parametrize(("module", "name", "value"), [pytest.param(m, n, v, id=f"{m}.{n}") for m, n, v, _ in NUMERIC])
def test_every_numeric_constant_is_in_the_table_with_its_value(module, name, value):
    rows = _table_rows()
    assert (module, name) in rows, f"{module}.{name} is not in {TABLE.name}"
    shown = rows[(module, name)][2].strip("`")
    assert shown == _shown(value), f"{name}: the table says {shown}, the code holds {_shown(value)}"


def test_the_table_lists_no_constant_that_does_not_exist():
    known = {(m, n) for m, n, _, _ in NUMERIC}
    assert set(_table_rows()) <= known, set(_table_rows()) - known


def _held_out_citations(text: str, names: list[str]) -> list[str]:
    found = [n for n in names if n in text]
    for m in re.finditer(r"\bseeds?\s*[=:]?\s*((?:\d+)(?:\s*(?:,|and|or|to|-)\s*\d+)*)", text):
        if str(HELD_OUT_SEED) in re.findall(r"\d+", m.group(1)):
            found.append(m.group(0))
    return found


@pytest.fixture(scope="module")
def held_out_names():
    rows = load_rows(os.path.join(ROOT, "bench", "calibration_data.jsonl"))
    names = [case_name(r) for r in rows if is_held_out(r)]
    assert len(names) == 40
    return names


def test_no_constant_is_justified_by_a_held_out_case(held_out_names):
    for module, name, _, doc in CONSTANTS:
        if name == "HELD_OUT_SEED":  # the constant that names them
            continue
        assert not _held_out_citations(doc, held_out_names), f"{module}.{name} cites held-out cases"
    for (_, name), cells in _table_rows().items():
        assert not _held_out_citations(cells[4], held_out_names), f"{TABLE.name}, {name}: chosen on held-out cases"


def test_the_citation_check_finds_a_held_out_case(held_out_names):
    assert held_out_names[0] in _held_out_citations(f"On {held_out_names[0]} the rule pays.", held_out_names)
    assert _held_out_citations(f"measured on seeds 3 and {HELD_OUT_SEED}", held_out_names)
    assert not _held_out_citations("measured on the 20 s charge-retention case (seed 1)", held_out_names)
