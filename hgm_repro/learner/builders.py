"""Small builders for the Dueling DQN + PER learner, one TorchRL part each (as in TorchRL's sota DQN)."""

from __future__ import annotations

import warnings
from collections.abc import Callable

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictSequential
from torchrl.data import LazyTensorStorage, TensorDictPrioritizedReplayBuffer
from torchrl.modules import QValueActor
from torchrl.objectives import DQNLoss, HardUpdate, SoftUpdate
from torchrl.objectives.utils import TargetNetUpdater

from ..contracts.runtime_choice import update_dtype
from ..contracts.schema import LearnerSchema, RuntimeSchema
from .exploration import EpsilonGreedy
from .priority_trees import install_if_missing

install_if_missing()

# Key the replay buffer reads priorities from; DQNLoss writes its (squared) TD error there.
PRIORITY_KEY = "td_error"


def make_exploration(learner: LearnerSchema, device: torch.device) -> EpsilonGreedy:
    """Epsilon-greedy over the actor's action, annealed linearly over `eps_steps` env steps (then to
    `eps_floor` over `eps_floor_steps` more), drawing lane changes at `random_lane_change_share`."""
    return EpsilonGreedy(learner.eps_start, learner.eps_end, learner.eps_steps, eps_floor=learner.eps_floor,
                         floor_steps=learner.eps_floor_steps, lane_change_share=learner.random_lane_change_share,
                         device=device)


def make_optimizer(learner: LearnerSchema, params, capturable: bool = False) -> torch.optim.Adam:
    """The learner's one optimiser: Adam at `learner.lr` with `learner.adam_eps`."""
    return torch.optim.Adam(params, lr=learner.lr, eps=learner.adam_eps, capturable=capturable)


class PolyakUpdate(SoftUpdate):
    """TorchRL's `SoftUpdate`, the same arithmetic, a tenth of its cost per update.

    `SoftUpdate.step` walks its TensorDicts of sources and targets key by key on every update,
    about 10 ms at the quick preset, a third of the update itself. The tensors are the same ones
    every time, so this one gathers them on its first step (after any checkpoint was restored
    into them) and then lerps the two lists in one call, with `SoftUpdate`'s weight.
    """

    _pairs: tuple[list[torch.Tensor], list[torch.Tensor]] | None = None

    def step(self) -> None:
        if self._pairs is None:
            if not self.initialized:
                raise RuntimeError(f"{type(self).__name__} must be initialized (`init_()`) before calling step()")
            for name in self._target_names:
                getattr(self.loss_module, name)
            sources, targets = [], []
            for key, source in self._sources.items():
                target = self._targets.get(f"target_{key}")
                if isinstance(source, TensorDictBase):
                    for leaf in source.keys(include_nested=True, leaves_only=True):
                        sources.append(source.get(leaf).data)
                        targets.append(target.get(leaf).data)
                else:
                    sources.append(source.data)
                    targets.append(target.data)
            self._pairs = (sources, targets)
        sources, targets = self._pairs
        torch._foreach_lerp_(targets, sources, 1 - self.eps)


def make_target_updater(learner: LearnerSchema, loss_module: DQNLoss) -> TargetNetUpdater:
    """Hard copies every `target_update_steps` env steps, or Polyak averaging at `target_tau` per update."""
    if learner.target_tau > 0:
        return PolyakUpdate(loss_module, tau=learner.target_tau)
    updates_per_target = max(1, round(learner.target_update_steps / learner.update_every))
    # HardUpdate copies on the (interval + 1)-th call: interval = period - 1 gives exactly one
    # copy every target_update_steps env steps.
    return HardUpdate(loss_module, value_network_update_interval=updates_per_target - 1)


def make_policy(actor: QValueActor, exploration: EpsilonGreedy) -> TensorDictSequential:
    return TensorDictSequential(actor, exploration)


def make_loss(learner: LearnerSchema, actor: QValueActor) -> DQNLoss:
    """DQN loss with a delayed (target) copy of the network; Double DQN from config."""
    loss = DQNLoss(actor, loss_function=learner.loss_function, delay_value=True, double_dqn=learner.double_dqn,
                   action_space="one-hot")
    loss.make_value_estimator(gamma=learner.gamma)
    return loss


def make_replay_buffer(learner: LearnerSchema, device: torch.device) -> TensorDictPrioritizedReplayBuffer:
    """Proportional prioritized replay over flat transitions, stored on the training device."""
    return TensorDictPrioritizedReplayBuffer(
        alpha=learner.per_alpha, beta=learner.per_beta_start,
        storage=LazyTensorStorage(learner.buffer_size, device=device),
        batch_size=learner.batch_size, priority_key=PRIORITY_KEY)


def make_update(learner: LearnerSchema, runtime: RuntimeSchema, loss_module: DQNLoss, optimizer: torch.optim.Optimizer,
                device: torch.device) -> Callable[[TensorDictBase], TensorDict]:
    """One gradient step on a sampled batch -> TensorDict(loss, td_error, grad_norm); `runtime` says
    how it runs (bf16 autocast, torch.compile, a CUDA graph), never what it computes.

    The TD error is returned rather than read back from the batch because a CUDA-graph
    captured update works on its own static copy of the input.
    """
    max_grad_norm = learner.max_grad_norm
    params = list(loss_module.parameters())

    # bf16 autocast of the forward passes (runtime.update_dtype); the weights, gradients and Adam's
    # state stay float32, and the loss is reduced in float32.
    bf16 = update_dtype(runtime.update_dtype, device) == torch.bfloat16

    def update(batch: TensorDictBase) -> TensorDict:
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
            loss = loss_module(batch)["loss"].float()
        optimizer.zero_grad(set_to_none=False)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(params, max_grad_norm)
        optimizer.step()
        return TensorDict(loss=loss.detach(), td_error=batch.get(PRIORITY_KEY).detach(),
                          grad_norm=grad_norm.detach())

    if runtime.compile:
        update = torch.compile(update)
    if runtime.cuda_graph:
        if device.type != "cuda":
            warnings.warn("runtime.cuda_graph=true needs device=cuda; ignored on " + str(device), stacklevel=2)
        else:
            from tensordict.nn import CudaGraphModule

            # The first calls run eagerly (warm-up) so that lazy state such as Adam's moments
            # exists before capture.
            update = CudaGraphModule(update, warmup=10)
    return update
