"""Where a run's code and person come from: the git commit, MLflow's source tags, and the tags of a
job's runs and of a launch's parent run."""

from __future__ import annotations

import getpass
import os
import subprocess
from functools import lru_cache
from pathlib import Path

from ..contracts.conf_dir import PACKAGE_ROOT
from ..contracts.schema import JobConfig

SOURCE_NAME = "python -m hgm_repro"
# Tracked folders whose edits cannot change a run: documentation and the published results.
DOCS_NOT_RUN = ("docs",)


def git_info(repo_root: Path = PACKAGE_ROOT.parent) -> tuple[str, str]:
    """(commit, dirty) of the code that runs; ('unknown', 'unknown') outside a checkout.

    `dirty` ignores tracked changes under DOCS_NOT_RUN: the publish scripts rewrite docs/results in the
    checkout they run from, which never changes what runs, and used to flag every later run dirty."""

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(repo_root), *args], capture_output=True, text=True, check=True, timeout=20
        ).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        changed = git("status", "--porcelain", "--untracked-files=no", "--", ".",
                      *(f":(exclude){d}" for d in DOCS_NOT_RUN))
        dirty = "true" if changed else "false"
        return commit, dirty
    except (OSError, subprocess.SubprocessError):
        return "unknown", "unknown"


@lru_cache(maxsize=1)
def source_tags() -> dict[str, str]:
    """MLflow's standard tags for the code and person behind a run (the UI's Source and User)."""
    commit, _ = git_info()
    tags = {"mlflow.source.name": SOURCE_NAME, "mlflow.source.type": "LOCAL", "mlflow.user": _user()}
    if commit != "unknown":
        tags["mlflow.source.git.commit"] = commit
    return tags


def _user() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no passwd entry (some containers)
        return str(os.getuid()) if hasattr(os, "getuid") else "unknown"


def run_tags(job: JobConfig, key: str) -> dict[str, str]:
    """Tags of a job's training and evaluation runs (each adds its `stage` and `scenario`)."""
    commit, dirty = git_info()
    return {"model": job.model.name, "seed": str(job.seed), "train_key": key, "git_commit": commit,
            "git_dirty": dirty, "preset": job.experiment.name, "device": job.device}


def launch_tags(kind: str, overrides: str) -> dict[str, str]:
    """Tags of a launch's parent run. No `stage` tag: analysis reads only train and eval runs."""
    commit, dirty = git_info()
    return {"launch": kind, "sweep": str(kind == "sweep").lower(), "overrides": overrides[:5000],
            "git_commit": commit, "git_dirty": dirty}

