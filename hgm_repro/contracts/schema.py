"""The typed shape of a job's config, checked at job start before any work is done.

Hydra already rejects unknown config-group options (`scenario=7`, `model=nope`) and unknown
keys (struct mode). What it cannot know is that `learner.lr=-1` or `learner.batch_size=abc`
is nonsense: command-line values arrive as whatever YAML makes of them. `check_config(cfg)`
checks every value named here against its type and range, the observation node through the
observation builders' `ObservationConfig`, the simulator and scenario nodes through the
simulator's own validated configs (each rule lives once, with the part it protects), and raises
one `ConfigError` listing every problem. Keys that a part adds and this schema does not name are left to that part.
"""

from __future__ import annotations

import dataclasses
import re
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, Literal

from omegaconf import DictConfig

from .config_files import scenario_config, simulator_config
from .config_tree import plain
from .errors import ConfigError
from .observation_config import ObservationConfig
from .simulator_config import ScenarioConfig, SimulatorConfig


@dataclass(frozen=True)
class Check:
    """A range rule on a value, with the words the error message uses for it."""

    test: Callable[[Any], bool]
    says: str


def gt(x: float) -> dict[str, Check]:
    return {"check": Check(lambda v: v > x, f"must be > {x}")}


def ge(x: float) -> dict[str, Check]:
    return {"check": Check(lambda v: v >= x, f"must be >= {x}")}


def unit() -> dict[str, Check]:
    return {"check": Check(lambda v: 0.0 <= v <= 1.0, "must lie in [0, 1]")}


# eval.checkpoint=safest judges collisions per episode on at least this many validation episodes: on
# fewer, a pass with one crash in 20 cannot be told from a safe one.
SAFEST_MIN_EPISODES = 256

DEVICE_PATTERN = re.compile(r"^(cpu|cuda(:\d+)?|mps)$")

# Where MLflow can keep runs (its tracking store registry); `postgresql+psycopg2://` counts as postgresql.
TRACKING_SCHEMES = ("sqlite", "file", "http", "https", "postgresql", "mysql", "mssql", "databricks")
TRACKING_EXAMPLES = "sqlite:///path/mlflow.db, file:///path/mlruns, http(s)://host:5000, postgresql://user@host/db"


@dataclass(frozen=True)
class LearnerSchema:
    """The algorithm: every value here shapes the trained weights (the training identity hashes all
    of it). Defaults live in conf/learner/dqn.yaml, not here."""

    name: str
    lr: float = field(metadata=gt(0))
    gamma: float = field(metadata=unit())
    batch_size: int = field(metadata=ge(1))
    warmup_steps: int = field(metadata=ge(0))
    buffer_size: int = field(metadata=ge(1))
    target_update_steps: int = field(metadata=ge(1))
    total_steps: int = field(metadata=ge(1))
    eps_start: float = field(metadata=unit())
    eps_end: float = field(metadata=unit())
    eps_steps: int = field(metadata=ge(1))
    update_every: int = field(metadata=ge(1))
    double_dqn: bool
    per_alpha: float = field(metadata=ge(0))
    per_beta_start: float = field(metadata=unit())
    per_beta_end: float = field(metadata=unit())
    n_envs: int = field(metadata=ge(1))
    max_grad_norm: float = field(metadata=gt(0))
    n_step: int = field(metadata=ge(1))
    reward_scale: float = field(metadata=gt(0))
    collision_weight: float = field(metadata=gt(0))
    loss_function: Literal["l2", "l1", "smooth_l1"]
    # Learning options beyond the paper (hgm_repro.learner.exploration, member); each
    # default in dqn.yaml trains as the learner did before the option existed.
    eps_floor: float = field(metadata=unit())
    eps_floor_steps: int = field(metadata=ge(0))
    random_lane_change_share: float = field(metadata=unit())
    adam_eps: float = field(metadata=gt(0))
    target_tau: float = field(metadata=unit())
    ema_decay: float = field(metadata=unit())


