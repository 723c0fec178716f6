"""The package's floors: every import (function-local ones included) points down or sideways, never
up, and no two modules import each other, directly or around a loop; `research/studies/` has no loop either."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.helpers import REPO_ROOT

# The floors of docs/architecture (a module may import its own floor and the ones below).
FLOORS = {
    "contracts": 0,
    "simulator": 1,
    "observations": 2,
    "envs": 3,
    "models": 3,
    "evaluation": 4,
    "learner": 4,
    "app": 5,
}
TOOLS = 6  # the package face, the entry point, bench and show


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, module: str, package: str) -> set[str]:
    """Every module of `package` that `path` imports, anywhere in the file."""
    found: set[str] = set()
    here = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            # `from pkg import mod` imports the module `pkg.mod` too: name it, so that a loop through it shows.
            # A name that is no module (`from pkg import some_function`) is dropped by `import_graph`.
            names = [source, *(f"{source}.{alias.name}" for alias in node.names)]
        else:
            continue
        found |= {name for name in names if name == package or name.startswith(package + ".")}
    return found


def import_graph(root: Path, package: str) -> dict[str, set[str]]:
    """Each module of `package` under `root` and the modules of `package` it imports."""
    paths = sorted((root / package.replace(".", "/")).rglob("*.py"))
    modules = {_module_name(p, root) for p in paths}
    return {_module_name(p, root): {name for name in _imports(p, _module_name(p, root), package)
                                    if name in modules or name == package}
            for p in paths}


def floor(module: str) -> int:
    parts = module.split(".")
    return FLOORS.get(parts[1], TOOLS) if len(parts) > 1 else TOOLS


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected set of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_the_graph_reader_sees_local_and_relative_imports(tmp_path):
    (tmp_path / "pkg" / "low").mkdir(parents=True)
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "low" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "low" / "a.py").write_text("def f():\n    from ..high import b\n")
    (tmp_path / "pkg" / "high.py").write_text("from .low import a\n")
    (tmp_path / "pkg" / "side.py").write_text("from pkg import high, low\nfrom pkg.low import a, f\n")
    graph = import_graph(tmp_path, "pkg")
    assert graph["pkg.low.a"] == {"pkg.high"}
    assert graph["pkg.high"] == {"pkg.low", "pkg.low.a"}
    assert graph["pkg.side"] == {"pkg", "pkg.high", "pkg.low", "pkg.low.a"}  # `f` is no module: no edge
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_points_to_a_higher_floor():
    upward = [f"{a} (floor {floor(a)}) imports {b} (floor {floor(b)})"
              for a, targets in import_graph(REPO_ROOT, "hgm_repro").items() for b in sorted(targets)
              if floor(b) > floor(a)]
    assert not upward, "\n".join(upward)


@pytest.mark.parametrize("package", ["hgm_repro", "research.studies", "analysis"])
def test_no_import_cycle(package):
    graph = import_graph(REPO_ROOT, package)
    if package == "research.studies":  # scripts import each other by their bare names (their folder is on sys.path)
        names = {m.split(".")[-1] for m in graph}
        for path in (REPO_ROOT / "research" / "studies").glob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and node.module in names and not node.level:
                    graph[_module_name(path, REPO_ROOT)].add(f"research.studies.{node.module}")
                elif isinstance(node, ast.Import):
                    graph[_module_name(path, REPO_ROOT)] |= {f"research.studies.{a.name}" for a in node.names
                                                             if a.name in names}
    assert not cycles(graph)



@pytest.mark.parametrize("package", ["hgm_repro", "analysis", "baselines"])
def test_the_product_never_imports_research(package):
    """research/ is the lab notebook beside the product: the wheel does not ship it."""
    reaching = [str(path.relative_to(REPO_ROOT)) for path in sorted((REPO_ROOT / package).rglob("*.py"))
                if _imports(path, _module_name(path, REPO_ROOT), "research")]
    assert reaching == []
