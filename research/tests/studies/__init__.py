"""Tests of the study scripts under research/studies/."""

from __future__ import annotations

import importlib.util
from types import ModuleType

from tests.helpers import REPO_ROOT


def load_study(name: str) -> ModuleType:
    """research/studies/<name>.py as a module (the scripts are not a package)."""
    spec = importlib.util.spec_from_file_location(name, REPO_ROOT / "research" / "studies" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
