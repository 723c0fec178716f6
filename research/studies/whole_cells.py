"""A copy of a results store that holds only what is whole, to publish from.

A study store fills cell by cell, and a study stopped part-way leaves a model with fewer tests than its grid.
Publishing such a store as it is would replace that model's published rows in docs/results with the part
(combining bundles replaces each model's rows), so a study publishes from a copy cut to what is whole:

- a model's tests are kept when it has all `--cells` (scenario, seed) cells, else dropped with its trainings
  (so that combining keeps its published rows);
- a `<host>_safest` model keeps each seed tested in all `--scenarios` scenarios (a refused seed has none);
- a training run is kept when it finished and a kept test tested it.

    python research/studies/whole_cells.py STORE.db COPY.db [--cells 25] [--scenarios 5] [--dry-run]

The copy is made with SQLite's online backup (a store being written waits up to a minute for its lock); the
source is never changed. Each model's count and what is dropped are printed.
"""

from __future__ import annotations

import argparse
import sqlite3
import sys
from collections import defaultdict
from pathlib import Path

EXPERIMENT = "hgm_repro"
SAFEST_SUFFIX = "_safest"


def copy_store(source: Path, target: Path) -> None:
    """`target`, a consistent copy of the SQLite store `source` (written or not at the time)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    target.unlink(missing_ok=True)
    src, dst = sqlite3.connect(f"file:{source}?mode=ro", uri=True, timeout=60), sqlite3.connect(target)
    try:
        src.backup(dst)
    finally:
        src.close()
        dst.close()


def partial(runs: list, cells: int, scenarios: int) -> tuple[list, list[str]]:
    """The runs to drop from `runs` (MLflow runs of one experiment) and one line per model saying why."""
    tests = [r for r in runs if r.data.tags.get("stage") == "eval" and r.info.status == "FINISHED"]
    by_model: dict[str, list] = defaultdict(list)
    for run in tests:
        by_model[run.data.tags.get("model", "")].append(run)
    drop, lines, dropped_models = [], [], set()
    for model, mine in sorted(by_model.items()):
        held = {(r.data.tags.get("scenario"), r.data.tags.get("seed")) for r in mine}
        if model.endswith(SAFEST_SUFFIX):
            per_seed: dict[str, set] = defaultdict(set)
            for scenario, seed in held:
                per_seed[seed].add(scenario)
            short = {seed for seed, got in per_seed.items() if len(got) < scenarios}
            drop += [r for r in mine if r.data.tags.get("seed") in short]
            lines.append(f"{model}: seeds kept {sorted(set(per_seed) - short)}, dropped {sorted(short)}")
        elif len(held) < cells:
            drop += mine
            dropped_models.add(model)
            lines.append(f"{model}: {len(held)} of {cells} cells, dropped with its trainings")
        else:
            lines.append(f"{model}: {len(held)} cells, kept")
    kept_keys = {r.data.tags.get("train_key") for r in tests if r not in drop}
    for run in runs:
        if run.data.tags.get("stage") != "train":
            continue
        if (run.info.status != "FINISHED" or run.data.tags.get("model") in dropped_models
                or run.data.tags.get("train_key") not in kept_keys):
            drop.append(run)
            lines.append(f"training dropped: {run.data.tags.get('model')} seed {run.data.tags.get('seed')} "
                         f"({run.info.status})")
    return drop, lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("store", type=Path, help="the study's mlflow.db")
    parser.add_argument("copy", type=Path, help="where the cut copy goes (replaced)")
    parser.add_argument("--cells", type=int, default=25, help="a model's whole grid (default: %(default)s)")
    parser.add_argument("--scenarios", type=int, default=5, help="a safest seed's whole set (default: %(default)s)")
    parser.add_argument("--dry-run", action="store_true", help="print what would be dropped; change nothing")
    args = parser.parse_args(argv)
    if not args.store.is_file():
        print(f"whole_cells.py: no store at {args.store}", file=sys.stderr)
        return 2
    if args.cells < 1 or args.scenarios < 1:
        print(f"whole_cells.py: --cells {args.cells} and --scenarios {args.scenarios} must be at least 1",
              file=sys.stderr)
        return 2
    from mlflow import MlflowClient
    from mlflow.entities import ViewType

    copy_store(args.store, args.copy)
    client = MlflowClient(tracking_uri=f"sqlite:///{args.copy.resolve()}")
    experiment = client.get_experiment_by_name(EXPERIMENT)
    if experiment is None:
        print(f"whole_cells.py: {args.store} holds no experiment '{EXPERIMENT}'", file=sys.stderr)
        return 2
    runs, token = [], None
    while True:
        page = client.search_runs([experiment.experiment_id], run_view_type=ViewType.ACTIVE_ONLY,
                                  max_results=1000, page_token=token)
        runs += list(page)
        token = page.token
        if not token:
            break
    drop, lines = partial(runs, args.cells, args.scenarios)
    print("\n".join(lines))
    print(f"{len(drop)} of {len(runs)} runs dropped{' (dry run)' if args.dry_run else ''}")
    if not args.dry_run:
        for run in drop:
            client.delete_run(run.info.run_id)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
