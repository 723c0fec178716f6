"""The command line: help, printed config, and bad values that stop before any work (subprocesses)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
import yaml

from hgm_repro.__main__ import quote_numeric_choices
from hgm_repro.contracts.conf_dir import CONF_DIR
from tests.helpers.cli import hgm

# Every test here checks the exit code itself, and the command line answers in seconds.
QUICK = {"check": False, "timeout": 120}


def test_help_lists_groups_options_and_examples(tmp_path: Path) -> None:
    out = hgm(tmp_path, "--help", **QUICK)
    assert out.returncode == 0, out.stderr
    for line in ("experiment: paper, paper_pixels, paper_steps, quick, quick160, smoke",
                 "launcher: basic, joblib", "learner: dqn",
                 "model: coordinate, coordinate_guarded, human, idm_limits, idm_mobil, idm_mobil_limits, min, "
                 "min_guarded, proposed, proposed_enriched, proposed_guarded, random",
                 "scenario: 1, 2, 3, 4, 5, train",
                 "simulator: highway", "tracking: sqlite", "eval: default", "runtime: default", "logging: default",
                 "grid: paper, references"):
        assert line in out.stdout
    for example in ("-m scenario=1,2,3,4,5 model=proposed,min,coordinate", "-m grid=paper", "seed=0,1",
                    "experiment=paper",
                    "device=cuda", "tracking.uri=http://", "hydra/launcher=joblib", "mlflow ui"):
        assert example in out.stdout, example


def test_cfg_job_prints_the_composed_config(tmp_path: Path) -> None:
    out = hgm(tmp_path, "--cfg", "job", "experiment=smoke", "scenario=3", "model=min", "seed=2", **QUICK)
    assert out.returncode == 0, out.stderr
    cfg = yaml.safe_load(out.stdout)
    assert cfg["scenario"]["name"] == "3" and cfg["model"]["name"] == "min" and cfg["seed"] == 2
    assert cfg["learner"]["total_steps"] == 256 and cfg["train_scenario"]["name"] == "train"
    assert "hydra" not in cfg
    assert list(tmp_path.iterdir()) == []  # printing the config runs nothing


def test_numeric_group_choices_are_quoted_for_hydra() -> None:
    assert quote_numeric_choices(["scenario=3", "scenario=1,2,3", "seed=0,1", "learner.lr=1"]) == [
        "scenario='3'", "scenario='1','2','3'", "seed=0,1", "learner.lr=1"]
    assert quote_numeric_choices(["scenario@train_scenario=5", "+scenario=2"]) == [
        "scenario@train_scenario='5'", "+scenario='2'"]


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("scenario=7", ["scenario=7 is not allowed: expected one of 1, 2, 3, 4, 5, train"]),
        ("model=nope", ["model=nope is not allowed", "proposed", "idm_mobil"]),
        ("experiment=nope", ["experiment=nope is not allowed", "smoke", "paper"]),
        ("learner.nope=1", ["learner.nope is not a config key"]),
        ("learner.lr=-1", ["learner.lr=-1 is not allowed: must be > 0"]),
        ("learner.batch_size=abc", ["learner.batch_size='abc' is not allowed: expected an integer"]),
        ("seed=-3", ["seed=-3 is not allowed"]),
        ("device=tpu", ["device='tpu' is not allowed"]),
        ("simulator.lanes=0", ["simulator.lanes=0 is not allowed"]),
    ],
)
def test_bad_value_stops_before_any_work(tmp_path: Path, override: str, expected: list[str]) -> None:
    out = hgm(tmp_path, "experiment=smoke", override, **QUICK)
    assert out.returncode == 2, out.stderr
    for text in expected:
        assert text in out.stderr, (text, out.stderr[-2000:])
    # Nothing at all, not even Hydra's output dir: validation runs before the job opens anything.
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("override", "says"), [
    ("scenario=7", "scenario=7 is not allowed: expected one of 1, 2, 3, 4, 5, train"),
    ("learner.lr=-1", "learner.lr=-1 is not allowed: must be > 0"),
    # A mistyped key, plain or added with +, is refused with the nearest key that exists.
    ("learner.lrr=0.1", "learner.lrr is not a config key; did you mean learner.lr?"),
    ("+learner.lrr=0.1", "learner.lrr is not a config key; did you mean learner.lr?"),
    ("scenaro=3", "scenaro is not a config key; did you mean scenario?"),
    ("tracking.uri=foo://bar", "tracking.uri='foo://bar' is not allowed: MLflow stores runs only under the schemes "
                               "sqlite, file, http, https, postgresql"),
])
def test_bad_input_is_one_line_exit_2_and_leaves_nothing(tmp_path: Path, override: str, says: str) -> None:
    """The acceptance commands: one message, no traceback, exit code 2, no store, run, checkpoint or dir, and
    before the heavy imports (torch, MLflow: seconds on a busy machine), which Python's import log shows."""
    out = hgm(tmp_path, override, env={"PYTHONPROFILEIMPORTTIME": "1"}, **QUICK)
    assert out.returncode == 2, out.stderr
    imported = {line.rsplit("|", 1)[-1].strip() for line in out.stderr.splitlines() if line.startswith("import time:")}
    assert imported and not imported & {"torch", "mlflow", "torchrl", "tensordict", "pandas"}, sorted(imported)
    lines = [line for line in out.stderr.splitlines() if line.strip() and not line.startswith("import time:")]
    assert len(lines) == 1 and says in lines[0], out.stderr
    assert "Traceback" not in out.stderr + out.stdout and out.stdout == ""
    assert list(tmp_path.iterdir()) == []


