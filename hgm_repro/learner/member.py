"""One training member: a seed of one model, with everything that is its own.

The training loop (`loop.py`) steps one simulator for every member at once; a `Member` holds the
rest: its Q-network and TorchRL parts (actor, epsilon-greedy, `DQNLoss` with its target rule, Adam,
prioritized replay, PER beta schedule, n-step window, moving average), its validation traffic,
its curves between two log points, and its checkpoints. A solo run is a group of one member.
"""

from __future__ import annotations

import copy
import math
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data.replay_buffers.scheduler import LinearScheduler

from ..contracts.checkpoint import (
    BEST_CHECKPOINT,
    EMA_CHECKPOINT,
    FINAL_CHECKPOINT,
    LAST_CHECKPOINT,
    chosen_by_current_validation,
    load_checkpoint,
    recorded_training_config,
    save_checkpoint,
    save_final,
    val_checkpoint_path,
    weights_only,
)
from ..contracts.names import TRAINING_CURVE_METRICS, VAL_SEED_OFFSET
from ..contracts.schema import JobConfig
from ..contracts.train_key import EVALUATION_VERSION, train_key
from ..envs import make_env
from ..evaluation.episodes import episode_means, run_episodes
from ..models.builders import make_actor, make_network
from .builders import (
    make_exploration,
    make_loss,
    make_optimizer,
    make_policy,
    make_replay_buffer,
    make_target_updater,
    make_update,
)
from .frame_replay import FrameReplay
from .n_step import NStepReturns
from .progress import Progress
from .training_reward import training_reward

Log = Callable[[dict[str, float], int], None]

# Keys of a collected step that are metrics, not part of a transition.
NOT_TRANSITION_KEYS = ("collector", "episode", "reward_terms", ("next", "episode"), ("next", "reward_terms"))


class NonFiniteLossError(FloatingPointError):
    """The TD loss became NaN or infinite: training stops rather than writing broken weights."""


def rng_state() -> dict[str, Any]:
    """The process's torch / numpy / python (and CUDA) generator states, as a checkpoint keeps them."""
    state = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def buffer_megabytes(buffer) -> float:
    if len(buffer) == 0:
        return 0.0
    one = buffer.storage[0]
    return len(buffer) * one.bytes() / 2**20


def update_ema(ema_net: torch.nn.Module, net: torch.nn.Module, decay: float) -> None:
    """One step of the exponential moving average of the online weights (buffers are copied)."""
    with torch.no_grad():
        # One call over all tensors: on a CPU the same lerp_ per tensor, without Python's loop.
        torch._foreach_lerp_(list(ema_net.parameters()), list(net.parameters()), 1.0 - decay)
        for averaged, current in zip(ema_net.buffers(), net.buffers(), strict=True):
            averaged.copy_(current)


