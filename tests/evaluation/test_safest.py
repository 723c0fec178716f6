"""eval.checkpoint=safest: among the kept validation passes, the best return of those under a collision
bar, each pass driven on at least 256 validation episodes; refused with a message when none is under it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch

from hgm_repro.contracts.checkpoint import SAFEST_CHECKPOINT, SAFEST_RECORD, VAL_CHECKPOINTS, load_checkpoint
from hgm_repro.contracts.errors import ConfigError
from hgm_repro.contracts.names import VAL_SEED_OFFSET
from hgm_repro.envs import make_env
from hgm_repro.evaluation import safest
from hgm_repro.evaluation.episodes import learned_policy, run_episodes
from hgm_repro.learner import train
from tests.helpers.learner import Recorder, compose_job

KEEP = ["eval.val_every=32", "eval.val_envs=2", "eval.keep_val_checkpoints=true", "eval.checkpoint=safest",
        "eval.safest_envs=64"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One tiny training that keeps four validation passes."""
    directory = tmp_path_factory.mktemp("safest")
    train(compose_job(*KEEP), directory, Recorder())
    return directory


def test_pick_takes_the_best_return_under_the_bar():
    rows = [{"env_steps": 32, "return": 90.0, "collisions": 0.0}, {"env_steps": 64, "return": 200.0, "collisions": 0.3},
            {"env_steps": 96, "return": 120.0, "collisions": 0.04}, {"env_steps": 128, "return": 120.0,
                                                                      "collisions": 0.01}]
    assert safest.pick_safest(rows, 0.05)["env_steps"] == 96  # the racer at 64 crashes; ties: the earlier pass
    assert safest.pick_safest(rows, 0.5)["env_steps"] == 64
    assert safest.pick_safest(rows, 0.0) is None  # under the bar means strictly under


def test_every_pass_is_driven_on_256_validation_episodes_and_the_choice_follows_the_bar(trained, tmp_path):
    directory = tmp_path / "copy"
    shutil.copytree(trained, directory)
    # A bar every pass passes (an episode holds at most one crash): the best return of all.
    path, record = safest.choose_safest(compose_job(*KEEP, "eval.safest_max_collisions=1.01"), directory)
    rows = record["candidates"]
    assert [r["env_steps"] for r in rows] == [32, 64, 96, 128]
    assert all(r["episodes"] == 256 for r in rows)
    assert record["options"]["traffic_seed"] == 0 + VAL_SEED_OFFSET
    best = max(rows, key=lambda r: r["return"])
    assert record["chosen_env_steps"] == best["env_steps"]
    assert load_checkpoint(path)["safest_from"] == best["env_steps"]
    assert path == directory / SAFEST_CHECKPOINT
    # A row is its pass's own greedy drive on the validation traffic, recomputed here.
    job = compose_job(*KEEP)
    env = make_env(job, job.train_scenario, n_envs=64, seed=VAL_SEED_OFFSET)
    episodes = run_episodes(env, learned_policy(job, directory / VAL_CHECKPOINTS / "000000064.pt",
                                                torch.device("cpu")), 4, VAL_SEED_OFFSET)
    assert rows[1]["return"] == pytest.approx(float(episodes["episode_return"].mean()))
    assert rows[1]["collisions"] == pytest.approx(float(episodes["collisions"].mean()))
    # A bar just above the safest pass's collisions: that pass, or a safer-enough one with more return.
    lowest = min(r["collisions"] for r in rows)
    bar = lowest + 1e-6
    stamp = (directory / SAFEST_RECORD).stat().st_mtime_ns
    _, again = safest.choose_safest(compose_job(*KEEP, f"eval.safest_max_collisions={bar}"), directory)
    under = [r for r in rows if r["collisions"] < bar]
    assert again["chosen_env_steps"] == max(under, key=lambda r: r["return"])["env_steps"]
    assert again["candidates"] == rows  # another bar re-picks from the same drives
    assert (directory / SAFEST_RECORD).stat().st_mtime_ns >= stamp


