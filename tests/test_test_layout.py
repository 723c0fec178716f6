"""The tests' own layout: one folder per package they test, the shared fixtures in tests/conftest.py, the
shared helpers in tests/helpers/, and no test module importing another test module (or a conftest)."""

from __future__ import annotations

import ast
from pathlib import Path

from tests.helpers import REPO_ROOT

TESTS = REPO_ROOT / "tests"
# Folders of tests/ that are not one package's tests: the shared helpers, and the tests that need
# real services (PostgreSQL, an MLflow server, SLURM, Ray, Chromium).
NOT_A_PACKAGE = {"helpers", "integration"}


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imported_names(path: Path, module: str) -> set[str]:
    """Every module name `path` (the module `module`) imports, anywhere in the file, relative ones
    resolved; `from a import b` gives both `a` and `a.b`, for `b` may be a module."""
    here = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = here[: len(here) - node.level + 1] if node.level else []
            source = ".".join(base + ([node.module] if node.module else []))
            found |= {source} | {f"{source}.{alias.name}" for alias in node.names}
    return found


def cross_imports(root: Path) -> list[str]:
    """'<file>: <name>' for each import, in a tests/**/test_*.py under `root`, of a test module or of a
    conftest, whether by its package path, relatively or by its bare name (pytest's rootdir on sys.path)."""
    modules = {_module_name(p, root): p for p in sorted((root / "tests").rglob("test_*.py"))}
    bare = {m.rsplit(".", 1)[-1] for m in modules} | {"conftest"}
    found = []
    for module, path in modules.items():
        for name in sorted(imported_names(path, module)):
            parts = name.split(".")
            if parts[0] in bare or "conftest" in parts or any(
                    name == m or name.startswith(m + ".") for m in modules):
                found.append(f"{path.relative_to(root)}: {name}")
    return found


def test_conftest_holds_the_shared_fixtures_and_helpers_are_a_package():
    assert (TESTS / "conftest.py").is_file()
    assert (TESTS / "helpers" / "__init__.py").is_file()


def test_no_test_module_imports_another():
    assert cross_imports(REPO_ROOT) == []


def test_the_checker_sees_every_way_to_import_a_test_module(tmp_path):
    (tmp_path / "tests" / "a").mkdir(parents=True)
    (tmp_path / "tests" / "helpers").mkdir()
    for package in ("tests", "tests/a", "tests/helpers"):
        (tmp_path / package / "__init__.py").write_text("")
    (tmp_path / "tests" / "helpers" / "cli.py").write_text("")
    (tmp_path / "tests" / "test_top.py").write_text("from tests.helpers.cli import hgm\nfrom . import helpers\n")
    (tmp_path / "tests" / "a" / "test_one.py").write_text(
        "from .test_two import x\n"
        "from ..test_top import y\n"
        "from tests.a import test_two\n"
        "import tests.test_top\n"
        "from ..conftest import z\n"
        "def f():\n    from test_top import w\n")
    (tmp_path / "tests" / "a" / "test_two.py").write_text("from tests.helpers import cli\nimport os.path\n")
    assert cross_imports(tmp_path) == [
        "tests/a/test_one.py: test_top",
        "tests/a/test_one.py: test_top.w",
        "tests/a/test_one.py: tests.a.test_two",
        "tests/a/test_one.py: tests.a.test_two.x",
        "tests/a/test_one.py: tests.conftest",
        "tests/a/test_one.py: tests.conftest.z",
        "tests/a/test_one.py: tests.test_top",
        "tests/a/test_one.py: tests.test_top.y",
    ]


def test_each_test_folder_is_named_after_a_package_and_is_a_package_itself():
    folders = [d for d in sorted(TESTS.iterdir()) if d.is_dir() and not d.name.startswith((".", "__"))]
    assert folders
    for folder in folders:
        # A package of hgm_repro (tests/learner/) or of the repository (tests/analysis/, tests/scripts/).
        assert folder.name in NOT_A_PACKAGE or (REPO_ROOT / "hgm_repro" / folder.name).is_dir() or \
            (REPO_ROOT / folder.name).is_dir(), folder.name
        # Test modules are tests.<folder>.<name>: duplicate file names in two folders stay apart.
        assert (folder / "__init__.py").is_file(), folder.name
