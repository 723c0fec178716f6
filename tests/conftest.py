"""Fixtures shared by the test modules. Plain helpers (functions, constants) are in `tests.helpers`;
no test module imports another one (tests/test_test_layout.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import torch


@pytest.fixture
def one_thread() -> Iterator[None]:
    """Torch on one thread for the test: runs of many small ops (small tensors stepped many times) are
    several times faster on a loaded 2-core machine than with threads competing for the cores."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