@dataclass(frozen=True)
class RuntimeSchema:
    """How a job runs, never what it computes: threads, compilation, CUDA graphs, the update's
    precision, grouping seeds in one process, the replay memory's layout and how much of it a
    checkpoint keeps (conf/runtime/default.yaml). Outside the training and evaluation identities,
    like `device`."""

    torch_threads: int = field(metadata=ge(0))
    compile: bool
    cuda_graph: bool
    update_dtype: Literal["auto", "float32", "bfloat16"]
    overlap: Literal["auto", True, False]
    grouped: Literal["auto", True, False]
    replay_frames: bool
    checkpoint_buffer_max_mb: float = field(metadata=ge(0))


@dataclass(frozen=True)
class LoggingSchema:
    """How often a training reports and saves (conf/logging/default.yaml), in env steps."""

    log_every: int = field(metadata=ge(1))
    checkpoint_every: int = field(metadata=ge(1))


@dataclass(frozen=True)
class ModelSchema:
    name: str
    learned: bool
    streams: dict[str, Any]  # checked by ObservationConfig, which owns the observation rules
    network: dict[str, Any] | None = None  # learned models: instantiated with `_target_`
    driver: dict[str, Any] | None = None  # non-learning hosts: instantiated with `_target_`
    # A learned host under the human-driven host's safety layer (conf/model/*_guarded.yaml). Absent from
    # the paper's models' configs, so that their training identities stay what they were.
    safety_layer: bool = False


@dataclass(frozen=True)
class TrackingSchema:
    """Where runs and checkpoints go and what a run logs besides metrics (conf/tracking/sqlite.yaml)."""

    uri: str | None
    experiment_name: str
    artifact_dir: str | None
    checkpoint_dir: str | None
    log_gif: bool
    log_model: bool
    system_metrics: bool


@dataclass(frozen=True)
class EvalSchema:
    """The test (decisions, envs, which checkpoint drives) and the validation passes during training
    that choose best.pt (conf/eval/default.yaml)."""

    checkpoint: Literal["final", "best", "ema", "reselected", "safest"]
    test_steps: int = field(metadata=ge(1))
    test_envs: int = field(metadata=ge(1))
    val_every: int = field(metadata=ge(0))
    val_envs: int = field(metadata=ge(1))
    val_episodes: int = field(metadata=ge(1))
    keep_val_checkpoints: bool
    reselect_top: int = field(metadata=ge(1))
    reselect_envs: int = field(metadata=ge(1))
    reselect_episodes: int = field(metadata=ge(1))
    safest_max_collisions: float = field(metadata=ge(0))
    safest_episodes: int = field(metadata=ge(SAFEST_MIN_EPISODES))
    safest_envs: int = field(metadata=ge(1))
    host_safety_layer: bool


@dataclass(frozen=True)
class ExperimentSchema:
    name: str


@dataclass(frozen=True)
class JobConfig:
    """What `check_config` hands back, and what `train`, `evaluate` and `make_env` receive: the typed
    parts plus the simulator's and the observation builders' own validated configs.

    `model.network` / `model.driver` stay plain `_target_` mappings (Hydra instantiates them), and
    `resolved` is the whole resolved tree as plain data: the training identity hashes it
    (`train_key`), runs log it. No part reads a setting from `resolved`.
    """

    seed: int
    device: str
    force_retrain: bool
    learner: LearnerSchema
    observation: ObservationConfig
    model: ModelSchema
    tracking: TrackingSchema
    experiment: ExperimentSchema
    eval: EvalSchema
    runtime: RuntimeSchema
    logging: LoggingSchema
    simulator: SimulatorConfig
    scenario: ScenarioConfig
    train_scenario: ScenarioConfig
    resolved: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)


# What a test of a learned host under the layer only at test (eval.host_safety_layer) is called in its
# results: never the name of the model it trained as, whose results mean the paper's setting.
LAYER_AT_TEST_SUFFIX = "_layer_at_test"
# What a test of the safest kept validation pass (eval.checkpoint=safest) is called in its results: it sits
# beside the same training's test of the preset's own network, never in its place.
SAFEST_SUFFIX = "_safest"


