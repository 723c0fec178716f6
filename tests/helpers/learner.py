"""Tiny job configs for in-process training, and a `log` callable that keeps what it was given."""

from __future__ import annotations

from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from hgm_repro.contracts.conf_dir import CONF_DIR
from hgm_repro.contracts.schema import JobConfig, check_config

# Tiny on top of the smoke preset, so that every test trains in a few seconds. The observation
# sizes repeat smoke.yaml's: they make the test independent of how the root config orders presets.
TINY = ["experiment=smoke", "observation.height=36", "observation.width=36", "observation.frame_stack=2",
        "learner.n_envs=4", "learner.batch_size=8", "learner.warmup_steps=32",
        "learner.total_steps=128", "learner.eps_steps=128", "logging.checkpoint_every=64", "logging.log_every=32",
        "learner.target_update_steps=32", "eval.test_steps=48", "eval.test_envs=4", "runtime.torch_threads=1",
        # The path every pinned number was recorded on: float32, collect then update (the overlapped
        # loop has tests of its own).
        "runtime.update_dtype=float32", "runtime.overlap=false"]


def compose_cfg(*overrides: str) -> DictConfig:
    """TINY plus `overrides`; learned models also get small dense layers (the conv stack stays Table 3's)."""
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[*TINY, *overrides])
        if cfg.model.learned:
            cfg = compose("config", overrides=[*TINY, "model.network.hidden=[32,32]", *overrides])
        return cfg


def compose_job(*overrides: str) -> JobConfig:
    """`compose_cfg(*overrides)`, validated: the typed config `train`, `evaluate` and `make_env` take."""
    return check_config(compose_cfg(*overrides))


class Recorder:
    """A `log` callable that keeps what it was given."""

    def __init__(self, stop_at: int | None = None):
        self.calls: list[tuple[int, dict[str, float]]] = []
        self.stop_at = stop_at

    def __call__(self, metrics: dict[str, float], step: int) -> None:
        self.calls.append((step, dict(metrics)))
        if self.stop_at is not None and step >= self.stop_at:
            raise KeyboardInterrupt("simulated kill")

    def steps(self, key: str) -> list[int]:
        return [s for s, m in self.calls if key in m]
