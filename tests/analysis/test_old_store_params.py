"""A store written before the config's groups by concern logged its runs' params under the old
names (`learner.eval_every`, `learner.test_steps`, ...): the loader reads them under today's."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

from analysis.load import load_store
from analysis.synthetic import write_store
from hgm_repro.contracts.names import MOVED_CONFIG_KEYS
from hgm_repro.contracts.schema import EvalSchema, LearnerSchema, LoggingSchema, RuntimeSchema

OLD_PARAMS = {"learner.eval_every": "50000", "learner.test_steps": "200000", "learner.torch_threads": "1",
              "learner.log_every": "5000", "learner.lr": "0.0025"}


def test_an_old_stores_params_are_read_under_their_names_today(tmp_path: Path):
    from mlflow.tracking import MlflowClient

    uri = write_store(tmp_path / "old")
    client = MlflowClient(tracking_uri=uri)
    experiment = client.get_experiment_by_name("hgm_repro")
    trainings = client.search_runs([experiment.experiment_id], "tags.stage = 'train'")
    assert trainings
    for run in trainings:
        for key, value in OLD_PARAMS.items():
            if key not in run.data.params:  # the synthetic store logs learner.lr already
                client.log_param(run.info.run_id, key, value)

    runs = load_store(uri, "hgm_repro").runs
    train = runs[runs["stage"] == "train"]
    assert (train["params.eval.val_every"] == "50000").all()
    assert (train["params.eval.test_steps"] == "200000").all()
    assert (train["params.runtime.torch_threads"] == "1").all()
    assert (train["params.logging.log_every"] == "5000").all()
    assert (train["params.learner.lr"] == "0.0025").all()  # a key that did not move keeps its name
    assert not [c for c in runs.columns if c.removeprefix("params.") in MOVED_CONFIG_KEYS]


def test_every_moved_key_left_the_learner_group_for_a_key_of_today():
    groups = {"eval": EvalSchema, "runtime": RuntimeSchema, "logging": LoggingSchema}
    for old, new in MOVED_CONFIG_KEYS.items():
        group, name = new.split(".")
        assert old.startswith("learner.") and old not in ("learner." + f.name for f in fields(LearnerSchema)), old
        assert name in {f.name for f in fields(groups[group])}, new
