"""Write the ``# %%`` example scripts of ``docs/examples/`` as Jupyter notebooks.

    python docs/make_notebooks.py [--out DIR] [--quick] [NAME ...]

Each notebook is its script converted by jupytext (percent format: ``# %%`` starts a code cell,
``# %% [markdown]`` a text cell), preceded by one code cell that lets the script run inside Jupyter,
where there is no ``__file__`` and ``sys.argv`` holds the kernel's own arguments: it names the script
(so paths relative to the checkout, such as ``../shared/data``, resolve), puts the checkout on
``sys.path``, sends the figures and tables into ``figures/`` beside the notebook (``PHS_DOCS_OUT``, so
the documentation's own figures are not overwritten) and sets the script's options (``--quick`` with
``--quick``: the reduced size the tests run).  Notebooks are written without outputs, into ``notebooks/``
by default; run them to produce the outputs.  NAMEs (``new_actuator``) choose scripts; default: every
script of ``docs/examples/`` that has cells.  Needs ``jupytext`` (``pip install ".[docs]"``).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent / "examples"
ROOT = EXAMPLES.parent.parent


def scripts() -> list[Path]:
    """The example scripts written as ``# %%`` cells, by name.

    Examples
    --------
    >>> "new_actuator" in [p.stem for p in scripts()]
    True
    """
    return sorted(p for p in EXAMPLES.glob("*.py") if "\n# %%" in "\n" + p.read_text(encoding="utf-8"))


def setup_cell(script: Path, quick: bool = False) -> str:
    """The first cell of the notebook of ``script``: its path, the checkout on ``sys.path``, its options.

    Examples
    --------
    >>> cell = setup_cell(EXAMPLES / "new_actuator.py", quick=True)
    >>> "--quick" in cell and "PHS_DOCS_OUT" in cell
    True
    """
    options = ', "--quick"' if quick else ""
    return (
        "# Running the script as a notebook: its path, the checkout on sys.path, where figures go, its options.\n"
        "import os\n"
        "import sys\n"
        "\n"
        f"__file__ = {str(script)!r}  # the script this notebook was made from\n"
        f"sys.path.insert(0, {str(ROOT)!r})\n"
        'os.environ["PHS_DOCS_OUT"] = os.path.abspath("figures")  # figures and tables beside the notebook\n'
        'os.makedirs(os.environ["PHS_DOCS_OUT"], exist_ok=True)\n'
        f'sys.argv = [__file__, "--out", os.environ["PHS_DOCS_OUT"]{options}]  # add "--quick" for the reduced size\n'
    )


def notebook(script: Path, quick: bool = False):
    """The notebook of ``script`` (an ``nbformat`` node, without outputs).

    Examples
    --------
    >>> nb = notebook(EXAMPLES / "new_actuator.py")
    >>> nb.cells[0].cell_type, nb.cells[1].cell_type, nb.nbformat
    ('code', 'markdown', 4)
    """
    import jupytext
    import nbformat

    nb = jupytext.reads(script.read_text(encoding="utf-8"), fmt="py:percent")
    nb.cells.insert(0, nbformat.v4.new_code_cell(setup_cell(script, quick)))
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.metadata.pop("jupytext", None)
    for i, cell in enumerate(nb.cells):
        cell["id"] = f"cell-{i}"
    return nb


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Write the example scripts of docs/examples/ as Jupyter notebooks")
    ap.add_argument("names", nargs="*", help="script names without .py (default: every script with # %% cells)")
    ap.add_argument("--out", default="notebooks", help="directory of the notebooks (default: notebooks/)")
    ap.add_argument("--quick", action="store_true", help="set the scripts' --quick option (the tests' reduced size)")
    args = ap.parse_args(argv)
    try:
        import jupytext  # noqa: F401
    except ImportError:
        print("make_notebooks: error: jupytext is not installed (pip install jupytext, or '.[docs]')", file=sys.stderr)
        return 2
    import nbformat

    available = {p.stem: p for p in scripts()}
    unknown = [n for n in args.names if n not in available]
    if unknown:
        print(f"make_notebooks: error: no example script with cells named {', '.join(unknown)}; "
              f"available: {', '.join(available)}", file=sys.stderr)
        return 2
    os.makedirs(args.out, exist_ok=True)
    for name in args.names or list(available):
        path = os.path.join(args.out, name + ".ipynb")
        tmp = path + ".tmp"
        nbformat.write(notebook(available[name], args.quick), tmp)
        os.replace(tmp, path)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
