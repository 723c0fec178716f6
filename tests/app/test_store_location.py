"""A SQLite store named by tracking.uri is kept like the default store: artifacts beside it."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from hgm_repro.app.store import resolve_location


def test_a_named_sqlite_store_keeps_its_artifacts_beside_it(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        location = resolve_location({"uri": f"sqlite:///{tmp_path}/new/dir/x.db"}, tmp_path / "launch")
    assert (tmp_path / "new" / "dir").is_dir()  # made, and said so
    assert "creating the missing directory" in caplog.text and "x.db" in caplog.text
    assert location.tracking_uri == f"sqlite:///{tmp_path}/new/dir/x.db"
    assert location.artifact_location == (tmp_path / "new" / "dir" / "mlartifacts").as_uri()
    assert location.lock_path == tmp_path / "new" / "dir" / "x.db.lock"


def test_a_relative_sqlite_store_is_under_the_launch_directory(tmp_path: Path) -> None:
    location = resolve_location({"uri": "sqlite:///runs/x.db"}, tmp_path)
    assert location.tracking_uri == f"sqlite:///{tmp_path}/runs/x.db"
    assert location.artifact_location == (tmp_path / "runs" / "mlartifacts").as_uri()


def test_a_reader_does_not_make_directories(tmp_path: Path) -> None:
    resolve_location({"uri": f"sqlite:///{tmp_path}/absent/x.db"}, tmp_path, create=False)
    assert not (tmp_path / "absent").exists()
