"""The package's import graph: every module imports alone, and imports run one way.

Imports inside functions count: a lazy import hides a cycle from the
interpreter but not from a reader (``runner`` -> ``estimate`` ->
``sampling`` -> ``runner`` was one).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "bayesgloss"


def modules() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the package."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def imported(name: str, path: Path, known) -> set[str]:
    """Modules of the package that ``name`` imports anywhere in its file."""
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            # "from . import x" names modules; "from .m import f" names m
            targets = [f"{base}.{a.name}" for a in node.names] + [base]
        else:
            continue
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


def import_graph() -> dict[str, set[str]]:
    known = modules()
    graph = {name: imported(name, path, known) for name, path in known.items()}
    # a package's own __init__ importing its submodules is its table of contents,
    # not a dependency of theirs on it: submodule -> package edges are dropped
    for name in graph:
        graph[name] = {t for t in graph[name] if not name.startswith(t + ".")}
    return graph


def cycle(graph) -> list[str] | None:
    """One cycle of the graph, or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m) :] + [m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return None


def test_the_import_graph_has_no_cycle():
    graph = import_graph()
    assert "bayesgloss.sampling.posterior" in graph and "bayesgloss.diagnostics" in graph
    assert cycle(graph) is None, " -> ".join(cycle(graph))


def test_the_cycle_finder_finds_the_old_cycle():
    # the checker itself must be able to fail: the cycle this project once had
    old = {"runner": {"estimate"}, "estimate": {"sampling"}, "sampling": {"runner"}, "x": set()}
    assert cycle(old) == ["estimate", "sampling", "runner", "estimate"]


def test_leaf_modules_import_nothing_of_bayesgloss():
    # the process pool, the diagnostics and the quiet third-party imports are
    # used across the inference layer and must not pull it back in
    graph = import_graph()
    leaves = ("pool", "diagnostics", "_thirdparty", "gamma_interval", "intervals", "sampling.moves")
    for leaf in leaves:
        assert graph[f"bayesgloss.{leaf}"] == set(), (leaf, graph[f"bayesgloss.{leaf}"])


def test_inference_modules_stay_small():
    # the inference layer split by stage: no module of it above about 600 lines
    layer = ["likelihood", "estimate", "pooling", "compare", "evidence", "loo", "diagnostics"]
    layer += ["runner", "summary"]
    layer += [p.stem for p in (PACKAGE / "sampling").glob("*.py")]
    sizes = {}
    for name in layer:
        path = PACKAGE / f"{name}.py"
        path = path if path.exists() else PACKAGE / "sampling" / f"{name}.py"
        sizes[name] = len(path.read_text().splitlines())
    assert max(sizes.values()) <= 640, sizes


@pytest.mark.parametrize("name", sorted(modules()))
def test_each_module_imports_alone(name):
    # in a fresh interpreter, with warnings as errors: no module needs another
    # to have been imported first, and none warns on import
    proc = subprocess.run(
        [sys.executable, "-W", "error", "-c", f"import {name}"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
