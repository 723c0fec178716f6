"""Reselection (eval.checkpoint=reselected): training keeps each validation pass's network, and the
test drives the best of the top passes re-driven on fresh validation traffic, chosen once per training."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch

from hgm_repro.app.job import run_job
from hgm_repro.app.store import Tracker, resolve_location
from hgm_repro.contracts.checkpoint import (
    BEST_CHECKPOINT,
    RESELECTED_CHECKPOINT,
    RESELECTION_RECORD,
    VAL_CHECKPOINTS,
    load_checkpoint,
)
from hgm_repro.contracts.errors import ConfigError
from hgm_repro.contracts.interrupts import JobInterrupted
from hgm_repro.contracts.names import RESELECT_SEED_OFFSET, VAL_SEED_OFFSET
from hgm_repro.contracts.schema import check_config
from hgm_repro.envs import make_env
from hgm_repro.evaluation import reselection
from hgm_repro.evaluation.episodes import run_episodes
from hgm_repro.evaluation.policies import trained_network
from hgm_repro.models.builders import make_actor
from tests.helpers.learner import compose_cfg, compose_job

KEEP = ["eval.val_every=32", "eval.val_envs=2", "eval.keep_val_checkpoints=true", "tracking.log_gif=false",
        "tracking.log_model=false"]
RESELECT = [*KEEP, "eval.checkpoint=reselected", "eval.reselect_top=2", "eval.reselect_envs=2",
            "eval.reselect_episodes=1"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """One real (tiny) training with four validation passes, tested from its reselected network."""
    launch = tmp_path_factory.mktemp("reselect")
    outcome = run_job(compose_cfg(*RESELECT), launch)
    return launch, outcome


def _same_weights(a: Path, b: Path) -> bool:
    wa, wb = load_checkpoint(a)["network"], load_checkpoint(b)["network"]
    return all(torch.equal(wa[k], wb[k]) for k in wa)


def test_training_keeps_every_validation_pass_and_best_pt_is_the_best_of_them(trained) -> None:
    launch, outcome = trained
    directory = outcome.training.checkpoint.parent
    passes = reselection.validation_passes(directory)
    assert [p.env_steps for p in passes] == [32, 64, 96, 128]
    tracker = Tracker(resolve_location(compose_cfg(*RESELECT).tracking, launch), "hgm_repro")
    logged = {m.step: m.value for m in tracker.client.get_metric_history(outcome.training.run_id,
                                                                         "val/episode_return")}
    assert {p.env_steps: pytest.approx(p.val_return) for p in passes} == logged
    first_best = max(passes, key=lambda p: p.val_return)  # max keeps the first: best.pt changes only on a rise
    assert _same_weights(directory / BEST_CHECKPOINT, first_best.path)


def test_the_test_drives_the_best_of_the_top_passes_on_fresh_traffic(trained) -> None:
    launch, outcome = trained
    directory = outcome.training.checkpoint.parent
    job = compose_job(*RESELECT)
    record = json.loads((directory / RESELECTION_RECORD).read_text())
    passes = reselection.validation_passes(directory)
    top = sorted(passes, key=lambda p: (-p.val_return, p.env_steps))[:2]
    assert [c["env_steps"] for c in record["candidates"]] == [p.env_steps for p in top]
    assert record["options"]["traffic_seed"] == job.seed + RESELECT_SEED_OFFSET != job.seed + VAL_SEED_OFFSET
    # Each candidate's return is its own greedy drive on the reselection traffic, recomputed here.
    env = make_env(job, job.train_scenario, n_envs=2, seed=job.seed + RESELECT_SEED_OFFSET)
    for candidate, row in zip(top, record["candidates"], strict=True):
        actor = make_actor(trained_network(job, candidate.path, torch.device("cpu")))
        episodes = run_episodes(env, actor, 1, job.seed + RESELECT_SEED_OFFSET)
        assert row["return"] == pytest.approx(float(episodes["episode_return"].mean()))
        assert row["episodes"] == 2
    chosen = max(record["candidates"], key=lambda r: r["return"])["env_steps"]
    assert record["chosen_env_steps"] == chosen
    winner = next(p for p in passes if p.env_steps == chosen)
    assert _same_weights(directory / RESELECTED_CHECKPOINT, winner.path)
    # The test run says which pass it drove, and keeps the record.
    tracker = Tracker(resolve_location(compose_cfg(*RESELECT).tracking, launch), "hgm_repro")
    tags = tracker.get_run(outcome.eval_run_id).data.tags
    assert tags["checkpoint"] == "reselected" and tags["reselected_env_steps"] == str(chosen)
    artifacts = [a.path for a in tracker.client.list_artifacts(outcome.eval_run_id)]
    assert RESELECTION_RECORD in artifacts


def test_a_choice_is_reused_only_under_the_same_options_and_passes(trained, tmp_path: Path) -> None:
    _, outcome = trained
    directory = tmp_path / "copy"
    shutil.copytree(outcome.training.checkpoint.parent, directory)
    job = compose_job(*RESELECT)
    stamp = (directory / RESELECTED_CHECKPOINT).stat().st_mtime_ns
    path, record = reselection.reselect(job, directory)
    assert path.stat().st_mtime_ns == stamp and len(record["candidates"]) == 2  # reused, not driven again
    # Other options: chosen again, among the three best passes this time.
    _, wider = reselection.reselect(compose_job(*RESELECT, "eval.reselect_top=3"), directory)
    assert len(wider["candidates"]) == 3
    # A pass gone from the folder (a training redone, say): chosen again from the passes there are.
    gone = wider["candidates"][0]["env_steps"]
    (directory / VAL_CHECKPOINTS / f"{gone:09d}.pt").unlink()
    _, again = reselection.reselect(compose_job(*RESELECT, "eval.reselect_top=3"), directory)
    assert gone not in [c["env_steps"] for c in again["candidates"]]


def test_a_reselection_stopped_mid_way_leaves_no_choice_and_the_next_test_makes_it(
        trained, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _, outcome = trained
    directory = tmp_path / "copy"
    shutil.copytree(outcome.training.checkpoint.parent, directory)
    (directory / RESELECTED_CHECKPOINT).unlink()
    (directory / RESELECTION_RECORD).unlink()
    job = compose_job(*RESELECT)
    drives = []

    def stopped_on_the_second_candidate(env, policy, episodes, traffic):  # a stop signal between two drives
        drives.append(traffic)
        if len(drives) == 2:
            raise JobInterrupted(15)
        return real_run_episodes(env, policy, episodes, traffic)

    real_run_episodes = reselection.run_episodes
    monkeypatch.setattr(reselection, "run_episodes", stopped_on_the_second_candidate)
    with pytest.raises(JobInterrupted):
        reselection.reselect(job, directory)
    assert not (directory / RESELECTED_CHECKPOINT).exists() and not (directory / RESELECTION_RECORD).exists()
    monkeypatch.setattr(reselection, "run_episodes", real_run_episodes)
    path, record = reselection.reselect(job, directory)
    assert path.is_file() and record == json.loads((outcome.training.checkpoint.parent /
                                                    RESELECTION_RECORD).read_text())


def test_reselection_without_kept_passes_is_refused_before_any_work(trained, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"eval.checkpoint=reselected is not allowed with eval.val_every=32 "
                                          r"and eval.keep_val_checkpoints=false"):
        check_config(compose_cfg(*RESELECT, "eval.keep_val_checkpoints=false"))
    with pytest.raises(ConfigError, match="eval.checkpoint=reselected is not allowed with eval.val_every=0"):
        check_config(compose_cfg(*RESELECT, "eval.val_every=0"))
    # The training exists but kept no passes (trained without keep_val_checkpoints): the job says so and
    # opens no test run.
    launch, outcome = trained
    kept = outcome.training.checkpoint.parent / VAL_CHECKPOINTS
    kept.rename(tmp_path / "aside")
    try:
        with pytest.raises(ConfigError, match=r"kept no validation pass's network .*eval.checkpoint=best"):
            run_job(compose_cfg(*RESELECT, "scenario='3'"), launch)
    finally:
        (tmp_path / "aside").rename(kept)
    tracker = Tracker(resolve_location(compose_cfg(*RESELECT).tracking, launch), "hgm_repro")
    tests = tracker.client.search_runs([tracker.experiment_id], "tags.stage = 'eval'")
    assert [r.info.run_id for r in tests] == [outcome.eval_run_id]


def test_passes_scored_by_the_blank_frame_validation_are_all_candidates(trained, tmp_path: Path) -> None:
    """Kept passes of a training whose validation handed hosts blank frames (evaluation version 1):
    their validation returns rank nothing, so reselection drives every pass."""
    from hgm_repro.contracts.checkpoint import save_checkpoint

    _, outcome = trained
    directory = tmp_path / "old"
    shutil.copytree(outcome.training.checkpoint.parent, directory)
    for path in (directory / VAL_CHECKPOINTS).glob("*.pt"):
        state = load_checkpoint(path)
        del state["evaluation_version"]
        save_checkpoint(state, path)
    _, record = reselection.reselect(compose_job(*RESELECT), directory)
    assert record["ranked_by_validation"] is False
    assert [c["env_steps"] for c in record["candidates"]] == [32, 64, 96, 128]


def test_revalidation_scores_kept_passes_as_training_did_and_chooses_best_pt_again(trained, tmp_path: Path) -> None:
    """A training whose validation predates evaluation version 2 (its passes' scores and best.pt are the
    blank-frame ones): revalidation gives each pass the score this code's validation gives it, which
    for this training is what it logged, and writes best.pt from those scores."""
    from hgm_repro.contracts.checkpoint import chosen_by_current_validation, save_checkpoint

    launch, outcome = trained
    directory = tmp_path / "old"
    shutil.copytree(outcome.training.checkpoint.parent, directory)
    (directory / BEST_CHECKPOINT).unlink()
    for path in (directory / VAL_CHECKPOINTS).glob("*.pt"):  # scores of the old validation: made up here
        state = load_checkpoint(path)
        del state["evaluation_version"]
        save_checkpoint({**state, "val_return": -float(state["env_steps"])}, path)
    scored = reselection.revalidate(compose_job(*RESELECT), directory)
    tracker = Tracker(resolve_location(compose_cfg(*RESELECT).tracking, launch), "hgm_repro")
    logged = {m.step: m.value for m in tracker.client.get_metric_history(outcome.training.run_id,
                                                                         "val/episode_return")}
    assert {p.env_steps: pytest.approx(p.val_return) for p in scored} == logged
    assert all(p.current for p in reselection.validation_passes(directory))
    best = load_checkpoint(directory / BEST_CHECKPOINT)
    assert chosen_by_current_validation(best)
    assert _same_weights(directory / BEST_CHECKPOINT, outcome.training.checkpoint.parent / BEST_CHECKPOINT)


def test_best_pass_within_a_budget_is_what_a_shorter_training_would_keep(trained) -> None:
    """best_pass with a budget takes the best of the passes at or before it (research/studies/budget_cut.py tests it as
    a shorter training's best.pt); without one it is the training's own best.pt; a budget before the first
    pass is refused with the passes' steps."""
    _, outcome = trained
    directory = outcome.training.checkpoint.parent
    passes = reselection.validation_passes(directory)
    assert _same_weights(reselection.best_pass(passes).path, directory / BEST_CHECKPOINT)
    for budget in (32, 64, 96, 100):
        within = [p for p in passes if p.env_steps <= budget]
        chosen = reselection.best_pass(passes, budget)
        assert chosen.env_steps <= budget
        assert chosen.val_return == max(p.val_return for p in within)
        assert chosen is next(p for p in within if p.val_return == chosen.val_return)  # the first of equals
    tied = [reselection.ValidationPass(s, 7.0, p.path, True) for s, p in zip((32, 64), passes, strict=False)]
    assert reselection.best_pass(tied).env_steps == 32
    with pytest.raises(ConfigError, match=r"at or before 31 env steps.*\[32, 64, 96, 128\]"):
        reselection.best_pass(passes, 31)
