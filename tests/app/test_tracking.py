"""Tracking and train-once logic, in process, with a fake learner and evaluator (seconds, no torch)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from hgm_repro.app.job import run_job
from hgm_repro.app.provenance import git_info
from hgm_repro.app.store import STORE_FORMAT_TAG, StoreError, Tracker, flatten, resolve_location, retry, tidy_number
from hgm_repro.app.trainings import RUN_ID_FILE
from hgm_repro.contracts.checkpoint import CHECKPOINT_FORMAT, save_checkpoint
from hgm_repro.contracts.conf_dir import CONF_DIR
from hgm_repro.contracts.errors import ConfigError
from hgm_repro.contracts.interrupts import JobInterrupted
from hgm_repro.contracts.schema import JobConfig, check_config
from hgm_repro.contracts.simulator_config import ScenarioConfig
from hgm_repro.contracts.train_key import EVALUATION_VERSION, train_key


def make_cfg(*overrides: str) -> DictConfig:
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return compose("config", overrides=["experiment=smoke", "tracking.log_gif=false", "tracking.log_model=false",
                                            *overrides])


@pytest.fixture(scope="module")
def empty_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An initialised SQLite store, made once: creating one runs MLflow's migrations (seconds)."""
    launch = tmp_path_factory.mktemp("template")
    Tracker(resolve_location(make_cfg().tracking, launch), "hgm_repro")
    return launch / "mlflow.db"


@pytest.fixture
def launch(tmp_path: Path, empty_store: Path) -> Path:
    """A launch dir holding a copy of the empty store (artifacts still land in the template's
    dir, which its experiment names; unique run ids keep them apart)."""
    shutil.copy(empty_store, tmp_path / "mlflow.db")
    return tmp_path


class FakeLearner:
    """Writes last.pt and final.pt like the learner; can stop once, mid-way, like a SIGTERM."""

    def __init__(self, interrupt_after: int | None = None) -> None:
        self.calls: list[Path] = []
        self.interrupt_after = interrupt_after

    def __call__(self, job: JobConfig, checkpoint_dir: Path, log) -> Path:
        self.calls.append(checkpoint_dir)
        last = checkpoint_dir / "last.pt"
        start = int(last.read_text()) if last.exists() else 0
        for step in range(start + 64, job.learner.total_steps + 1, 64):
            log({"train/loss": 1.0 / step, "train/episode_return": float(step)}, step)
            last.write_text(str(step))
            if self.interrupt_after is not None and step >= self.interrupt_after:
                self.interrupt_after = None
                raise JobInterrupted()
        final = checkpoint_dir / "final.pt"
        final.write_text("weights")
        return final


def fake_evaluate(job: JobConfig, scenario: ScenarioConfig, checkpoint: Path | None) -> SimpleNamespace:
    episodes = pd.DataFrame({"avg_speed_kmh": [60.0, 62.0], "episode_return": [10.0, 12.0]})
    return SimpleNamespace(episodes=episodes, means={"eval/avg_speed_kmh": 61.0, "eval/episode_return": 11.0})


def store(tmp_path: Path) -> Tracker:
    return Tracker(resolve_location(make_cfg().tracking, tmp_path), "hgm_repro")


def runs(tmp_path: Path, stage: str) -> list:
    return store(tmp_path).search(f"tags.stage = '{stage}'")


def test_train_key_ignores_test_scenario_tracking_and_device() -> None:
    base = train_key(make_cfg())
    assert base == train_key(make_cfg("scenario='3'", "device=mps", "tracking.uri=http://x", "launcher=joblib"))
    assert base == train_key(make_cfg("eval.test_steps=999", "logging.log_every=7"))
    assert base != train_key(make_cfg("seed=1"))
    assert base != train_key(make_cfg("model=min"))
    assert base != train_key(make_cfg("learner.lr=0.001"))
    assert base != train_key(make_cfg("scenario@train_scenario='5'"))
    # The typed config a job hands on carries the same identity as the tree it was validated from.
    for overrides in ((), ("model=min", "seed=3"), ("model=human",)):
        assert train_key(check_config(make_cfg(*overrides))) == train_key(make_cfg(*overrides))
    assert len(base) == 12 and int(base, 16) >= 0


