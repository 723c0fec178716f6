"""Dueling DQN + prioritized replay on TorchRL: the whole training loop, top to bottom.

See the package docstring (`hgm_repro.learner`) for what a checkpoint holds and what a resume restores.
"""

from __future__ import annotations

import copy
import logging
import math
import random
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.collectors import Collector
from torchrl.data.replay_buffers.scheduler import LinearScheduler
from tqdm import tqdm

from ..contracts.checkpoint import (
    BEST_CHECKPOINT,
    EMA_CHECKPOINT,
    load_checkpoint,
    recorded_training_config,
    save_checkpoint,
    save_final,
    weights_only,
)
from ..contracts.interrupts import JobInterrupted, deferred, pending, raise_if_pending
from ..contracts.names import TRAINING_CURVE_METRICS, VAL_SEED_OFFSET
from ..contracts.schema import JobConfig
from ..contracts.train_key import train_key
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
from .training_reward import training_reward

Log = Callable[[dict[str, float], int], None]
logger = logging.getLogger(__name__)





class NonFiniteLossError(FloatingPointError):
    """The TD loss became NaN or infinite: training stops rather than writing broken weights."""


def _rng_state() -> dict[str, Any]:
    state = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def _set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def _buffer_megabytes(buffer) -> float:
    if len(buffer) == 0:
        return 0.0
    one = buffer.storage[0]
    return len(buffer) * one.bytes() / 2**20


def update_ema(ema_net: torch.nn.Module, net: torch.nn.Module, decay: float) -> None:
    """One step of the exponential moving average of the online weights (buffers are copied)."""
    with torch.no_grad():
        for averaged, current in zip(ema_net.parameters(), net.parameters(), strict=True):
            averaged.lerp_(current, 1.0 - decay)
        for averaged, current in zip(ema_net.buffers(), net.buffers(), strict=True):
            averaged.copy_(current)


