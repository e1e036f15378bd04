"""The example scripts of ``docs/examples/`` open as Jupyter notebooks (``docs/make_notebooks.py``, jupytext).

Every script with ``# %%`` cells converts: each code cell of its notebook is a verbatim piece of the
script (the pair is in sync by construction: the notebook is made from the script, never edited), and
every cell compiles.  One notebook is executed as Jupyter would run it — no ``__file__``, the kernel's own
``sys.argv`` — at reduced size, in a fresh process, and must write its figure beside the notebook, not
into ``docs/figures``.  An argparse-driven one runs with ``-m slow``.
"""

from __future__ import annotations

import doctest
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("jupytext")

ROOT = Path(__file__).resolve().parent.parent
SPEC = importlib.util.spec_from_file_location("make_notebooks", ROOT / "docs" / "make_notebooks.py")
make_notebooks = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(make_notebooks)

# runs the code cells of a notebook in order, as a Jupyter kernel would: no __file__, the kernel's argv
_KERNEL = """
import json, sys
sys.argv = ["ipykernel_launcher.py", "-f", "kernel-1234.json"]
nb = json.load(open({path!r}, encoding="utf-8"))
ns = {{"__name__": "__main__"}}
for cell in nb["cells"]:
    if cell["cell_type"] == "code":
        exec(compile("".join(cell["source"]), "<cell>", "exec"), ns)
"""


def _run(name: str, tmp_path: Path, timeout: int) -> subprocess.CompletedProcess:
    assert make_notebooks.main([name, "--quick", "--out", str(tmp_path)]) == 0
    driver = tmp_path / "kernel.py"
    driver.write_text(_KERNEL.format(path=str(tmp_path / f"{name}.ipynb")))
    env = {k: v for k, v in os.environ.items() if k != "PHS_DOCS_OUT"}
    env["MPLBACKEND"] = "Agg"
    return subprocess.run([sys.executable, str(driver)], cwd=tmp_path, capture_output=True, text=True, env=env, timeout=timeout)


def test_make_notebooks_docstring_examples():
    assert doctest.testmod(make_notebooks).failed == 0


@pytest.mark.parametrize("script", make_notebooks.scripts(), ids=lambda p: p.stem)
def test_every_script_converts_in_sync(script):
    import nbformat

    nb = make_notebooks.notebook(script)
    nbformat.validate(nb)
    text = script.read_text(encoding="utf-8")
    code = [c for c in nb.cells[1:] if c.cell_type == "code"]
    assert len(nb.cells) - 1 == text.count("\n# %%") + text.startswith("# %%")  # one cell per marker
    for cell in code:
        assert cell.source.strip() in text, f"{script.name}: a cell that is not in the script:\n{cell.source[:300]}"
        compile(cell.source, script.name, "exec")
    assert not any(c.get("outputs") for c in code)
    compile(nb.cells[0].source, "setup", "exec")


def test_unknown_name_is_refused_in_one_line(tmp_path, capsys):
    assert make_notebooks.main(["no_such_example", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no_such_example" in err and "new_actuator" in err
    assert not list(tmp_path.iterdir())


def test_a_notebook_runs_as_in_jupyter_and_writes_beside_itself(tmp_path):
    docs_figure = ROOT / "docs" / "figures" / "new_actuator.png"
    before = docs_figure.stat().st_mtime_ns
    proc = _run("new_actuator", tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "pull-in voltage" in proc.stdout
    assert (tmp_path / "figures" / "new_actuator.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert docs_figure.stat().st_mtime_ns == before  # the documentation's own figure is left alone
    nb = json.loads((tmp_path / "new_actuator.ipynb").read_text(encoding="utf-8"))
    assert nb["nbformat"] == 4 and "--quick" in "".join(nb["cells"][0]["source"])


@pytest.mark.slow
def test_an_argparse_example_runs_as_a_notebook(tmp_path):
    proc = _run("identify_curling_hasel", tmp_path, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (tmp_path / "figures" / "identify_curling_hasel.png").is_file()