def test_flatten_cuts_values_and_nests_keys() -> None:
    flat = flatten({"a": {"b": 1, "c": {"d": "x" * 900}}, "e": [1, 2], "f": {}})
    assert flat == {"a.b": "1", "a.c.d": "x" * 500, "e": "[1, 2]", "f": "{}"}


def test_retry_waits_out_a_locked_database() -> None:
    calls = []

    def flaky() -> str:
        calls.append(1)
        if len(calls) < 3:
            raise RuntimeError("(sqlite3.OperationalError) database is locked")
        return "ok"

    assert retry(flaky) == "ok" and len(calls) == 3
    with pytest.raises(ValueError):
        retry(lambda: (_ for _ in ()).throw(ValueError("not transient")))


def test_git_info_outside_a_checkout(tmp_path: Path) -> None:
    assert git_info(tmp_path) == ("unknown", "unknown")


def test_git_dirty_ignores_docs_but_not_code(tmp_path: Path) -> None:
    # A publish script rewrites docs/results in the checkout it runs from; that must not flag the runs
    # after it dirty, while an edit to code (or to docs and code together) must.
    def git(*args: str) -> None:
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True)

    git("init", "-q")
    (tmp_path / "docs" / "results").mkdir(parents=True)
    (tmp_path / "docs" / "results" / "evals.csv").write_text("a\n")
    (tmp_path / "hgm.py").write_text("x = 1\n")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "init")
    commit, dirty = git_info(tmp_path)
    assert len(commit) == 40 and dirty == "false"
    (tmp_path / "docs" / "results" / "evals.csv").write_text("b\n")
    assert git_info(tmp_path)[1] == "false"
    (tmp_path / "hgm.py").write_text("x = 2\n")
    assert git_info(tmp_path)[1] == "true"


def test_store_is_absolute_under_the_launch_dir(tmp_path: Path) -> None:
    loc = resolve_location(make_cfg().tracking, tmp_path)
    assert loc.tracking_uri == f"sqlite:///{tmp_path.resolve()}/mlflow.db"
    assert loc.artifact_location == (tmp_path.resolve() / "mlartifacts").as_uri()
    assert loc.checkpoint_root == tmp_path.resolve() / "checkpoints"
    remote = resolve_location(make_cfg("tracking.uri=http://127.0.0.1:5999").tracking, tmp_path)
    assert remote.tracking_uri == "http://127.0.0.1:5999" and remote.artifact_location is None
    assert remote.checkpoint_root == tmp_path.resolve() / "checkpoints"


def test_params_beyond_one_batch_are_all_logged(launch: Path) -> None:
    tracker = store(launch)
    run_id = tracker.start_run("many", {"stage": "eval"})
    tracker.log_params(run_id, {f"p{i}": str(i) for i in range(250)})
    assert len(tracker.get_run(run_id).data.params) == 250


def test_train_once_evaluate_many(launch: Path) -> None:
    learner = FakeLearner()
    outcomes = [
        run_job(make_cfg(f"scenario='{s}'"), launch, train_fn=learner, evaluate_fn=fake_evaluate)
        for s in ("1", "5", "3")
    ]
    assert len(learner.calls) == 1
    assert [o.training.how for o in outcomes] == ["trained", "reused", "reused"]
    train_runs, eval_runs = runs(launch, "train"), runs(launch, "eval")
    assert len(train_runs) == 1 and len(eval_runs) == 3
    train = train_runs[0]
    assert train.info.status == "FINISHED" and train.data.tags["scenario"] == "train"
    assert train.data.metrics["train/loss"] == pytest.approx(1 / 256)
    assert {e.data.tags["train_run_id"] for e in eval_runs} == {train.info.run_id}
    for run in [*train_runs, *eval_runs]:
        for tag in ("model", "scenario", "seed", "stage", "train_key", "git_commit", "git_dirty"):
            assert tag in run.data.tags, tag
    assert sorted(e.data.tags["scenario"] for e in eval_runs) == ["1", "3", "5"]
    assert eval_runs[0].data.metrics["eval/avg_speed_kmh"] == 61.0
    assert eval_runs[0].data.params["learner.total_steps"] == "256"
    client = store(launch).client
    assert {a.path for a in client.list_artifacts(eval_runs[0].info.run_id)} >= {"config.yaml", "episodes.csv"}
    assert [a.path for a in client.list_artifacts(train.info.run_id, "checkpoint")] == ["checkpoint/final.pt"]