def train(job: JobConfig, checkpoint_dir: Path, log: Log) -> Path:
    """Train `job.model` on `job.train_scenario`; returns the final checkpoint's path.

    Resumes from `checkpoint_dir/last.pt` when it exists (and belongs to this config), and
    returns `final.pt` at once when the run already finished.
    """
    L = job.learner
    checkpoint_dir = Path(checkpoint_dir)
    last_path, final_path = checkpoint_dir / "last.pt", checkpoint_dir / "final.pt"
    best_path = checkpoint_dir / BEST_CHECKPOINT
    ema_path = checkpoint_dir / EMA_CHECKPOINT
    device = torch.device(job.device)
    config = recorded_training_config(job)
    this_train_key = train_key(job)

    resume = None
    for path in (final_path, last_path):
        if path.exists():
            # On the CPU: RNG states must stay CPU tensors; load_state_dict moves weights to `device`.
            resume = load_checkpoint(path, job, strict=True, map_location="cpu")  # refuses a foreign one
            break
    if resume is not None and resume["finished"]:
        return final_path if final_path.exists() else save_checkpoint(resume, final_path)

    if L.torch_threads > 0:
        torch.set_num_threads(L.torch_threads)
    torch.manual_seed(job.seed)
    np.random.seed(job.seed)
    random.seed(job.seed)

    # --- the parts: env, network, policy, loss, target updater, optimiser, replay ---------------
    n_envs = L.n_envs
    frames_per_batch = n_envs  # one decision in every env per batch
    # Round the total up to whole batches so that a fresh and a resumed run stop at the same step.
    total_steps = math.ceil(L.total_steps / frames_per_batch) * frames_per_batch
    warmup_steps = math.ceil(L.warmup_steps / frames_per_batch) * frames_per_batch
    update_every = L.update_every

    steps_done = int(resume["env_steps"]) if resume else 0
    env = make_env(job, job.train_scenario, n_envs=n_envs, seed=job.seed)
    net = make_network(job).to(device)
    actor = make_actor(net).to(device)
    exploration = make_exploration(L, device)
    policy = make_policy(actor, exploration)
    loss_module = make_loss(L, actor).to(device)
    target_updater = make_target_updater(L, loss_module)
    optimizer = make_optimizer(L, loss_module.parameters(), capturable=L.cuda_graph and device.type == "cuda")
    # The moving average of the online weights (learner.ema_decay > 0): tested from ema.pt.
    ema_net = copy.deepcopy(net).requires_grad_(False) if L.ema_decay > 0 else None
    buffer = make_replay_buffer(L, device)
    # learner.replay_frames: the same prioritized memory, each frame stored once (frame_replay.py).
    memory = FrameReplay.for_env(buffer, env, L.n_step) if L.replay_frames else buffer
    n_batches = total_steps // frames_per_batch
    beta_schedule = LinearScheduler(buffer, "beta", final_value=L.per_beta_end, num_steps=n_batches)
    update = make_update(L, loss_module, optimizer, device)
    n_step = NStepReturns(L.n_step, L.gamma)
    reward_scale, collision_weight = L.reward_scale, L.collision_weight

    updates_done, update_credit = 0, 0.0
    eval_every = L.eval_every
    val_env = make_env(job, job.train_scenario, n_envs=L.val_envs,
                       seed=job.seed + VAL_SEED_OFFSET) if eval_every > 0 else None
    best_val = -math.inf
    if resume:
        best_val = float(resume.get("best_val_return", -math.inf))
        net.load_state_dict(resume["network"])
        loss_module.load_state_dict(resume["loss"])  # online and target weights
        optimizer.load_state_dict(resume["optimizer"])
        exploration.load_state_dict(resume["exploration"])
        beta_schedule.load_state_dict(resume["beta_schedule"])
        buffer.sampler.beta = resume["beta"]
        if hasattr(target_updater, "counter"):  # hard updates count; Polyak averaging has no phase
            target_updater.counter = resume["target_counter"]
        if ema_net is not None:
            ema_net.load_state_dict(resume.get("ema_network") or resume["network"])
        updates_done, update_credit = resume["updates"], resume["update_credit"]
        if resume["replay_buffer"] is not None:
            memory.load_state_dict(resume["replay_buffer"])
            if isinstance(memory, FrameReplay):
                memory.restart()  # the traffic restarts from fresh episodes
        _set_rng_state(resume["rng"])
        # The traffic restarts from fresh episodes (the simulator state is not stored), drawn from
        # the restored generator so that a resume is deterministic and does not replay episode one.
        env.simulator.generator.set_state(resume["env_rng"])

    # Updates start once the buffer holds the warm-up's worth of transitions. On a fresh run that
    # is exactly `warmup_steps` steps of random actions; on a resume without a stored buffer the
    # restored epsilon-greedy policy refills it first (those steps count as env steps).
    learn_from = min(warmup_steps, L.buffer_size)
    collector = Collector(
        env, policy, frames_per_batch=frames_per_batch, total_frames=total_steps - steps_done,
        init_random_frames=max(0, warmup_steps - steps_done), device=device, storing_device=device,
        auto_register_policy_transforms=False)  # the Q-network is feed-forward: no InitTracker needed

    def checkpoint_state(finished: bool) -> dict[str, Any]:
        megabytes = memory.megabytes() if isinstance(memory, FrameReplay) else _buffer_megabytes(buffer)
        small = megabytes <= L.checkpoint_buffer_max_mb
        return {
            "format": 1, "model": job.model.name, "train_key": this_train_key, "training_config": config,
            "finished": finished, "env_steps": steps_done, "updates": updates_done, "update_credit": update_credit,
            "network": net.state_dict(), "loss": loss_module.state_dict(), "optimizer": optimizer.state_dict(),
            "exploration": exploration.state_dict(), "epsilon": float(exploration.eps),
            "beta_schedule": beta_schedule.state_dict(), "beta": float(buffer.sampler.beta),
            "target_counter": getattr(target_updater, "counter", 0),
            **({"ema_network": ema_net.state_dict()} if ema_net is not None else {}),
            "replay_buffer": memory.state_dict() if small else None,
            "rng": _rng_state(), "env_rng": env.simulator.generator.get_state(), "best_val_return": best_val,
        }

    def validate() -> dict[str, float]:
        """A greedy pass over `val_episodes` episodes per validation env, in the training traffic
        drawn from validation seeds; keeps `best.pt` when the mean return is the best so far."""
        nonlocal best_val
        net.eval()
        episodes = run_episodes(val_env, actor, L.val_episodes, job.seed + VAL_SEED_OFFSET)
        net.train()
        metrics = episode_means(episodes, "val")
        if metrics["val/episode_return"] > best_val:
            best_val = metrics["val/episode_return"]
            save_checkpoint(weights_only(checkpoint_state(finished=False)), best_path)  # best.pt is for its weights
        metrics["val/best_episode_return"] = best_val
        if ema_net is not None:  # the averaged weights on the same validation traffic
            ema_net.eval()
            metrics.update(episode_means(run_episodes(val_env, ema_actor, L.val_episodes,
                                                      job.seed + VAL_SEED_OFFSET), "val_ema"))
        return metrics

    ema_actor = make_actor(ema_net).to(device) if ema_net is not None else None

    def save_ema(state: dict[str, Any]) -> None:
        """ema.pt: a finished checkpoint whose network is the moving average (no replay memory)."""
        if ema_net is not None:
            save_checkpoint(weights_only({**state, "network": ema_net.state_dict()}), ema_path)

    def stop(interrupted: JobInterrupted | None = None) -> None:
        """A stop signal ends training between batches, never inside one: last.pt holds everything
        up to this batch (a resume loses nothing), then the signal is raised."""
        save_checkpoint(checkpoint_state(finished=steps_done >= total_steps), last_path)
        progress.close()
        collector.shutdown()
        if interrupted is not None:
            raise interrupted
        raise_if_pending()

    progress = tqdm(total=total_steps, initial=steps_done, unit="step", desc=f"train {job.model.name}",
                    disable=not sys.stdout.isatty(), dynamic_ncols=True)
    episodes: dict[str, list[float]] = {k: [] for k in TRAINING_CURVE_METRICS}
    losses: list[torch.Tensor] = []
    last_log_steps, last_log_time = steps_done, time.perf_counter()
    recent_speed = float("nan")

    # --- the loop: collect one step of every env, store it, learn, log, checkpoint ---------------
    for batch in collector:
        batch: TensorDictBase = batch.reshape(n_envs, -1)  # [envs, time]
        steps_before, steps_done = steps_done, steps_done + batch.numel()
        exploration.step(batch.numel())
        beta_schedule.step()
        transitions = batch.exclude("collector", "episode", "reward_terms", ("next", "episode"),
                                    ("next", "reward_terms"))
        if reward_scale != 1.0 or collision_weight != 1.0:
            transitions.set(("next", "reward"), training_reward(batch, reward_scale, collision_weight))
        if isinstance(memory, FrameReplay):
            transitions = memory.observe(transitions)  # frames kept once; transitions carry their index
        transitions = n_step(transitions)  # n-step windows complete n - 1 decisions later
        if transitions is not None and transitions.numel() > 0:
            memory.extend(transitions.reshape(-1))
        batch = batch.reshape(-1)

        done = batch["next", "done"].reshape(-1)
        if done.any():
            finished = batch["next", "episode"][done]
            for key in TRAINING_CURVE_METRICS:
                episodes[key].extend(finished[key].tolist())
            recent_speed = float(finished["avg_speed_kmh"].mean())

        if len(memory) >= learn_from:
            update_credit += batch.numel() / update_every
            batch_losses = []
            while update_credit >= 1.0:
                update_credit -= 1.0
                sample = memory.sample()
                out = update(sample)
                # DQNLoss stores the squared TD error; PER's priority is |delta| (to the alpha).
                # nan_to_num keeps the sum tree valid until the check below stops the run.
                priority = torch.nan_to_num(out["td_error"].sqrt(), nan=1.0, posinf=1.0)
                memory.update_priority(sample["index"], priority)
                target_updater.step()
                if ema_net is not None:
                    update_ema(ema_net, net, L.ema_decay)
                batch_losses.append(out["loss"])
                updates_done += 1
            if batch_losses:
                batch_loss = torch.stack(batch_losses)
                if not torch.isfinite(batch_loss).all():
                    progress.close()
                    collector.shutdown()
                    raise NonFiniteLossError(
                        f"training loss became {batch_loss.tolist()} at env step {steps_done} (update {updates_done}) "
                        f"for model '{job.model.name}'; stopped. The last good checkpoint is {last_path} "
                        f"(if one was written). Try a lower learner.lr (now {L.lr}) or learner.max_grad_norm.")
                losses.append(batch_loss.mean())
            collector.update_policy_weights_()

        progress.update(batch.numel())
        if progress.n % (50 * frames_per_batch) < frames_per_batch:
            progress.set_postfix(eps=f"{float(exploration.eps):.3f}", speed_kmh=f"{recent_speed:.1f}", refresh=False)

        if steps_done // L.log_every > steps_before // L.log_every or steps_done >= total_steps:
            now = time.perf_counter()
            metrics = {f"train/{k}": float(np.mean(v)) for k, v in episodes.items() if v}
            if losses:
                metrics["train/loss"] = float(torch.stack(losses).mean())
            metrics.update({"train/epsilon": float(exploration.eps), "train/beta": float(buffer.sampler.beta),
                            "train/steps_per_s": (steps_done - last_log_steps) / max(now - last_log_time, 1e-9),
                            "train/episodes": float(len(episodes["avg_speed_kmh"])),
                            "train/updates": float(updates_done)})
            if val_env is not None and (steps_done // eval_every > steps_before // eval_every
                                        or steps_done >= total_steps):
                try:
                    metrics.update(validate())
                except JobInterrupted as interrupted:  # stopped between validation steps
                    stop(interrupted)
            with deferred():  # a signal during the store write waits for the stop below, after last.pt
                log(metrics, steps_done)
            if progress.disable:  # no bar when output goes to a file: a line per log interval instead
                logger.info("train %s: %d/%d env steps, %.0f steps/s, epsilon %.3f, mean speed %.1f km/h, "
                            "crashes per episode %.2f (greedy validation %.2f)",
                            job.model.name, steps_done, total_steps, metrics["train/steps_per_s"],
                            metrics["train/epsilon"], metrics.get("train/avg_speed_kmh", float("nan")),
                            metrics.get("train/collisions", float("nan")), metrics.get("val/collisions", float("nan")))
            episodes = {k: [] for k in TRAINING_CURVE_METRICS}
            losses = []
            last_log_steps, last_log_time = steps_done, now

        if steps_done // L.checkpoint_every > steps_before // L.checkpoint_every and steps_done < total_steps:
            save_checkpoint(checkpoint_state(finished=False), last_path)

        if pending() and steps_done < total_steps:
            stop()

    progress.close()
    collector.shutdown()
    if steps_done < total_steps:  # pragma: no cover - the collector stops exactly at total_frames
        warnings.warn(f"collector stopped at {steps_done} of {total_steps} env steps", stacklevel=2)
    final = checkpoint_state(finished=True)
    save_ema(final)
    return save_final(final, checkpoint_dir)