def results_model_name(job: JobConfig) -> str:
    """The model a test's run and results are named by: `job.model.name`, then `_layer_at_test` when a
    learned host trained without the safety layer is tested under it, then `_safest` when the test drives
    the safest kept validation pass."""
    name = job.model.name + (LAYER_AT_TEST_SUFFIX if job.eval.host_safety_layer else "")
    return name + (SAFEST_SUFFIX if job.eval.checkpoint == "safest" else "")


def _type_name(tp: Any) -> str:
    if typing.get_origin(tp) is Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(tp))
    names = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}
    if tp in names:
        return names[tp]
    if isinstance(tp, types.UnionType):
        return " or ".join(_type_name(a) if a is not type(None) else "null" for a in typing.get_args(tp))
    if typing.get_origin(tp) is dict:
        return "a mapping"
    return getattr(tp, "__name__", str(tp))


def _matches(tp: Any, value: Any) -> bool:
    if tp is Any:
        return True
    if tp is type(None):
        return value is None
    if isinstance(tp, types.UnionType):
        return any(_matches(a, value) for a in typing.get_args(tp))
    if typing.get_origin(tp) is Literal:
        return value in typing.get_args(tp)
    if typing.get_origin(tp) is dict:
        return isinstance(value, Mapping)
    if tp is bool:
        return isinstance(value, bool)
    if tp is int:  # YAML's `true` is not a count
        return isinstance(value, int) and not isinstance(value, bool)
    if tp is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return isinstance(value, tp)


def check_node(schema: type, node: Any, where: str, errors: list[str]) -> Any:
    """Build `schema` from `node`, appending one message per bad value to `errors`."""
    if not isinstance(node, Mapping):
        errors.append(f"{where}={node!r} is not allowed: expected a mapping")
        return None
    hints = typing.get_type_hints(schema)
    values: dict[str, Any] = {}
    for f in fields(schema):
        path = f"{where}.{f.name}" if where else f.name
        if f.name not in node:
            if f.default is MISSING:
                errors.append(f"{path} is missing: expected {_type_name(hints[f.name])}")
            continue
        value, tp = node[f.name], hints[f.name]
        if isinstance(tp, type) and hasattr(tp, "__dataclass_fields__"):
            values[f.name] = check_node(tp, value, path, errors)
            continue
        if not _matches(tp, value):
            errors.append(f"{path}={value!r} is not allowed: expected {_type_name(tp)}")
            continue
        rule: Check | None = f.metadata.get("check")
        if rule is not None and not rule.test(value):
            errors.append(f"{path}={value!r} is not allowed: {rule.says}")
            continue
        values[f.name] = float(value) if tp is float else value
    try:
        return schema(**values)
    except TypeError:  # a required field was reported missing above
        return None


def _check_model(model: Any, errors: list[str]) -> None:
    if not isinstance(model, ModelSchema):
        return
    if model.safety_layer and not model.learned:
        errors.append(f"model.safety_layer=true is not allowed for the non-learning model {model.name!r}: its driver "
                      "decides (model.driver.safety_layer)")
    part = "network" if model.learned else "driver"
    node = model.network if model.learned else model.driver
    if not node or "_target_" not in node:
        kind = "learned" if model.learned else "non-learning"
        errors.append(f"model.{part} with a `_target_` is required for a {kind} model ({model.name!r})")


def _check_device(device: Any, errors: list[str]) -> None:
    if not isinstance(device, str) or not DEVICE_PATTERN.match(device):
        errors.append(f"device={device!r} is not allowed: expected cpu, cuda, cuda:N or mps")
        return
    if device.startswith("cuda"):
        import torch  # only when asked: keeps validation of CPU jobs light

        if not torch.cuda.is_available():
            errors.append(f"device={device!r} is not available here: torch.cuda.is_available() is False")
        elif ":" in device and int(device.split(":")[1]) >= torch.cuda.device_count():
            errors.append(f"device={device!r} is not available: {torch.cuda.device_count()} CUDA device(s)")