def test_no_pass_under_the_bar_is_refused_with_the_safest_named(trained, tmp_path):
    directory = tmp_path / "copy"
    shutil.copytree(trained, directory)
    with pytest.raises(ConfigError, match=r"no validation pass .* stays under eval.safest_max_collisions=0.0"):
        safest.choose_safest(compose_job(*KEEP, "eval.safest_max_collisions=0"), directory)
    assert not (directory / SAFEST_CHECKPOINT).exists()
    assert json.loads((directory / SAFEST_RECORD).read_text())["chosen_env_steps"] is None


def test_no_kept_pass_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="holds no validation pass's network"):
        safest.choose_safest(compose_job(*KEEP), tmp_path)


def test_a_job_tests_the_safest_pass_and_the_probe_reuses_the_training_under_its_own_name(tmp_path):
    from hgm_repro.app.job import run_job
    from hgm_repro.app.store import Tracker, resolve_location
    from tests.helpers.learner import compose_cfg

    job_keep = [*KEEP, "tracking.log_gif=false", "tracking.log_model=false"]
    outcome = run_job(compose_cfg(*job_keep, "eval.safest_max_collisions=1.01"), tmp_path)
    tracker = Tracker(resolve_location(compose_cfg(*job_keep).tracking, tmp_path), "hgm_repro")
    tags = tracker.get_run(outcome.eval_run_id).data.tags
    record = json.loads((outcome.training.checkpoint.parent / SAFEST_RECORD).read_text())
    assert tags["checkpoint"] == "safest" and tags["safest_env_steps"] == str(record["chosen_env_steps"])
    assert SAFEST_RECORD in [a.path for a in tracker.client.list_artifacts(outcome.eval_run_id)]
    # The probe: the same training (not trained again), its test named as the layer-at-test host.
    probe = run_job(compose_cfg(*job_keep, "eval.checkpoint=best", "eval.host_safety_layer=true"), tmp_path)
    assert probe.training.run_id == outcome.training.run_id
    run = tracker.get_run(probe.eval_run_id)
    assert run.data.tags["model"] == "proposed_layer_at_test" and run.info.run_name.startswith("proposed_layer_at_test")
    # The safest test sits beside the training's other tests under a name of its own.
    tested = tracker.get_run(outcome.eval_run_id)
    assert tested.data.tags["model"] == "proposed_safest" and tested.info.run_name.startswith("proposed_safest ")
    # A bar no pass is under: refused with the message, before a run opens (no failed run in the store).
    evals_before = len(tracker.client.search_runs([tested.info.experiment_id], "tags.stage = 'eval'"))
    with pytest.raises(ConfigError, match="no validation pass .* stays under eval.safest_max_collisions=0"):
        run_job(compose_cfg(*job_keep, "eval.safest_max_collisions=0"), tmp_path)
    assert len(tracker.client.search_runs([tested.info.experiment_id], "tags.stage = 'eval'")) == evals_before
    # The training run says what the safest choice found, the latest bar's outcome: chosen, then refused.
    train_tags = tracker.get_run(outcome.training.run_id).data.tags
    lowest = min(r["collisions"] for r in record["candidates"])
    assert (train_tags["safest_choice"], train_tags["safest_bar"]) == ("refused", "0.0")
    assert float(train_tags["safest_lowest_collisions"]) == pytest.approx(lowest, abs=1e-4)
    # The report reads the refusal from the store: the training is named though no test run exists for it.
    from analysis import safest as section
    from analysis.load import load_store

    data = load_store(tracker_uri := resolve_location(compose_cfg(*job_keep).tracking, tmp_path).tracking_uri)
    assert tracker_uri.startswith("sqlite:///")
    refused = section.refusals(data.evals, data.runs)
    assert refused[["host", "seed"]].values.tolist() == [["proposed", 0]]
    assert refused["bar"].tolist() == [0.0]


def test_the_training_run_is_tagged_with_what_the_choice_found():
    record = {"candidates": [{"collisions": 0.25}, {"collisions": 0.0625}], "max_collisions": 0.05,
              "chosen_env_steps": None}
    assert safest.outcome_tags(record) == {"safest_choice": "refused", "safest_bar": "0.05",
                                           "safest_lowest_collisions": "0.0625"}
    assert safest.outcome_tags({**record, "chosen_env_steps": 20000})["safest_choice"] == "20000"
