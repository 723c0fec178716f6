"""The job's host as something that acts: a trained network loaded from its checkpoint, or the
model's driver attached to a simulator. Evaluation and the episode GIF both start here."""

from __future__ import annotations

from pathlib import Path

import hydra.utils
import torch
from omegaconf import DictConfig

from ..experiment.checkpoint import load_checkpoint
from ..simulator import HighwaySimulator
from ..simulator.driver import Driver, attach


def trained_network(cfg: DictConfig, checkpoint: Path | None, device: torch.device) -> torch.nn.Module:
    """`cfg.model`'s network with the weights of `checkpoint`, in eval mode on `device`."""
    from ..learner.builders import make_network

    if checkpoint is None:
        raise ValueError(f"model '{cfg.model.name}' is learned: it needs its checkpoint")
    # Only the architecture must match: a model trained once is tested in every scenario.
    state = load_checkpoint(Path(checkpoint), cfg, strict=False, map_location="cpu")
    net = make_network(cfg)
    net.load_state_dict(state["network"])
    return net.to(device).eval()


def attached_driver(cfg: DictConfig, sim: HighwaySimulator) -> Driver:
    """`cfg.model`'s driver (a non-learning host), attached to `sim`."""
    return attach(hydra.utils.instantiate(cfg.model.driver), sim)
