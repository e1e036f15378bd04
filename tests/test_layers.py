"""The house: imports run one way between the layers, no import circles, modules of readable size.

The layers (docs/architecture.md), bottom to top:

* ``phs`` core: every module of ``phs/`` outside ``phs/workflows/``;
* ``components`` and ``codegen``, each above the core and independent of each other;
* ``systems``, above ``components``;
* ``phs.workflows``, on top: it may import everything.

The import graph is read from the source files with :mod:`ast` (imports inside functions count).
The one door upward is the lazy ``__getattr__`` (and ``__dir__``) of ``phs/__init__.py``, which
loads workflow functions on first use; imports inside those two functions are not edges.
An import of ``a.b.c`` is an edge to the module ``a/b/c.py`` (or package ``a/b/c/__init__.py``),
not to the packages above it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("phs", "components", "systems", "codegen")
ALLOWED = {
    "phs": {"phs"},
    "components": {"phs", "components"},
    "codegen": {"phs", "codegen"},
    "systems": {"phs", "components", "systems"},
    "workflows": {"phs", "components", "codegen", "systems", "workflows"},
}
# the lazy door of phs/__init__.py: workflow functions loaded on first use
DOOR = {("phs", "__getattr__"), ("phs", "__dir__")}
MAX_LINES = 600
# modules allowed above MAX_LINES, with the reason
LONGER: dict[str, str] = {}


def modules(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for the project's packages under ``root``."""
    found = {}
    for pkg in PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def layer(module: str) -> str:
    return "workflows" if module == "phs.workflows" or module.startswith("phs.workflows.") else module.split(".")[0]


def import_edges(root: Path) -> dict[str, dict[str, int]]:
    """Module -> {imported project module: line}, imports inside functions included, the door excluded."""
    mods = modules(root)

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, dict[str, int]] = {}
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        skip: set[int] = set()
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and (mod, node.name) in DOOR:
                skip.update(id(n) for n in ast.walk(node))
        out: dict[str, int] = {}
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
                    for _ in range(node.level - 1):
                        base = base.rpartition(".")[0]
                    src = base + ("." + node.module if node.module else "")
                else:
                    src = node.module or ""
                # ``from pkg import sub`` runs ``pkg/__init__`` first: it depends on the package too
                targets = [src] + [f"{src}.{a.name}" for a in node.names if f"{src}.{a.name}" in mods]
            for t in targets:
                r = resolve(t)
                if r and r != mod:
                    out.setdefault(r, node.lineno)
        edges[mod] = out
    return edges


def upward_imports(edges) -> list[str]:
    return [f"{a} (line {line}) imports {b}: {layer(a)} may import only {sorted(ALLOWED[layer(a)])}"
            for a in sorted(edges) for b, line in sorted(edges[a].items()) if layer(b) not in ALLOWED[layer(a)]]


def circles(edges) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on, stack, found, counter = {}, {}, set(), [], [], [0]
    for start in sorted(edges):
        if start in index:
            continue
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in edges:
                    continue
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_no_upward_import():
    assert upward_imports(import_edges(ROOT)) == []


def test_no_import_circle():
    assert circles(import_edges(ROOT)) == []


def test_modules_readable_at_one_sitting():
    long = {m: n for m, p in modules(ROOT).items() if (n := len(p.read_text().splitlines())) > MAX_LINES and m not in LONGER}
    assert long == {}, f"modules over {MAX_LINES} lines (split by idea, or list in LONGER with the reason): {long}"


# -- the checks fail when they should ------------------------------------------------------------


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir(exist_ok=True)
        (tmp_path / pkg / "__init__.py").touch()
    return tmp_path


def test_a_circle_through_a_function_level_import_is_found(tmp_path):
    root = _tree(tmp_path, {"phs/a.py": "from phs.b import f\n", "phs/b.py": "def f():\n    from phs import a\n"})
    assert circles(import_edges(root)) == [["phs.a", "phs.b"]]


def test_a_relative_import_circle_is_found(tmp_path):
    root = _tree(tmp_path, {"codegen/x/__init__.py": "from .y import g\n", "codegen/x/y.py": "from codegen.x import z\n",
                            "codegen/x/z.py": "from . import y\n"})
    assert circles(import_edges(root)) == [["codegen.x", "codegen.x.y", "codegen.x.z"]]


@pytest.mark.parametrize("source, target, text", [
    ("phs/core.py", "codegen", "import codegen\n"),
    ("phs/core.py", "phs.workflows", "def f():\n    from phs.workflows.run import go\n"),
    ("components/c.py", "codegen", "from codegen.sim import run\n"),
    ("codegen/g.py", "components", "from components import Mass\n"),
    ("codegen/g.py", "systems", "def f():\n    import systems\n"),
    ("systems/s.py", "codegen", "from codegen import simulate\n"),
])
def test_an_upward_import_is_found(tmp_path, source, target, text):
    root = _tree(tmp_path, {source: text, "phs/workflows/__init__.py": "", "phs/workflows/run.py": "", "codegen/sim.py": ""})
    found = upward_imports(import_edges(root))
    assert len(found) == 1 and target in found[0], found


def test_the_lazy_door_is_the_only_exception(tmp_path):
    door = "def __getattr__(name):\n    from phs.workflows.run import go\n    return go\n"
    root = _tree(tmp_path, {"phs/workflows/__init__.py": "", "phs/workflows/run.py": "import phs\n"})
    (root / "phs" / "__init__.py").write_text(door)
    assert upward_imports(import_edges(root)) == [] and circles(import_edges(root)) == []
    (root / "phs" / "other.py").write_text(door)
    assert len(upward_imports(import_edges(root))) == 1