class Member:
    """A member's parts, built by `build` once the group's simulator exists."""

    def __init__(self, job: JobConfig, checkpoint_dir: Path, log: Log):
        self.job = job
        self.checkpoint_dir = Path(checkpoint_dir)
        self.log = log
        self.resume: dict[str, Any] | None = None
        self.best_val = -math.inf
        self.episodes: dict[str, list[float]] = {k: [] for k in TRAINING_CURVE_METRICS}
        self.losses: list[torch.Tensor] = []
        self.recent_speed = float("nan")

    @property
    def last_path(self) -> Path:
        return self.checkpoint_dir / LAST_CHECKPOINT

    @property
    def final_path(self) -> Path:
        return self.checkpoint_dir / FINAL_CHECKPOINT

    def read_resume(self) -> dict[str, Any] | None:
        """The member's final.pt or last.pt (refused with a message when it belongs to another config)."""
        for path in (self.final_path, self.last_path):
            if path.exists():
                # On the CPU: RNG states must stay CPU tensors; load_state_dict moves weights to `device`.
                self.resume = load_checkpoint(path, self.job, strict=True, map_location="cpu")
                return self.resume
        self.resume = None
        return None

    def build(self, env: Any, rows: slice, n_batches: int) -> None:
        """The member's parts; `rows` are its envs in the group's simulator `env`."""
        job, L = self.job, self.job.learner
        device = torch.device(job.device)
        self.rows = rows
        # The member's own traffic generator (its block of the group's envs), saved and restored as env_rng.
        self.generator = env.simulator.randomness.generators[rows.start // L.n_envs]
        self.net = make_network(job).to(device)
        self.actor = make_actor(self.net).to(device)
        self.exploration = make_exploration(L, device)
        self.policy = make_policy(self.actor, self.exploration)
        self.loss_module = make_loss(L, self.actor).to(device)
        self.target_updater = make_target_updater(L, self.loss_module)
        self.optimizer = make_optimizer(L, self.loss_module.parameters(),
                                        capturable=job.runtime.cuda_graph and device.type == "cuda")
        # The moving average of the online weights (learner.ema_decay > 0): tested from ema.pt.
        self.ema_net = copy.deepcopy(self.net).requires_grad_(False) if L.ema_decay > 0 else None
        self.buffer = make_replay_buffer(L, device)
        # runtime.replay_frames: the same prioritized memory, each frame stored once (frame_replay.py).
        self.memory = FrameReplay.for_env(self.buffer, env, L.n_step, n_envs=L.n_envs) \
            if job.runtime.replay_frames else self.buffer
        self.beta_schedule = LinearScheduler(self.buffer, "beta", final_value=L.per_beta_end, num_steps=n_batches)
        self.update = make_update(L, job.runtime, self.loss_module, self.optimizer, device)
        self.n_step = NStepReturns(L.n_step, L.gamma)
        self.val_env = make_env(job, job.train_scenario, n_envs=job.eval.val_envs,
                                seed=job.seed + VAL_SEED_OFFSET) if job.eval.val_every > 0 else None
        self.ema_actor = make_actor(self.ema_net).to(device) if self.ema_net is not None else None
        self.train_key = train_key(job)
        self.config = recorded_training_config(job)

    def restore(self) -> None:
        """Everything of the member's own that `resume` holds (the process's generators: the loop)."""
        resume = self.resume
        if resume is None:
            return
        # A best return scored by an older validation is not compared with this one's: best.pt is chosen afresh.
        self.best_val = float(resume.get("best_val_return", -math.inf)) if chosen_by_current_validation(resume) \
            else -math.inf
        self.net.load_state_dict(resume["network"])
        self.loss_module.load_state_dict(resume["loss"])  # online and target weights
        self.optimizer.load_state_dict(resume["optimizer"])
        self.exploration.load_state_dict(resume["exploration"])
        self.beta_schedule.load_state_dict(resume["beta_schedule"])
        self.buffer.sampler.beta = resume["beta"]
        if hasattr(self.target_updater, "counter"):  # hard updates count; Polyak averaging has no phase
            self.target_updater.counter = resume["target_counter"]
        if self.ema_net is not None:
            self.ema_net.load_state_dict(resume.get("ema_network") or resume["network"])
        if resume["replay_buffer"] is not None:
            self.memory.load_state_dict(resume["replay_buffer"])
            if isinstance(self.memory, FrameReplay):
                self.memory.restart()  # the traffic restarts from fresh episodes
        # The traffic restarts from fresh episodes (the simulator state is not stored), drawn from
        # the restored generator so that a resume is deterministic and does not replay episode one.
        self.generator.set_state(resume["env_rng"])

    # --- one batch ---------------------------------------------------------------------------------
    def observe(self, batch: TensorDictBase) -> None:
        """Store the member's envs' step (`batch`: [envs, time]) and keep its finished episodes."""
        L = self.job.learner
        self.exploration.step(batch.numel())
        self.beta_schedule.step()
        transitions = batch.exclude(*NOT_TRANSITION_KEYS)
        if L.reward_scale != 1.0 or L.collision_weight != 1.0:
            transitions.set(("next", "reward"), training_reward(batch, L.reward_scale, L.collision_weight))
        if isinstance(self.memory, FrameReplay):
            transitions = self.memory.observe(transitions)  # frames kept once; transitions carry their index
        transitions = self.n_step(transitions)  # n-step windows complete n - 1 decisions later
        if transitions is not None and transitions.numel() > 0:
            self.memory.extend(transitions.reshape(-1))
        flat = batch.reshape(-1)
        done = flat["next", "done"].reshape(-1)
        if done.any():
            finished = flat["next", "episode"][done]
            for key in TRAINING_CURVE_METRICS:
                self.episodes[key].extend(finished[key].tolist())
            self.recent_speed = float(finished["avg_speed_kmh"].mean())

    def learn(self, updates: int, progress: Progress) -> None:
        """`updates` gradient steps on prioritized samples (the batch that brought training to
        `progress` earned them); stops the run on a loss that is not finite."""
        L = self.job.learner
        losses = []
        for _ in range(updates):
            sample = self.memory.sample()
            out = self.update(sample)
            # DQNLoss stores the squared TD error; PER's priority is |delta| (to the alpha).
            # nan_to_num keeps the sum tree valid until the check below stops the run.
            priority = torch.nan_to_num(out["td_error"].sqrt(), nan=1.0, posinf=1.0)
            self.memory.update_priority(sample["index"], priority)
            self.target_updater.step()
            if self.ema_net is not None:
                update_ema(self.ema_net, self.net, L.ema_decay)
            losses.append(out["loss"])
        if not losses:
            return
        batch_loss = torch.stack(losses)
        self.losses.append(batch_loss.mean())
        # One host read per batch, not per update; the run stops rather than write broken weights.
        if not torch.isfinite(batch_loss).all():
            raise NonFiniteLossError(
                f"training loss became {batch_loss.tolist()} at env step {progress.env_steps} (update "
                f"{progress.updates + updates}) for model '{self.job.model.name}' seed {self.job.seed}; stopped. "
                f"The last good checkpoint is {self.last_path} (if one was written). "
                f"Try a lower learner.lr (now {L.lr}) or learner.max_grad_norm.")

    # --- log points --------------------------------------------------------------------------------
    def interval_metrics(self, steps_per_s: float, updates_done: int,
                         cpu_steps_per_s: float | None = None) -> dict[str, float]:
        """The member's `train/*` values since the last log point; the curves start afresh. `steps_per_s` and
        `cpu_steps_per_s`: env steps per second of wall time and of the process's CPU time since then."""
        metrics = {f"train/{k}": float(np.mean(v)) for k, v in self.episodes.items() if v}
        if self.losses:
            metrics["train/loss"] = float(torch.stack(self.losses).mean())
        metrics.update({"train/epsilon": float(self.exploration.eps), "train/beta": float(self.buffer.sampler.beta),
                        "train/steps_per_s": steps_per_s,
                        "train/episodes": float(len(self.episodes["avg_speed_kmh"])),
                        "train/updates": float(updates_done)})
        if cpu_steps_per_s is not None:
            metrics["train/cpu_steps_per_s"] = cpu_steps_per_s
        self.episodes = {k: [] for k in TRAINING_CURVE_METRICS}
        self.losses = []
        return metrics

    def validate(self, progress: Progress) -> dict[str, float]:
        """A greedy pass over `val_episodes` episodes per validation env, in the training traffic
        drawn from validation seeds; keeps `best.pt` when the mean return is the best so far."""
        episodes_per_env, seed = self.job.eval.val_episodes, self.job.seed + VAL_SEED_OFFSET
        self.net.eval()
        episodes = run_episodes(self.val_env, self.actor, episodes_per_env, seed)
        self.net.train()
        metrics = episode_means(episodes, "val")
        keep, better = self.job.eval.keep_val_checkpoints, metrics["val/episode_return"] > self.best_val
        if better:
            self.best_val = metrics["val/episode_return"]
        if keep or better:  # one weights-only state serves both files
            state = weights_only(self.checkpoint_state(progress, finished=False))
            if keep:  # each pass's network, for reselection (eval.checkpoint=reselected)
                save_checkpoint({**state, "val_return": metrics["val/episode_return"]},
                                val_checkpoint_path(self.checkpoint_dir, progress.env_steps))
            if better:
                save_checkpoint(state, self.checkpoint_dir / BEST_CHECKPOINT)
        metrics["val/best_episode_return"] = self.best_val
        if self.ema_net is not None:  # the averaged weights on the same validation traffic
            self.ema_net.eval()
            metrics.update(episode_means(run_episodes(self.val_env, self.ema_actor, episodes_per_env, seed), "val_ema"))
        return metrics

    # --- checkpoints -------------------------------------------------------------------------------
    def checkpoint_state(self, progress: Progress, finished: bool) -> dict[str, Any]:
        megabytes = self.memory.megabytes() if isinstance(self.memory, FrameReplay) else buffer_megabytes(self.buffer)
        small = megabytes <= self.job.runtime.checkpoint_buffer_max_mb
        return {
            "format": 1, "model": self.job.model.name, "train_key": self.train_key, "training_config": self.config,
            "finished": finished, **progress.to_checkpoint(),
            "network": self.net.state_dict(), "loss": self.loss_module.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "exploration": self.exploration.state_dict(), "epsilon": float(self.exploration.eps),
            "beta_schedule": self.beta_schedule.state_dict(), "beta": float(self.buffer.sampler.beta),
            "target_counter": getattr(self.target_updater, "counter", 0),
            **({"ema_network": self.ema_net.state_dict()} if self.ema_net is not None else {}),
            "replay_buffer": self.memory.state_dict() if small else None,
            "rng": rng_state(), "env_rng": self.generator.get_state(), "best_val_return": self.best_val,
            "evaluation_version": EVALUATION_VERSION,
        }

    def save_last(self, progress: Progress, finished: bool = False) -> None:
        save_checkpoint(self.checkpoint_state(progress, finished), self.last_path)

    def save_final(self, progress: Progress) -> Path:
        """final.pt (replacing last.pt), and ema.pt: a finished checkpoint whose network is the moving
        average (no replay memory)."""
        final = self.checkpoint_state(progress, finished=True)
        if self.ema_net is not None:
            save_checkpoint(weights_only({**final, "network": self.ema_net.state_dict()}),
                            self.checkpoint_dir / EMA_CHECKPOINT)
        return save_final(final, self.checkpoint_dir)

    def finished_path(self) -> Path:
        """The final checkpoint of a member whose resume state is finished (written if only last.pt is)."""
        return self.final_path if self.final_path.exists() else save_checkpoint(self.resume, self.final_path)
