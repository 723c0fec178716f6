"""What several test modules share, as plain functions and constants (the shared fixtures are in
tests/conftest.py). Test modules import from here, never from one another (tests/test_test_layout.py).

- `tests.helpers`: the repository root, the text of a PDF, scripts/mlflow_ui_check.py as a module
- `tests.helpers.cli`: `python -m hgm_repro` in a subprocess, and the store a launch leaves
- `tests.helpers.learner`: tiny job configs and a metrics recorder for in-process training
- `tests.helpers.sim`: simulators and hand-placed traffic situations
- `tests.helpers.servers`: throwaway PostgreSQL and MLflow servers for the integration tests
"""

from __future__ import annotations

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]


def pdf_text(path: Path) -> str:
    """The text of every page, whitespace collapsed: where a table cell or a paragraph wraps is a layout detail."""
    from pypdf import PdfReader

    return " ".join(" ".join(page.extract_text() or "" for page in PdfReader(str(path)).pages).split())


def ui_check_script():
    """scripts/mlflow_ui_check.py as a module (it is a script, not part of a package); its server
    helpers serve the integration tests too."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("mlflow_ui_check", REPO_ROOT / "scripts" / "mlflow_ui_check.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