def _check_eval(evaluation: Any, model: Any, learner: Any, errors: list[str]) -> None:
    learned = isinstance(model, ModelSchema) and model.learned
    if isinstance(evaluation, EvalSchema) and evaluation.checkpoint == "best" and learned:
        if not evaluation.val_every:
            errors.append("eval.checkpoint=best is not allowed with eval.val_every=0: without validation "
                          "training keeps no best.pt (set eval.val_every=N, or eval.checkpoint=final)")
    if isinstance(evaluation, EvalSchema) and evaluation.checkpoint == "reselected" and learned:
        if not evaluation.val_every or not evaluation.keep_val_checkpoints:
            errors.append(f"eval.checkpoint=reselected is not allowed with eval.val_every={evaluation.val_every} "
                          f"and eval.keep_val_checkpoints={str(evaluation.keep_val_checkpoints).lower()}: "
                          "reselection re-checks the networks of the best validation passes, which training keeps "
                          "only with both on (set eval.val_every=N eval.keep_val_checkpoints=true, or "
                          "eval.checkpoint=best)")
    if isinstance(evaluation, EvalSchema) and evaluation.checkpoint == "safest" and learned:
        if not evaluation.val_every or not evaluation.keep_val_checkpoints:
            errors.append(f"eval.checkpoint=safest is not allowed with eval.val_every={evaluation.val_every} "
                          f"and eval.keep_val_checkpoints={str(evaluation.keep_val_checkpoints).lower()}: it "
                          "chooses among the networks of the validation passes, which training keeps only with both "
                          "on (set eval.val_every=N eval.keep_val_checkpoints=true, or eval.checkpoint=best)")
    if isinstance(evaluation, EvalSchema) and evaluation.host_safety_layer and isinstance(model, ModelSchema):
        if not model.learned:
            errors.append(f"eval.host_safety_layer=true is not allowed for the non-learning model {model.name!r}: "
                          "its driver decides its layer (model.driver.safety_layer)")
        elif model.safety_layer:
            errors.append(f"eval.host_safety_layer=true is not allowed with model={model.name}: it drives under "
                          "the layer already, in training and test")
    if isinstance(evaluation, EvalSchema) and evaluation.checkpoint == "ema" and learned:
        if isinstance(learner, LearnerSchema) and not learner.ema_decay:
            errors.append("eval.checkpoint=ema is not allowed with learner.ema_decay=0: training keeps no moving "
                          "average of the weights (set learner.ema_decay, e.g. 0.999, or eval.checkpoint=final)")


def _check_tracking(tracking: Any, errors: list[str]) -> None:
    if isinstance(tracking, TrackingSchema) and tracking.system_metrics:
        import importlib.util

        if importlib.util.find_spec("psutil") is None:
            errors.append("tracking.system_metrics=true needs psutil, which is not installed "
                          "(pip install 'hgm_repro[system-metrics]')")


def _check_tracking_uri(tracking: Any, errors: list[str]) -> None:
    uri = tracking.uri if isinstance(tracking, TrackingSchema) else None
    if not uri:
        return  # the default SQLite store in the launch dir
    scheme = uri.split("://", 1)[0].split("+", 1)[0].lower() if "://" in uri else ""
    if scheme not in TRACKING_SCHEMES:
        errors.append(f"tracking.uri={uri!r} is not allowed: MLflow stores runs only under the schemes "
                      f"{', '.join(TRACKING_SCHEMES)} (e.g. {TRACKING_EXAMPLES})")


