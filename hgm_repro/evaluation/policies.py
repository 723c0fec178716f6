"""The job's host as something that acts: a trained network loaded from its checkpoint, or the
model's driver attached to a simulator. Evaluation and the episode GIF both start here."""

from __future__ import annotations

from pathlib import Path

import hydra.utils
import torch

from ..contracts.checkpoint import load_checkpoint
from ..contracts.schema import JobConfig
from ..simulator import HighwaySimulator
from ..simulator.driver import Driver, attach


def trained_network(job: JobConfig, checkpoint: Path | None, device: torch.device) -> torch.nn.Module:
    """`job.model`'s network with the weights of `checkpoint`, in eval mode on `device`."""
    from ..models.builders import make_network

    if checkpoint is None:
        raise ValueError(f"model '{job.model.name}' is learned: it needs its checkpoint")
    # Only the architecture must match: a model trained once is tested in every scenario.
    state = load_checkpoint(Path(checkpoint), job, strict=False, map_location="cpu")
    net = make_network(job)
    net.load_state_dict(state["network"])
    return net.to(device).eval()


def attached_driver(job: JobConfig, sim: HighwaySimulator) -> Driver:
    """`job.model`'s driver (a non-learning host), attached to `sim`."""
    return attach(hydra.utils.instantiate(job.model.driver), sim)