def test_force_retrain_trains_again(launch: Path) -> None:
    learner = FakeLearner()
    run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    outcome = run_job(make_cfg("force_retrain=true"), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    assert outcome.training.how == "trained" and len(learner.calls) == 2
    assert len(runs(launch, "train")) == 2


def test_interrupted_training_resumes_the_same_run(launch: Path) -> None:
    learner = FakeLearner(interrupt_after=128)
    with pytest.raises(SystemExit) as stopped:
        run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    assert stopped.value.code == 128 + 15
    (killed,) = runs(launch, "train")
    assert killed.info.status == "KILLED"
    outcome = run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    assert outcome.training.how == "resumed" and outcome.training.run_id == killed.info.run_id
    (train,) = runs(launch, "train")
    assert train.info.status == "FINISHED" and train.data.tags["resumes"] == "1"
    history = store(launch).client.get_metric_history(train.info.run_id, "train/loss")
    assert sorted(m.step for m in history) == [64, 128, 192, 256]


def _held_by_another_process(lock_file: Path) -> subprocess.Popen:
    """Another process holds `lock_file` (as a job training that key holds its train.lock) until killed."""
    code = ("import sys, time\nfrom filelock import FileLock\nlock = FileLock(sys.argv[1])\nlock.acquire()\n"
            "print('held', flush=True)\ntime.sleep(600)\n")
    other = subprocess.Popen([sys.executable, "-c", code, str(lock_file)], stdout=subprocess.PIPE, text=True)
    assert other.stdout.readline().strip() == "held"
    return other


def test_a_stop_while_waiting_for_a_training_that_comes_free_does_not_reopen_it(launch: Path) -> None:
    """A sweep's stop reaches the job that trains a key and the job waiting for it at once. The trainer
    closes its run KILLED and frees the key; the waiter, whose lock comes free in the same moment,
    must stop too, not reopen the run (which the stop would then leave RUNNING)."""
    import threading

    learner = FakeLearner(interrupt_after=128)
    with pytest.raises(SystemExit):
        run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    (killed,) = runs(launch, "train")
    trainer = _held_by_another_process(launch / "checkpoints" / train_key(make_cfg()) / "train.lock")

    def stop_both() -> None:  # the signal reaches this job, and the trainer lets go of the key
        os.kill(os.getpid(), signal.SIGTERM)
        trainer.kill()

    timer = threading.Timer(0.5, stop_both)
    timer.start()
    try:
        with pytest.raises(SystemExit) as stopped:
            run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    finally:
        timer.cancel()
        trainer.kill()
        trainer.wait()
    assert stopped.value.code == 128 + signal.SIGTERM
    (train,) = runs(launch, "train")
    assert train.info.status == "KILLED" and "resumes" not in train.data.tags
    assert len(learner.calls) == 1


def test_a_stop_while_a_training_run_reopens_ends_it_killed(launch: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The stop arrives while a resumed training's run is being marked RUNNING again: the run ends KILLED."""
    from mlflow.tracking import MlflowClient

    learner = FakeLearner(interrupt_after=128)
    with pytest.raises(SystemExit):
        run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    update_run = MlflowClient.update_run

    def stopped_while_updating(self, run_id, *args, **kwargs):  # noqa: ANN001, ANN202
        os.kill(os.getpid(), signal.SIGTERM)
        return update_run(self, run_id, *args, **kwargs)

    monkeypatch.setattr(MlflowClient, "update_run", stopped_while_updating)
    with pytest.raises(SystemExit):
        run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    monkeypatch.undo()
    (train,) = runs(launch, "train")
    assert train.info.status == "KILLED"
    assert len(learner.calls) == 1  # stopped before it trained again


def _run_in_a_process(launch: Path, key: str) -> tuple[subprocess.Popen, str]:
    """Another process opens a training run of `key` and keeps working on it (sleeps)."""
    code = (
        "import sys, time\n"
        "from pathlib import Path\n"
        "from hgm_repro.app.store import Tracker, resolve_location\n"
        "tracker = Tracker(resolve_location({}, Path(sys.argv[1])), 'hgm_repro')\n"
        "print(tracker.start_run('train-other', {'stage': 'train', 'train_key': sys.argv[2]}), flush=True)\n"
        "time.sleep(600)\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(CONF_DIR.parent), os.environ.get("PYTHONPATH", "")])}
    other = subprocess.Popen([sys.executable, "-c", code, str(launch), key], stdout=subprocess.PIPE, text=True,
                             env=env)
    return other, other.stdout.readline().strip()


def test_a_killed_process_run_is_closed_and_resumed(launch: Path) -> None:
    """A run stays RUNNING while its process lives; SIGKILLed, the next job marks it KILLED and resumes it."""
    cfg = make_cfg()
    key = train_key(cfg)
    other, run_id = _run_in_a_process(launch, key)
    try:
        assert store(launch).close_orphans() == []  # alive: another job must not close it
        assert store(launch).get_run(run_id).info.status == "RUNNING"
    finally:
        other.send_signal(signal.SIGKILL)
        other.wait()
    (launch / "checkpoints" / key).mkdir(parents=True)
    (launch / "checkpoints" / key / RUN_ID_FILE).write_text(run_id)
    (launch / "checkpoints" / key / "last.pt").write_text("128")
    learner = FakeLearner()
    outcome = run_job(cfg, launch, train_fn=learner, evaluate_fn=fake_evaluate)
    assert outcome.training.how == "resumed" and outcome.training.run_id == run_id
    assert [r.info.status for r in runs(launch, "train")] == ["FINISHED"]


def test_orphans_of_every_stage_are_closed(launch: Path) -> None:
    """Runs of any stage left by a dead pid on this host (no lock file: an older job) are closed."""
    tracker = store(launch)
    ids = [tracker.start_run(f"dead-{stage}", {"stage": stage, "train_key": "other"}) for stage in ("train", "eval")]
    for run_id in ids:
        tracker.set_tags(run_id, {"pid": "999999999"})  # no such process
        lock = tracker._held.pop(run_id)  # as if written before run locks existed
        Path(lock.lock_file).unlink()
        lock.release()
    run_job(make_cfg("model=human"), launch, train_fn=FakeLearner(), evaluate_fn=fake_evaluate)
    assert {store(launch).get_run(run_id).info.status for run_id in ids} == {"KILLED"}


class LogsPastItsCheckpoint(FakeLearner):
    """Logs step 192 but dies before its checkpoint records it (SIGKILL between the two writes)."""

    def __call__(self, cfg: DictConfig, checkpoint_dir: Path, log) -> Path:
        if self.interrupt_after is None:
            return super().__call__(cfg, checkpoint_dir, log)
        self.calls.append(checkpoint_dir)
        for step in (64, 128):
            log({"train/loss": 1.0 / step}, step)
            (checkpoint_dir / "last.pt").write_text(str(step))
        log({"train/loss": 1.0}, 192)
        self.interrupt_after = None
        raise JobInterrupted()


def test_a_resumed_run_logs_each_step_once(launch: Path) -> None:
    learner = LogsPastItsCheckpoint(interrupt_after=192)
    with pytest.raises(SystemExit):
        run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    (train,) = runs(launch, "train")
    history = store(launch).client.get_metric_history(train.info.run_id, "train/loss")
    assert sorted(m.step for m in history) == [64, 128, 192, 256]


def test_a_finished_evaluation_is_not_repeated(launch: Path) -> None:
    first = run_job(make_cfg(), launch, train_fn=FakeLearner(), evaluate_fn=fake_evaluate)
    again = run_job(make_cfg(), launch, train_fn=FakeLearner(), evaluate_fn=fake_evaluate)
    assert again.eval_run_id == first.eval_run_id and again.means == first.means
    assert len(runs(launch, "eval")) == 1
    other = run_job(make_cfg("eval.test_steps=32"), launch, train_fn=FakeLearner(), evaluate_fn=fake_evaluate)
    assert other.eval_run_id != first.eval_run_id and len(runs(launch, "eval")) == 2


def _lose_the_network(launch: Path, train_run_id: str) -> None:
    """The trained network gone from this machine and from the store, as after a move to a fresh machine
    that carried the store's database but not networks too large for git."""
    shutil.rmtree(launch / "checkpoints")
    artifacts = store(launch).client.get_run(train_run_id).info.artifact_uri.removeprefix("file://")
    shutil.rmtree(Path(artifacts) / "checkpoint")


def test_a_tested_training_needs_no_network_until_a_new_test(launch: Path) -> None:
    first = run_job(make_cfg(), launch, train_fn=FakeLearner(), evaluate_fn=fake_evaluate)
    _lose_the_network(launch, first.training.run_id)
    learner = FakeLearner()
    again = run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    assert not learner.calls and again.training.how == "reused"
    assert again.training.run_id == first.training.run_id and again.eval_run_id == first.eval_run_id
    assert len(runs(launch, "train")) == 1 and len(runs(launch, "eval")) == 1
    # A test not yet run needs the network: with none left, the key trains again.
    other = run_job(make_cfg("eval.test_steps=32"), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    assert len(learner.calls) == 1 and other.training.how == "trained"
    # force_retrain asks for a new training even where the test is done.
    forced = run_job(make_cfg("force_retrain=true", "eval.test_steps=32"), launch, train_fn=learner,
                     evaluate_fn=fake_evaluate)
    assert len(learner.calls) == 2 and forced.training.run_id not in {first.training.run_id,
                                                                      other.training.run_id}
    # The newest training is the one a test reads: the first test, done on an older one, does not stand for it.
    newest = run_job(make_cfg(), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    assert newest.training.run_id == forced.training.run_id and newest.eval_run_id != first.eval_run_id
    assert len(learner.calls) == 2


def test_a_store_from_another_version_is_named(launch: Path) -> None:
    tracker = store(launch)
    tracker.client.set_experiment_tag(tracker.experiment_id, STORE_FORMAT_TAG, "0")
    with pytest.raises(StoreError, match="another version of hgm_repro"):
        store(launch)


def test_a_checkpoint_from_another_version_or_half_written_is_refused(tmp_path: Path) -> None:
    import torch

    from hgm_repro.contracts.checkpoint import CheckpointMismatchError, load_checkpoint, save_checkpoint

    path = save_checkpoint({"format": 99}, tmp_path / "last.pt")
    with pytest.raises(CheckpointMismatchError, match="another version of hgm_repro"):
        load_checkpoint(path)
    torch.save({"format": 1, "weights": torch.zeros(1000)}, path)
    path.write_bytes(path.read_bytes()[:500])  # cut short, as by a crash of a non-atomic writer
    with pytest.raises(CheckpointMismatchError, match="cannot be read"):
        load_checkpoint(path)


def test_non_learning_driver_only_evaluates(launch: Path) -> None:
    learner = FakeLearner()
    outcome = run_job(make_cfg("model=human"), launch, train_fn=learner, evaluate_fn=fake_evaluate)
    assert outcome.training.how == "none" and not learner.calls
    assert runs(launch, "train") == [] and len(runs(launch, "eval")) == 1


@pytest.mark.parametrize("override,says", [
    ("learner.lr=-1", "learner.lr=-1"),
    ("observation.height=20", "observation.height=20"),  # the builders' own rule: the conv stack needs 36
    ("observation.camera_fov_deg=175", "camera_fov_deg"),
    ("simulator.lanes=0", "lanes"),
])
def test_bad_value_stops_before_the_store_is_touched(tmp_path: Path, override: str, says: str) -> None:
    from hgm_repro.contracts.errors import ConfigError

    with pytest.raises(ConfigError, match=says):
        run_job(make_cfg(override), tmp_path, train_fn=FakeLearner(), evaluate_fn=fake_evaluate)
    assert not (tmp_path / "mlflow.db").exists() and not os.listdir(tmp_path)


class ValidatingLearner(FakeLearner):
    """Like the learner with validation on: logs `val/episode_return`, keeps best.pt at its best."""

    def __init__(self, returns: tuple[float, ...] = (3.0, 7.5, 5.0), keep_best: bool = True,
                 evaluation_version: int = EVALUATION_VERSION) -> None:
        super().__init__()
        self.returns, self.keep_best, self.evaluation_version = returns, keep_best, evaluation_version

    def __call__(self, job: JobConfig, checkpoint_dir: Path, log) -> Path:
        for step, value in enumerate(self.returns, start=1):
            log({"val/episode_return": value}, 64 * step)
        if self.keep_best:
            save_checkpoint({"format": CHECKPOINT_FORMAT, "network": {}, "evaluation_version": self.evaluation_version},
                            checkpoint_dir / "best.pt")
        return super().__call__(job, checkpoint_dir, log)


class RecordingEvaluate:
    def __init__(self) -> None:
        self.checkpoints: list[Path | None] = []

    def __call__(self, job: JobConfig, scenario: ScenarioConfig, checkpoint: Path | None) -> SimpleNamespace:
        self.checkpoints.append(checkpoint)
        return fake_evaluate(job, scenario, checkpoint)


VALIDATION_ON = "eval.val_every=64"


def test_job_returns_the_best_validation_return_never_the_test_return(launch: Path) -> None:
    outcome = run_job(make_cfg("scenario='3'", VALIDATION_ON), launch, train_fn=ValidatingLearner(),
                      evaluate_fn=fake_evaluate)
    assert outcome.validation_return == 7.5  # the best of 3.0, 7.5, 5.0; the test return is 11.0
    assert outcome.means["eval/episode_return"] == 11.0
    # A reused training gives the same value, read from its run in the store.
    again = run_job(make_cfg("scenario='5'", VALIDATION_ON), launch, train_fn=ValidatingLearner(),
                    evaluate_fn=fake_evaluate)
    assert again.training.how == "reused" and again.validation_return == 7.5
    # Without validation there is nothing to hand a sweeper.
    plain = run_job(make_cfg("scenario='3'", "seed=4", "eval.val_every=0"), launch, train_fn=FakeLearner(),
                    evaluate_fn=fake_evaluate)
    assert plain.validation_return is None


def test_eval_checkpoint_best_evaluates_best_pt(launch: Path) -> None:
    evaluate = RecordingEvaluate()
    final = run_job(make_cfg(VALIDATION_ON), launch, train_fn=ValidatingLearner(), evaluate_fn=evaluate)
    best = run_job(make_cfg(VALIDATION_ON, "eval.checkpoint=best"), launch, train_fn=ValidatingLearner(),
                   evaluate_fn=evaluate)
    assert [c.name for c in evaluate.checkpoints] == ["final.pt", "best.pt"]
    assert best.training.run_id == final.training.run_id  # the same training, another file of it
    tags = store(launch).get_run(best.eval_run_id).data.tags
    assert tags["checkpoint"] == "best"
    names = [a.path for a in store(launch).client.list_artifacts(final.training.run_id, "checkpoint")]
    assert names == ["checkpoint/best.pt", "checkpoint/final.pt"]


def test_eval_checkpoint_best_without_best_pt_fails_clearly(launch: Path) -> None:
    with pytest.raises(ConfigError, match="eval.checkpoint=best is not allowed with eval.val_every=0"):
        check_config(make_cfg("eval.checkpoint=best", "eval.val_every=0"))
    # Validation asked for, but the training kept no best.pt (trained by older code, say).
    with pytest.raises(ConfigError, match=r"kept no best.pt .*eval.checkpoint=final"):
        run_job(make_cfg(VALIDATION_ON, "eval.checkpoint=best"), launch,
                train_fn=ValidatingLearner(keep_best=False), evaluate_fn=fake_evaluate)
    assert runs(launch, "eval") == []  # stopped before an evaluation run was opened
    # A best.pt chosen by the validation of before evaluation version 2 (blank frames) is not tested as
    # the best: the job names the versions and what it can test instead.
    with pytest.raises(ConfigError, match=r"chosen by the validation of before evaluation version 2.*"
                                          r"eval.checkpoint=final, or eval.checkpoint=reselected"):
        run_job(make_cfg(VALIDATION_ON, "eval.checkpoint=best", "seed=3"), launch,
                train_fn=ValidatingLearner(evaluation_version=1), evaluate_fn=fake_evaluate)
    assert runs(launch, "eval") == []
    with pytest.raises(ConfigError, match="eval.checkpoint='last' is not allowed"):
        check_config(make_cfg("eval.checkpoint=last"))


def test_metric_values_are_python_floats_without_float32_noise(launch: Path) -> None:
    import numpy as np

    assert tidy_number(np.float32(59.999992)) == 60.0
    assert tidy_number(np.float32(0.1)) == 0.1 and tidy_number(1234567) == 1234567.0
    assert tidy_number(float("nan")) != tidy_number(float("nan"))
    tracker = store(launch)
    run_id = tracker.start_run("noise", {"stage": "eval"})
    tracker.log_metrics(run_id, {"eval/avg_speed_kmh": np.float32(60.0) - np.float32(7.6e-6)}, step=0)
    assert tracker.get_run(run_id).data.metrics["eval/avg_speed_kmh"] == 60.0


def test_system_metrics_on_request(launch: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MLFLOW_SYSTEM_METRICS_SAMPLING_INTERVAL", "0.2")

    class SlowLearner(FakeLearner):
        def __call__(self, job, checkpoint_dir, log):
            import time

            time.sleep(1.5)
            return super().__call__(job, checkpoint_dir, log)

    outcome = run_job(make_cfg("tracking.system_metrics=true"), launch, train_fn=SlowLearner(),
                      evaluate_fn=fake_evaluate)
    metrics = store(launch).get_run(outcome.training.run_id).data.metrics
    assert "system/cpu_utilization_percentage" in metrics and "system/system_memory_usage_megabytes" in metrics
    off = run_job(make_cfg("tracking.system_metrics=false", "seed=3"), launch, train_fn=FakeLearner(),
                  evaluate_fn=fake_evaluate)
    assert not any(k.startswith("system/") for k in store(launch).get_run(off.training.run_id).data.metrics)


class CheckpointLearner(FakeLearner):
    """Writes real checkpoints: final.pt with an optimiser and a replay memory, best.pt beside it."""

    def __call__(self, job: JobConfig, checkpoint_dir: Path, log) -> Path:
        import torch

        from hgm_repro.contracts.checkpoint import recorded_training_config, save_checkpoint

        log({"train/epsilon": 0.7750020027160645}, 64)
        state = {"format": 1, "model": job.model.name, "train_key": train_key(job), "finished": True,
                 "training_config": recorded_training_config(job), "network": {"w": torch.ones(3)},
                 "optimizer": {"m": torch.ones(1000)}, "replay_buffer": {"obs": torch.ones(100_000)}}
        save_checkpoint({**state, "replay_buffer": None}, checkpoint_dir / "best.pt")
        return save_checkpoint(state, checkpoint_dir / "final.pt")


def test_artifacts_hold_weights_and_episodes_csv_is_plain(launch: Path) -> None:
    """The logged checkpoints are the weights only (the replay memory stays in the local final.pt);
    episodes.csv has one column per name and numbers as people write them; epsilon has no tail."""
    import torch

    def evaluate(job, scenario, checkpoint):
        episodes = pd.DataFrame({"env": [0, 1], "episode": [0, 0], "avg_speed_kmh": [75.400024, 60.0],
                                 "collisions": [1.0, 0.0], "episode_return": [17.745522, -1.2023659]})
        return SimpleNamespace(episodes=episodes, means={"eval/episode_return": 8.27})

    out = run_job(make_cfg(), launch, train_fn=CheckpointLearner(), evaluate_fn=evaluate)
    tracker = store(launch)
    fetched = tracker.download(out.training.run_id, "checkpoint", launch / "fetched")
    for name in ("final.pt", "best.pt"):
        artifact = torch.load(fetched / name, weights_only=False)
        assert "network" in artifact and "replay_buffer" not in artifact and "optimizer" not in artifact
    local = torch.load(out.training.checkpoint, weights_only=False)
    assert local["replay_buffer"] is not None  # what a longer training would resume from: kept once, here
    history = tracker.client.get_metric_history(out.training.run_id, "train/epsilon")
    assert [m.value for m in history] == [0.775]
    text = (tracker.download(out.eval_run_id, "episodes.csv", launch / "eps")).read_text().splitlines()
    assert text[0] == "env,episode,avg_speed_kmh,collisions,episode_return"
    assert text[1:] == ["0,0,75.4,1,17.7455", "1,0,60.0,0,-1.20237"]