def test_bad_value_in_a_sweep_launches_nothing(tmp_path: Path) -> None:
    out = hgm(tmp_path, "-m", "experiment=smoke", "learner.lr=-1", "seed=0,1", **QUICK)
    assert out.returncode == 2
    assert "learner.lr=-1 is not allowed" in out.stderr and "nothing was launched" in out.stderr
    assert "Launching" not in out.stdout + out.stderr and not (tmp_path / "mlflow.db").exists()


@pytest.mark.parametrize(("sweep", "says"), [
    ("scenario=1,9", "scenario=9 is not allowed: expected one of 1, 2, 3, 4, 5, train"),
    ("learner.lr=0.1,-1", "learner.lr=-1 is not allowed: must be > 0"),
    ("learner.lrr=0.1,0.2", "learner.lrr is not a config key; did you mean learner.lr?"),
])
def test_bad_swept_value_is_one_line_and_leaves_no_file(tmp_path: Path, sweep: str, says: str) -> None:
    """A value bad in one job of the sweep stops it before Hydra starts: no store, no directory."""
    out = hgm(tmp_path, "-m", "experiment=smoke", sweep, "seed=0,1", **QUICK)
    assert out.returncode == 2, out.stderr
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and says in lines[0] and lines[0].endswith("nothing was launched"), out.stderr
    assert list(tmp_path.iterdir()) == []


def test_launcher_presets_compose(tmp_path: Path) -> None:
    out = hgm(tmp_path, "launcher=joblib", "--cfg", "hydra", **QUICK)
    assert out.returncode == 0, out.stderr
    launcher = yaml.safe_load(out.stdout)["hydra"]["launcher"]
    assert launcher["_target_"].endswith("JoblibLauncher") and launcher["n_jobs"] == 2


@pytest.mark.parametrize(("preset", "plugin", "target"), [
    ("slurm", "hydra_plugins.hydra_submitit_launcher", "submitit_slurm"),
    ("ray", "hydra_plugins.hydra_ray_launcher", "ray"),
])
def test_cluster_launcher_presets(tmp_path: Path, preset: str, plugin: str, target: str) -> None:
    text = (CONF_DIR / "launcher" / f"{preset}.yaml").read_text()
    assert text.startswith("# @package _global_")
    node = yaml.safe_load(text)
    assert node["defaults"] == [{"override /hydra/launcher": target}]
    try:
        found = importlib.util.find_spec(plugin) is not None
    except ModuleNotFoundError:
        found = False
    if not found:
        pytest.skip(f"{plugin} is not installed (pip install '.[{preset}]')")
    out = hgm(tmp_path, f"launcher={preset}", "--cfg", "hydra", **QUICK)
    assert out.returncode == 0, out.stderr
    assert yaml.safe_load(out.stdout)["hydra"]["launcher"]["_target_"].startswith("hydra_plugins")


def test_optuna_preset_tunes_learner_values_on_the_training_traffic(tmp_path: Path) -> None:
    text = (CONF_DIR / "hparams_search" / "optuna_val.yaml").read_text()
    assert text.startswith("# @package _global_")
    if importlib.util.find_spec("hydra_plugins.hydra_optuna_sweeper") is None:
        pytest.skip("hydra-optuna-sweeper is not installed (pip install '.[optuna]')")
    out = hgm(tmp_path, "hparams_search=optuna_val", "--cfg", "all", **QUICK)
    assert out.returncode == 0, out.stderr
    composed = yaml.safe_load(out.stdout)
    sweeper = composed["hydra"]["sweeper"]
    assert sweeper["_target_"].endswith("OptunaSweeper") and sweeper["direction"] == "maximize"
    assert set(sweeper["params"]) == {"learner.lr", "learner.n_step"}
    assert composed["scenario"]["name"] == "train"  # trials never look at a test scenario
