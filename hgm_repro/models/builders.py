"""The networks' builders: a model's Q-network from its config, and the greedy actor around it (what
the learner trains and evaluation drives)."""

from __future__ import annotations

import hydra.utils
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import OneHot
from torchrl.modules import QValueActor

from ..contracts.observation_config import ObservationConfig
from ..contracts.schema import JobConfig
from ..simulator import N_ACTIONS


def network_kwargs(observation: ObservationConfig) -> dict:
    """Input sizes every network constructor receives, from the observation config."""
    frames = observation.frame_stack
    return {"n_actions": N_ACTIONS, "in_channels": 3 * frames, "image_size": (observation.height, observation.width),
            "coord_dim": frames * observation.coord_k * 6}


def make_network(job: JobConfig) -> nn.Module:
    """The model's Q-network from `job.model.network` (`_target_`), sized for `job.observation`."""
    if not job.model.learned or job.model.network is None:
        raise ValueError(f"model '{job.model.name}' is not a learned model: it has no network to train")
    return hydra.utils.instantiate(job.model.network, **network_kwargs(job.observation), _convert_="all")


def make_actor(net: nn.Module) -> QValueActor:
    """Greedy Q-value actor: reads the network's `in_keys`, writes a one-hot `action`."""
    module = TensorDictModule(net, in_keys=list(net.in_keys), out_keys=["action_value"])
    return QValueActor(module, spec=OneHot(N_ACTIONS), action_space="one-hot")
