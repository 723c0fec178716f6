"""What a newcomer meets in the MLflow UI: the links a job logs open the evaluations as a table and
the training curves as charts (shared views stored on the experiment), checked in a real browser
by scripts/mlflow_ui_check.py (integration: needs Debian's chromium)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hgm_repro.app.store import (
    CURVES_VIEW,
    GRID_VIEW,
    SHARED_VIEW_TAG,
    SHARED_VIEWS,
    StoreLocation,
    Tracker,
    resolve_location,
)
from hgm_repro.app.sweep import _sweep_time
from tests.helpers import ui_check_script


def _location(launch: Path) -> StoreLocation:
    return resolve_location({"uri": None, "artifact_dir": None, "checkpoint_dir": None}, launch)


def make_store(launch: Path, seeds: tuple[int, ...] = (0, 1)) -> Tracker:
    """A store shaped like a sweep's: a launch run over trainings (train/ and val/ curves) and
    evaluations (eval/ means), for two models, two scenarios and `seeds`."""
    tracker = Tracker(_location(launch), "hgm_repro")
    parent = tracker.start_run("sweep 2026-12-02 10:00:00", {"launch": "sweep", "sweep": "true"})
    for model in ("proposed", "min"):
        for seed in seeds:
            key = f"{model[:3]}{seed}"
            train = tracker.start_run(f"{model} seed{seed} training {key}", {
                "stage": "train", "model": model, "seed": seed, "scenario": "train", "train_key": key}, parent)
            for step in (64, 128, 192, 256):
                tracker.log_metrics(train, {"train/episode_return": step / 10 + seed, "train/epsilon": 1 - step / 300,
                                            "val/episode_return": step / 20}, step)
            tracker.end(train)
            for scenario in ("1", "3"):
                run = tracker.start_run(f"{model} seed{seed} scenario{scenario} eval", {
                    "stage": "eval", "model": model, "seed": seed, "scenario": scenario, "train_key": key,
                    "train_run_id": train}, parent)
                tracker.log_metrics(run, {"eval/episode_return": 10.5 * (seed + 1) + int(scenario),
                                          "eval/collisions": 0.25 * seed, "eval/avg_speed_kmh": 60.0 + seed}, 0)
                tracker.end(run)
    tracker.summarise_launch(parent, "A sweep.")
    tracker.end(parent)
    return tracker


def test_the_experiment_carries_the_views_the_links_open(tmp_path: Path) -> None:
    tracker = make_store(tmp_path, seeds=(0,))
    tags = tracker.client.get_experiment(tracker.experiment_id).tags
    envelope = json.loads(tags[SHARED_VIEW_TAG + GRID_VIEW])  # what MLflow's Views menu lists
    assert isinstance(envelope["name"], str) and isinstance(envelope["createdAt"], int)
    grid = json.loads(envelope["state"])
    assert grid == SHARED_VIEWS[GRID_VIEW] and grid["searchFilter"] == "tags.stage = 'eval'"
    # Sorted by something other than the start time, the filtered runs are listed flat, not folded.
    assert grid["orderByKey"] != "attributes.start_time"
    assert {"tags.`model`", "tags.`scenario`", "tags.`seed`", "metrics.`eval/episode_return`",
            "metrics.`eval/collisions`"} <= set(grid["selectedColumns"])
    curves = json.loads(json.loads(tags[SHARED_VIEW_TAG + CURVES_VIEW])["state"])
    assert curves["searchFilter"] == "tags.stage = 'train'"
    url = tracker.ui_url()
    assert url.endswith(f"/runs?workflowType=machine_learning&viewStateShareKey={GRID_VIEW}")
    assert "compareRunsMode=CHART" in tracker.ui_url(CURVES_VIEW)
    # Run links open the model-training layout, whatever the browser last chose.
    assert "workflowType=machine_learning" in tracker.run_link("abc", "run")


def test_launch_summary_is_a_table_not_metrics(tmp_path: Path) -> None:
    """Per-cell metrics on the launch run would come before train/ in the chart view: none are logged."""
    tracker = make_store(tmp_path, seeds=(0, 1))
    (parent,) = tracker.search("tags.launch = 'sweep'")
    assert parent.data.metrics == {}
    assert "| proposed | 3 | 2 | 18.75 | 60.5 | 0.125 |" in parent.data.tags["mlflow.note.content"]


def test_sweep_runs_are_named_with_date_and_time() -> None:
    assert _sweep_time(Path("multirun/2026-12-02/22-11-36")) == "2026-12-02 22:11:36"
    assert _sweep_time(Path("/somewhere/my_sweep")) == "my_sweep"


@pytest.mark.integration
def test_a_browser_sees_every_evaluation_as_a_row_and_charts_open_on_training(tmp_path: Path) -> None:
    check = ui_check_script()
    if check.chromium() is None:
        pytest.skip("needs chromium (Debian: apt-get install chromium)")
    make_store(tmp_path)
    with check.served(tmp_path) as base:
        assert check.check_grid(tmp_path, base) == []
        assert check.check_curves(tmp_path, base) == []


def test_the_table_parser_reads_cells_by_row_and_column() -> None:
    dom = ('<div class="ag-row x" row-id="r1"><div class="ag-cell" col-id="tags.`model`"><span>min</span></div>'
           '<div class="ag-cell" col-id="metrics.`eval/collisions`">0.5</div></div>'
           '<div class="ag-row" row-id="r1"><div class="ag-cell" col-id="tags.`seed`">1<br></div></div>')
    assert ui_check_script().table_rows(dom) == {"r1": {"tags.`model`": "min", "metrics.`eval/collisions`": "0.5",
                                                      "tags.`seed`": "1"}}