def check_config(cfg: DictConfig | Mapping[str, Any]) -> JobConfig:
    """Check the whole job config; raise `ConfigError` listing every bad value."""
    root = dict(plain(cfg))
    errors: list[str] = []
    parts = {
        "learner": check_node(LearnerSchema, root.get("learner"), "learner", errors),
        "model": check_node(ModelSchema, root.get("model"), "model", errors),
        "tracking": check_node(TrackingSchema, root.get("tracking"), "tracking", errors),
        "experiment": check_node(ExperimentSchema, root.get("experiment"), "experiment", errors),
        "eval": check_node(EvalSchema, root.get("eval"), "eval", errors),
        "runtime": check_node(RuntimeSchema, root.get("runtime"), "runtime", errors),
        "logging": check_node(LoggingSchema, root.get("logging"), "logging", errors),
    }
    _check_model(parts["model"], errors)
    _check_tracking_uri(parts["tracking"], errors)
    seed = root.get("seed")
    if not _matches(int, seed) or seed < 0:
        errors.append(f"seed={seed!r} is not allowed: expected an integer >= 0")
    _check_device(root.get("device"), errors)
    if not isinstance(root.get("force_retrain"), bool):
        errors.append(f"force_retrain={root.get('force_retrain')!r} is not allowed: expected true or false")
    learner = parts["learner"]
    if isinstance(learner, LearnerSchema) and learner.buffer_size < learner.batch_size:
        errors.append(
            f"learner.buffer_size={learner.buffer_size} is not allowed: "
            f"must be >= learner.batch_size={learner.batch_size}"
        )

    if isinstance(learner, LearnerSchema) and learner.eps_floor_steps and learner.eps_floor > learner.eps_end:
        errors.append(f"learner.eps_floor={learner.eps_floor} is not allowed above learner.eps_end={learner.eps_end}: "
                      "the second decay phase only lowers epsilon")
    if isinstance(learner, LearnerSchema) and learner.ema_decay >= 1.0:
        errors.append(f"learner.ema_decay={learner.ema_decay} is not allowed: must be in [0, 1) (0 = off)")
    runtime = parts["runtime"]
    if isinstance(runtime, RuntimeSchema) and runtime.update_dtype == "bfloat16":
        # Only bf16 asks the device (torch): a bad value elsewhere is refused before torch is imported.
        from .runtime_choice import check_update_dtype

        try:
            check_update_dtype(runtime.update_dtype, str(root.get("device", "cpu")))
        except (ValueError, RuntimeError) as e:
            errors.append(str(e))
    _check_eval(parts["eval"], parts["model"], parts["learner"], errors)
    _check_tracking(parts["tracking"], errors)

    # The observation builders and the simulator own their rules; collect their messages with the others.
    observation = None
    if isinstance(parts["model"], ModelSchema):
        try:
            observation = ObservationConfig.from_config(root.get("observation"), parts["model"].streams)
        except ValueError as e:
            errors.append(str(e))

    sim = scenario = train_scenario = None
    try:
        sim = simulator_config(root.get("simulator"))
    except ConfigError as e:
        errors.append(str(e))
    model = parts["model"]
    if sim is not None and isinstance(model, ModelSchema) and model.learned:
        # A learned host's layer is its model's (so that its name says so); a driver's is the driver's.
        if sim.host_safety_layer:
            errors.append(f"simulator.host_safety_layer=true is not allowed with the learned model {model.name!r}: "
                          f"a learned host under the layer is its own model, named as such (model={model.name}"
                          "_guarded, conf/model/*_guarded.yaml)")
        sim = dataclasses.replace(sim, host_safety_layer=model.safety_layer)
    if sim is not None:
        for name in ("scenario", "train_scenario"):
            try:
                built = scenario_config(root.get(name), sim)
            except ConfigError as e:
                errors.append(f"{name}: {e}")
                continue
            scenario, train_scenario = (built, train_scenario) if name == "scenario" else (scenario, built)

    if len(errors) == 1:
        raise ConfigError(f"invalid config: {errors[0]}")
    if errors:
        raise ConfigError("invalid config:\n  " + "\n  ".join(errors))
    return JobConfig(
        seed=seed, device=root["device"], force_retrain=root["force_retrain"], simulator=sim,
        scenario=scenario, train_scenario=train_scenario, observation=observation, resolved=root, **parts,
    )
