"""Every ```python block of ``README.md`` and ``docs/**/*.md`` runs as written, and prints what the page says.

Conventions for the pages:

* A block fenced ```` ```python ```` is code a reader may paste: it must run.  The blocks of one
  page run in order in one fresh namespace (a block may use what an earlier block of the same page
  defined), in a subprocess per page whose working directory is an empty temporary directory, with
  ``MPLBACKEND=Agg`` and a timeout of ``TIMEOUT`` seconds.  Code that is deliberately not runnable
  (shell sessions, terminal output, outlines with ``...``) is fenced with another language
  (``bash``, ``console``, ``text``), never hidden from this test.
* A ```` ```text ```` block that follows a python block with only blank lines between them holds
  that block's expected standard output.  Lines are compared one by one after stripping trailing
  blanks; within a line, numbers are compared with a relative tolerance (``RTOL``, or the value of
  ``rtol=`` on the fence line, e.g. ```` ```text rtol=0.1 ````) and an absolute tolerance (``ATOL``,
  or ``atol=``), everything else exactly.  An expected line ``...`` matches any number of output
  lines, and ``...`` inside a line matches any text.
* A page whose python blocks mention ``shared/data`` (the real recordings, ``../shared/data``
  beside the checkout) is skipped when that directory is absent.

Failures name the page and the block's first line (tracebacks point at the page's own line numbers).
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data"
TIMEOUT = 300
RTOL = 0.02
ATOL = 0.0
_FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```[ \t]*$", re.M | re.S)
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_SEPARATOR = "=====phs-doc-block-end====="

# runs in the subprocess: blocks in order, one namespace, a separator after each block's output
_DRIVER = """
import json, sys
sys.path.insert(0, {root!r})
blocks = json.loads(open(sys.argv[1], encoding="utf-8").read())
ns = {{"__name__": "__main__"}}
for path, line, code in blocks:
    exec(compile("\\n" * (line - 1) + code, path, "exec"), ns)
    sys.stdout.flush()
    print({sep!r}, flush=True)
"""


def _pages() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def blocks_of(text: str) -> list[dict]:
    """The fenced python blocks of a page with their first line and the expected output if any.

    Examples
    --------
    >>> page = "# T\\n\\n```python\\nprint(1 + 1)\\n```\\n\\n```text\\n2\\n```\\n"
    >>> blocks_of(page)
    [{'line': 4, 'code': 'print(1 + 1)\\n', 'expected': '2\\n', 'rtol': 0.02, 'atol': 0.0}]
    """
    fences = list(_FENCE.finditer(text))
    out = []
    for i, m in enumerate(fences):
        if m.group(1).strip() != "python":
            continue
        block = {"line": text.count("\n", 0, m.start(2)) + 1, "code": m.group(2), "expected": None, "rtol": RTOL, "atol": ATOL}
        nxt = fences[i + 1] if i + 1 < len(fences) else None
        if nxt is not None and text[m.end():nxt.start()].strip() == "":
            info = nxt.group(1).split()
            if info and info[0] == "text":
                opts = dict(o.split("=", 1) for o in info[1:] if "=" in o)
                block.update(expected=nxt.group(2), rtol=float(opts.get("rtol", RTOL)), atol=float(opts.get("atol", ATOL)))
        out.append(block)
    return out


def _line_matches(expected: str, actual: str, rtol: float, atol: float) -> bool:
    parts = [p for p in re.split(r"(\.\.\.|" + _NUMBER.pattern + ")", expected) if p]
    pattern, numbers = "", []
    for p in parts:
        if p == "...":
            pattern += ".*?"
        elif _NUMBER.fullmatch(p):
            pattern += "(" + _NUMBER.pattern + ")"
            numbers.append(float(p))
        else:
            pattern += re.escape(p)
    m = re.fullmatch(pattern, actual)
    if m is None:
        return False
    return all(math.isclose(float(got), want, rel_tol=rtol, abs_tol=atol) for got, want in zip(m.groups(), numbers))


def output_matches(expected: str, actual: str, rtol: float = RTOL, atol: float = ATOL) -> bool:
    """Whether printed output ``actual`` matches the page's ``expected`` (see the module docstring).

    Examples
    --------
    >>> output_matches("error 7e-07\\n...\\nV_pi = 37.34 V", "error 7.04e-07\\nmore\\nlines\\nV_pi = 37.343 V")
    True
    >>> output_matches("error 7e-07", "error 1.8e-04")
    False
    """
    exp = [ln.rstrip() for ln in expected.strip("\n").splitlines()]
    act = [ln.rstrip() for ln in actual.strip("\n").splitlines()]

    def match(i: int, j: int) -> bool:
        if i == len(exp):
            return j == len(act)
        if exp[i] == "...":
            return any(match(i + 1, k) for k in range(j, len(act) + 1))
        return j < len(act) and _line_matches(exp[i], act[j], rtol, atol) and match(i + 1, j + 1)

    return match(0, 0)


def _page_params():
    for page in _pages():
        blocks = blocks_of(page.read_text(encoding="utf-8"))
        if blocks:
            yield pytest.param(page, blocks, id=str(page.relative_to(ROOT)))


@pytest.mark.parametrize(("page", "blocks"), list(_page_params()))
def test_page_blocks_run_and_print_what_the_page_says(page, blocks, tmp_path):
    if any("shared/data" in b["code"] for b in blocks) and not DATA.is_dir():
        pytest.skip(f"{page.name} needs the recordings in {DATA}")
    rel = str(page.relative_to(ROOT))
    (tmp_path / "blocks.json").write_text(json.dumps([[str(page), b["line"], b["code"]] for b in blocks]))
    (tmp_path / "driver.py").write_text(_DRIVER.format(root=str(ROOT), sep=_SEPARATOR))
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    work = tmp_path / "cwd"
    work.mkdir()
    proc = subprocess.run([sys.executable, str(tmp_path / "driver.py"), str(tmp_path / "blocks.json")],
                          capture_output=True, text=True, env=env, cwd=work, timeout=TIMEOUT)
    outputs = proc.stdout.split(_SEPARATOR + "\n")
    if proc.returncode != 0:
        failed = blocks[len(outputs) - 1]
        pytest.fail(f"{rel}: the python block at line {failed['line']} fails:\n{proc.stderr[-3000:]}")
    for block, out in zip(blocks, outputs):
        if block["expected"] is not None:
            assert output_matches(block["expected"], out, block["rtol"], block["atol"]), (
                f"{rel}: the block at line {block['line']} prints\n{out}\nbut the page says\n{block['expected']}")


def test_every_fence_of_the_pages_states_its_language():
    """An unlabelled fence would be neither run nor clearly marked as not runnable."""
    bare = [f"{p.relative_to(ROOT)}:{p.read_text(encoding='utf-8').count(chr(10), 0, m.start()) + 1}"
            for p in _pages() for m in _FENCE.finditer(p.read_text(encoding="utf-8")) if not m.group(1).strip()]
    assert not bare, f"fenced blocks without a language: {bare}"
