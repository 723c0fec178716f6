"""Trainings under way: a training stopped by a signal (its run KILLED, to be resumed) is read from the store
with the steps it reached and the hours it trained, travels in the bundle, and the scale-ladder page says per
rung which seeds are tested, stopped and missing, and the hours of training left."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd
import pytest
from mlflow import MlflowClient
from mlflow.entities import Metric, Param

from analysis import ladder, ladder_figure
from analysis.bundle import MANIFEST, load_bundle, write_bundle
from analysis.combine import combine
from analysis.costs import hours_trained, slowest_rate
from analysis.labels import LEARNED
from analysis.load import STOPPED_COLUMNS, StoreData, load_store
from analysis.scenarios import with_cv_ratio
from analysis.synthetic import SyntheticSpec, synthetic_frames, write_store


def add_training(uri: str, status: str, seed: int, key: str, rates: list[tuple[int, float]],
                 resumes: str | None = None) -> str:
    """A paper_steps training run of the proposed host, ended with `status`, that logged `rates` (step, env
    steps per second)."""
    client = MlflowClient(tracking_uri=uri)
    exp_id = client.get_experiment_by_name("hgm_repro").experiment_id
    tags = {"stage": "train", "model": "proposed", "seed": str(seed), "scenario": "train", "train_key": key,
            "preset": "paper_steps", "git_commit": "abc1234"}
    if resumes is not None:
        tags["resumes"] = resumes
    run_id = client.create_run(exp_id, tags=tags).info.run_id
    client.log_batch(run_id, metrics=[Metric("train/steps_per_s", v, 0, s) for s, v in rates],
                     params=[Param("learner.total_steps", "1000000")])
    client.set_terminated(run_id, status=status)
    return run_id


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str]:
    root = tmp_path_factory.mktemp("under_way")
    uri = write_store(root, SyntheticSpec(models=("proposed", "human"), seeds=(0, 1), scenarios=("3",), episodes=2))
    # Seed 0: 100k steps at 100 per second, then 100k at 50 (1,000 s + 2,000 s), stopped and resumed once.
    stopped = add_training(uri, "KILLED", 0, "tk-steps-0", [(100_000, 100.0), (200_000, 50.0)], resumes="1")
    # Seed 1: an earlier stopped run of a training that another run finished since; a failed one of seed 2.
    add_training(uri, "KILLED", 1, "tk-steps-1", [(50_000, 100.0)])
    add_training(uri, "FINISHED", 1, "tk-steps-1", [(1_000_000, 100.0)])
    add_training(uri, "FAILED", 2, "tk-steps-2", [(10_000, 100.0)])
    return uri, stopped


def test_a_stopped_training_is_read_with_its_steps_and_hours(store: tuple[str, str]) -> None:
    uri, stopped_id = store
    data = load_store(uri)
    assert list(data.stopped.columns) == STOPPED_COLUMNS
    assert len(data.stopped) == 1  # not the finished training, not the failed one
    row = data.stopped.iloc[0]
    assert (row["run_id"], row["model"], row["seed"], row["experiment"], row["train_key"]) == (
        stopped_id, "proposed", 0, "paper_steps", "tk-steps-0")
    assert (row["step"], row["total_steps"], row["steps_per_s"], row["stops"]) == (200_000, 1_000_000, 50.0, 1)
    assert row["hours"] == pytest.approx(3000 / 3600)
    # A stopped run holds no result: it is still left out of the tables the report means over.
    assert stopped_id not in set(data.runs["run_id"]) and "tk-steps-0" not in set(data.curves["train_key"])


def test_a_training_still_running_is_under_way_not_a_result(tmp_path: Path) -> None:
    """A store read while a rung trains (or left with a training RUNNING by a job that could not close it):
    the training is under way, with its steps so far, and its curves stand in for no finished training."""
    uri = write_store(tmp_path, SyntheticSpec(models=("proposed", "human"), seeds=(0,), scenarios=("3",),
                                              episodes=2))
    running = add_training(uri, "KILLED", 0, "tk-running", [(340_000, 88.0)], resumes="2")
    MlflowClient(tracking_uri=uri).update_run(running, status="RUNNING")
    data = load_store(uri)
    assert list(data.stopped[["run_id", "step", "stops"]].itertuples(index=False, name=None)) == [
        (running, 340_000, 2)]
    assert running not in set(data.runs["run_id"]) and "tk-running" not in set(data.curves["train_key"])
    assert any("still RUNNING" in note for note in data.dropped)
    # The quick preset's own training of the same model and seed keeps its curves.
    assert not data.curves[data.curves["model"] == "proposed"].empty


def test_the_bundle_keeps_the_stopped_trainings_and_an_older_bundle_reads_none(store: tuple[str, str],
                                                                              tmp_path: Path) -> None:
    data = load_store(store[0])
    write_bundle(data, tmp_path / "b")
    pd.testing.assert_frame_equal(load_bundle(tmp_path / "b").stopped, data.stopped, check_exact=True)
    # A bundle written before the file existed.
    (tmp_path / "b" / "stopped.csv").unlink()
    manifest = json.loads((tmp_path / "b" / MANIFEST).read_text())
    del manifest["tables"]["stopped"]
    (tmp_path / "b" / MANIFEST).write_text(json.dumps(manifest))
    older = load_bundle(tmp_path / "b")
    assert older.stopped.empty and list(older.stopped.columns) == STOPPED_COLUMNS
    pd.testing.assert_frame_equal(older.evals, data.evals, check_exact=True)


def test_a_later_source_of_the_rung_replaces_its_stopped_trainings(store: tuple[str, str]) -> None:
    data = load_store(store[0])
    later = data.stopped.assign(step=300_000, hours=1.5)
    newer = StoreData(tracking_uri="sqlite:///later.db", experiment="hgm_repro", runs=data.runs.iloc[0:0],
                      curves=data.curves.iloc[0:0], evals=data.evals.iloc[0:0], episodes=data.episodes.iloc[0:0],
                      stopped=later)
    both = combine([data, newer])
    assert list(both.stopped["step"]) == [300_000] and len(both.evals) == len(data.evals)


def rung_data() -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """The quick rung whole (seeds 0-2); at the paper's steps only the proposed host's seed 0 tested, its seed 1
    stopped at 250k of 1M steps after 1.0 hour; the rest missing."""
    spec = SyntheticSpec(seeds=(0, 1, 2), models=(*LEARNED, "human"), episodes=2, experiment="quick")
    quick = synthetic_frames(spec)
    steps = synthetic_frames(SyntheticSpec(seeds=(0,), models=("proposed",), episodes=2, experiment="paper_steps"))
    evals, curves, episodes = (pd.concat([quick[i], steps[i]], ignore_index=True) for i in range(3))
    stopped = pd.DataFrame([{"run_id": "r1", "model": "proposed", "seed": 1, "experiment": "paper_steps",
                             "train_key": "tk-1", "step": 250_000, "total_steps": 1_000_000.0, "steps_per_s": 250.0,
                             "hours": 1.0,
                             "stops": 2}], columns=STOPPED_COLUMNS)
    return evals, curves, episodes, stopped


def test_the_ladder_says_what_is_tested_stopped_and_missing_and_the_hours_left() -> None:
    evals, curves, episodes, stopped = rung_data()
    evals = with_cv_ratio(evals, pd.DataFrame())
    section, _, _, states, _ = ladder.section(evals, curves, episodes, None, stopped)
    paras = [b.text for b in section.blocks if b.rows is None]
    step_rows = states[states["rung"] == "paper_steps"].set_index(["model", "seed"])
    assert list(step_rows["state"]) == ["tested", "stopped", "missing"] + ["missing"] * 6
    assert ladder.under_way(states) == {("paper_steps", "proposed")}
    steps_keys = set(evals.loc[evals["experiment"] == "paper_steps", "train_key"])
    tested_hours = ladder.training_costs(curves[curves["train_key"].isin(steps_keys)])["hours"].iloc[0]
    assert step_rows.loc[("proposed", 0), "hours"] == pytest.approx(tested_hours)
    # Left: the stopped one's 750k steps at its slowest rate (750k / 250 per s: 0.83 hours), and 7 whole trainings
    # at the tested one's hours (under 0.1 each): about 1 hour.
    left = 750_000 / 250 / 3600 + 7 * tested_hours
    assert ladder.hours_left(states[states["rung"] == "paper_steps"]) == pytest.approx(left)
    assert 0.5 <= left < 1.5
    text = next(p for p in paras if p.startswith("Rung 2, paper_steps"))
    assert ("Trainings: Proposed: seed 0 tested; seed 1 stopped at 250k of 1M steps after 1.00 CPU-hours of "
            "training, resumed 2 times; seed 2 missing. Min: seeds 0, 1 and 2 missing. Coordinate: seeds 0, 1 and 2 "
            "missing. Left: about 1 CPU-hour of training, at what one training takes as measured on this "
            f"rung: Proposed {tested_hours:.1f}, Min {tested_hours:.1f} and Coordinate {tested_hours:.1f} CPU-hours "
            "(the method's tested trainings") in text
    quick = next(p for p in paras if p.startswith("Rung 1, quick"))
    assert quick.endswith("Coordinate: seeds 0, 1 and 2 tested.") and "Left" not in quick
    pixels = next(p for p in paras if p.startswith("Rung 3, paper_pixels"))
    assert "not run. Trainings: Proposed: seeds 0, 1 and 2 missing." in pixels
    assert pixels.endswith("none has logged its rate yet, so the hours are not measured here.")


def test_a_rung_with_only_stopped_trainings_goes_on_at_their_slowest_rate() -> None:
    # The first stopped at 250k after 1 hour, its slowest rate 100 steps per second: 750k more steps take 2.08 hours.
    # The second logged no rate: it counts as a whole training, as does each missing one.
    states = pd.DataFrame({"model": "proposed", "state": ["stopped", "stopped", "missing"],
                           "step": [250_000.0, 0.0, None],
                           "total_steps": [1_000_000.0, 1_000_000.0, None], "steps_per_s": [100.0, None, None],
                           "hours": [1.0, 0.0, None]})
    whole = 1.0 + 750_000 / 100 / 3600
    assert ladder.hours_per_training(states) == pytest.approx(whole)
    assert ladder.hours_left(states) == pytest.approx((whole - 1.0) + whole + whole)


def test_each_method_s_trainings_left_cost_what_its_own_take() -> None:
    """The proposed host's tested training took 2 hours, Coordinate's 4: a missing seed of each costs its own
    method's; Min, with nothing measured on the rung, costs the rung's mean (3)."""
    states = pd.DataFrame({"model": ["proposed", "proposed", "coordinate", "coordinate", "min"],
                           "state": ["tested", "missing", "tested", "missing", "missing"],
                           "step": float("nan"), "total_steps": float("nan"), "steps_per_s": float("nan"),
                           "hours": [2.0, None, 4.0, None, None], "stops": 0, "seed": [0, 1, 0, 1, 0]})
    assert ladder.method_hours(states) == pytest.approx({"proposed": 2.0, "coordinate": 4.0, "min": 3.0})
    assert ladder.hours_left(states) == pytest.approx(2.0 + 4.0 + 3.0)
    text = ladder.progress_text(states)
    assert text.endswith("Left: about 9 CPU-hours of training, at what one training takes as measured on this rung: "
                         "Proposed 2.0, Coordinate 4.0 and Min 3.0 CPU-hours (the method's tested trainings, else a "
                         "stopped one's hours so far and the rest of its steps at the slowest rate it logged, else the "
                         "rung's), and the tests.")


def test_cpu_hours_come_from_the_cpu_rate_where_logged_and_the_wall_rate_elsewhere() -> None:
    # An older training logged only its wall rate; a newer one both: 1,000 steps at 10 per CPU second and at
    # 5 per wall second (a busy machine), then 1,000 at 20 and 20.
    curves = pd.DataFrame({"train_key": ["old", "new", "new", "new", "new"],
                           "metric": ["steps_per_s", "steps_per_s", "cpu_steps_per_s", "steps_per_s",
                                      "cpu_steps_per_s"],
                           "step": [3600, 1000, 1000, 2000, 2000], "value": [1.0, 5.0, 10.0, 20.0, 20.0]})
    assert hours_trained(curves).to_dict() == pytest.approx({"old": 1.0, "new": (100 + 50) / 3600})
    assert hours_trained(curves, cpu=False).to_dict() == pytest.approx({"old": 1.0, "new": (200 + 50) / 3600})
    assert slowest_rate(curves).to_dict() == {"old": 1.0, "new": 10.0}


def test_a_training_stopped_just_after_filling_its_replay_goes_on_at_its_update_pace() -> None:
    """Resumed at 490k, a training logs 1,200 steps per CPU second while it refills the replay memory without
    updating, then 60 with updates; stopped right after the refill, its rest is not 510k steps at 1,200."""
    curves = pd.DataFrame({"train_key": "tk", "metric": "cpu_steps_per_s",
                           "step": [480_000, 490_000, 495_000], "value": [60.0, 62.0, 1_200.0]})
    assert slowest_rate(curves).to_dict() == {"tk": 60.0}
    states = pd.DataFrame({"model": "coordinate", "seed": 4, "state": ["stopped"], "step": [495_000.0],
                           "total_steps": [1_000_000.0], "steps_per_s": slowest_rate(curves).to_list(),
                           "hours": [2.0], "stops": [1]})
    assert ladder.hours_left(states) == pytest.approx(505_000 / 60 / 3600)
    assert "Left: about 2 CPU-hours of training" in ladder.progress_text(states)


@pytest.mark.parametrize(("hours", "words"), [(0.2, "under half a CPU-hour"), (0.7, "about 1 CPU-hour"),
                                              (1.4, "about 1 CPU-hour"), (2.6, "about 3 CPU-hours")])
def test_the_hours_left_read_in_words_with_the_right_number(hours: float, words: str) -> None:
    states = pd.DataFrame({"model": "proposed", "seed": 0, "state": ["stopped"], "step": [500_000.0],
                           "total_steps": [1_000_000.0], "steps_per_s": [500_000 / hours / 3600],
                           "hours": [1.0], "stops": [0]})
    assert f"Left: {words} of training," in ladder.progress_text(states)


def test_a_method_whose_only_training_is_stopped_reads_under_way_in_the_figure(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    evals, curves, episodes, stopped = rung_data()
    stopped = stopped.assign(model="min")  # Min's seed 1 stopped at the paper's steps, none of its seeds tested
    evals = with_cv_ratio(evals, pd.DataFrame())
    drawn, draw = [], ladder_figure.draw

    def keep_marks(*args: object, **kwargs: object) -> plt.Figure:
        fig = draw(*args, **kwargs)
        drawn.append([[t.get_text() for t in ax.texts if t.get_text() in ("under way", "not run")] for ax in fig.axes])
        return fig

    monkeypatch.setattr(ladder_figure, "draw", keep_marks)
    section, numbers, _, states, _ = ladder.section(evals, curves, episodes, None, stopped, out_dir=tmp_path)
    (panels,) = drawn
    for marks in panels:  # the steps rung: Min under way, Coordinate not run; the pixels rung: all three not run
        assert marks.count("under way") == 1 and marks.count("not run") == 1 + len(LEARNED)
    # The steps rung's table says the same in every cell of the two untested rows.
    tables = [b.rows for b in section.blocks if b.rows is not None]
    steps = next(t for t in tables if any(row[0] == "Proposed" and row[1] == "1" for row in t))
    rows = {row[0]: row for row in steps[1:]}
    assert rows["Min"][2:6] == ["under way"] * 4 and rows["Coordinate"][2:6] == ["not run"] * 4
    assert rows["Proposed"][2] not in ("under way", "not run")


def test_page_one_says_under_way_for_a_rung_with_a_stopped_training_and_no_seed_tested() -> None:
    evals, curves, episodes, stopped = rung_data()
    evals = with_cv_ratio(evals, pd.DataFrame())
    # Nothing tested at the paper's steps; the proposed host's seed 1 stopped there. The pixels rung has one seed
    # tested, so page 1 speaks of the rungs above the main pages'.
    steps_keys = evals["experiment"] == "paper_steps"
    pixels = evals[steps_keys].assign(experiment="paper_pixels")
    evals = pd.concat([evals[~steps_keys], pixels], ignore_index=True)
    section, numbers, _, states, _ = ladder.section(evals, curves, episodes, None, stopped)
    going = ladder.under_way(states)
    assert going == {("paper_steps", "proposed")}
    lines = ladder.page_one_lines(numbers, {"quick"}, 3, going)
    assert "The paper's steps (1M steps, Table 4's learner, 36x36x2): Proposed under way, no seed tested yet " \
           "(scale ladder)." in lines
    assert ladder.page_one_lines(numbers, {"quick"}, 3)[0].endswith(": not run yet (scale ladder).")
    paras = [b.text for b in section.blocks if b.rows is None]
    assert any(p.startswith("Rung 2, paper_steps: the paper's steps (1M steps, Table 4's learner, 36x36x2): "
                            "under way. Trainings: Proposed: seed 1 stopped") for p in paras)
