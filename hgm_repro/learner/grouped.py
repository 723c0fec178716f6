"""Grouped training: several members (the seeds of one model) trained in one process.

One batched simulator holds every member's envs, in contiguous blocks, each block drawing its
traffic from its member's own generator (`HighwaySimulator(seed=[...])`), so a member meets the
same traffic alone or in any group. The members share one update step: their parameters are
stacked along a leading member dimension (`torch.func.stack_module_state`) and the Q-network runs
under `torch.func.vmap` + `functional_call`, so M members cost one wide update instead of M small
ones. Everything else stays per member: replay memory with its PER priorities, epsilon-greedy
schedule and random stream, target network, Adam moments (Adam is element-wise, so one Adam over
the stacked tensors is M independent Adams), gradient-norm clipping, n-step window, validation,
`train/*` curves and checkpoints.

A member's checkpoint has the solo format (`hgm_repro.learner.dqn`), with the member's slices of
the stacked weights and Adam moments written into a solo network, loss module and optimiser: a
grouped member can be evaluated, resumed solo, or resumed in another group, like a solo one.
What differs from a solo run of the same seed is only what the exploration and the replay sampling
draw (the traffic is the same): a member's epsilon-greedy draws come from its own generator, and
the replay sampling from the process's torch generator, seeded by the group.
"""

from __future__ import annotations

import copy
import logging
import math
import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from tensordict import TensorDictBase
from torch.func import functional_call, stack_module_state
from torchrl.data.replay_buffers.scheduler import LinearScheduler
from torchrl.objectives import HardUpdate

from ..contracts.checkpoint import (
    BEST_CHECKPOINT,
    load_checkpoint,
    recorded_training_config,
    save_checkpoint,
    save_final,
    weights_only,
)
from ..contracts.interrupts import JobInterrupted, deferred, pending, raise_if_pending
from ..contracts.names import EXPLORATION_SEED_OFFSET, TRAINING_CURVE_METRICS, VAL_SEED_OFFSET
from ..contracts.schema import JobConfig
from ..contracts.train_key import train_key, training_config
from ..envs import make_env
from ..evaluation.episodes import episode_means, run_episodes
from ..models.builders import make_actor, make_network
from ..simulator import N_ACTIONS
from .builders import make_exploration, make_loss, make_optimizer, make_replay_buffer
from .dqn import NonFiniteLossError, _buffer_megabytes, _rng_state, _set_rng_state
from .n_step import NStepReturns
from .training_reward import training_reward

Log = Callable[[dict[str, float], int], None]
logger = logging.getLogger(__name__)

# Keys of a collected step that are metrics, not part of a transition (as in the solo loop).
NOT_TRANSITION_KEYS = ("episode", "reward_terms", ("next", "episode"), ("next", "reward_terms"))


def use_grouped(setting: str | bool, device: str) -> bool:
    """`learner.grouped`: true / false force it; auto groups on CUDA only. On the 2-core CPU the
    stacked update gave no gain per member (one thread: 43 member-updates/s alone, 44 stacked by 5),
    while on a GPU one small update leaves most of the chip idle."""
    if setting == "auto":
        return torch.device(device).type == "cuda"
    if isinstance(setting, bool):
        return setting
    raise ValueError(f"learner.grouped={setting!r} is not allowed: use auto, true or false")


def group_key(job: JobConfig) -> str:
    """What members of one group share: the training identity without the seed, as text."""
    config = training_config(job)
    config.pop("seed")
    return repr(sorted(config.items()))


def check_group(jobs: Sequence[JobConfig]) -> None:
    """Members must differ only by seed (one architecture, one learner config, one traffic)."""
    if not jobs:
        raise ValueError("a training group needs at least one member")
    first = group_key(jobs[0])
    for job in jobs[1:]:
        if group_key(job) != first:
            raise ValueError(f"members of a training group must have the same training config except the seed; "
                             f"'{job.model.name}' seed {job.seed} differs from '{jobs[0].model.name}' seed "
                             f"{jobs[0].seed} in more than the seed")
    learner = jobs[0].learner
    solo_only = {k: v for k, v in (("target_tau", learner.target_tau), ("ema_decay", learner.ema_decay),
                                   ("replay_frames", learner.replay_frames)) if v}
    if solo_only:
        raise ValueError(f"{', '.join(f'learner.{k}={v}' for k, v in solo_only.items())} is not supported by grouped "
                         "training yet (it keeps hard target copies, no moving average and the flat replay memory): "
                         "use learner.grouped=false")
    seeds = [job.seed for job in jobs]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"members of a training group need distinct seeds; got seeds {seeds}")


@dataclass
class Member:
    """One training member's own parts; its weights live in the group's stacked tensors."""

    job: JobConfig
    checkpoint_dir: Path
    log: Log
    net: torch.nn.Module = field(init=False)
    resume: dict[str, Any] | None = None

    @property
    def last_path(self) -> Path:
        return self.checkpoint_dir / "last.pt"

    @property
    def final_path(self) -> Path:
        return self.checkpoint_dir / "final.pt"


def _read_resume(job: JobConfig, checkpoint_dir: Path) -> dict[str, Any] | None:
    for path in (checkpoint_dir / "final.pt", checkpoint_dir / "last.pt"):
        if path.exists():
            return load_checkpoint(path, job, strict=True, map_location="cpu")  # refuses a foreign one
    return None


def train_group(jobs: Sequence[JobConfig], checkpoint_dirs: Sequence[Path], logs: Sequence[Log]) -> list[Path]:
    """Train every member (`jobs[k]` into `checkpoint_dirs[k]`, curves to `logs[k]`); returns each
    member's final checkpoint, in order.

    Like `hgm_repro.learner.train` per member: finished members return at once, the others resume
    from their `last.pt`. Members that stopped at different env steps train in separate groups,
    one after the other (a group steps in lockstep).
    """
    jobs = list(jobs)
    check_group(jobs)
    finals: dict[int, Path] = {}
    waiting: dict[tuple, list[int]] = {}
    for k, (job, directory) in enumerate(zip(jobs, checkpoint_dirs, strict=True)):
        directory = Path(directory)
        resume = _read_resume(job, directory)
        if resume is not None and resume["finished"]:
            final = directory / "final.pt"
            finals[k] = final if final.exists() else save_checkpoint(resume, final)
            continue
        point = (0, 0, True) if resume is None else \
            (int(resume["env_steps"]), int(resume["updates"]), resume["replay_buffer"] is not None)
        waiting.setdefault(point, []).append(k)
    for members in waiting.values():
        paths = _train_lockstep([Member(jobs[k], Path(checkpoint_dirs[k]), logs[k]) for k in members])
        finals.update(zip(members, paths, strict=True))
    return [finals[k] for k in range(len(jobs))]


def _stacked_loss(base: torch.nn.Module, in_keys: Sequence[str], gamma: float, double_dqn: bool,
                  loss_function: str) -> Callable:
    """One member's weighted TD loss and squared TD error, written for `vmap` over members.

    The same quantities as TorchRL's `DQNLoss` with its TD(0) estimator (tests check that they
    match): Q(s, a) against r + gamma^k (1 - terminated) Q_target(s', a'), where a' is the
    target's argmax (DQN) or the online argmax (Double DQN) and k the n-step window's length;
    the loss is the PER-weighted mean sum(w * d) / sum(w).
    """
    distance = {"l2": F.mse_loss, "l1": F.l1_loss, "smooth_l1": F.smooth_l1_loss}[loss_function]

    def member_loss(params: dict, buffers: dict, target: dict, batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
        obs = tuple(batch[k] for k in in_keys)
        next_obs = tuple(batch["next_" + k] for k in in_keys)
        q_taken = (functional_call(base, (params, buffers), obs) * batch["action"]).sum(-1)
        next_q = functional_call(base, (target, buffers), next_obs)
        if double_dqn:
            chosen = functional_call(base, (params, buffers), next_obs).argmax(-1, keepdim=True)
            next_value = next_q.gather(-1, chosen).squeeze(-1)
        else:
            next_value = next_q.max(-1).values
        goal = (batch["reward"] + gamma ** batch["steps"] * (1.0 - batch["terminated"]) * next_value).detach()
        weights = batch["weight"]
        loss = (distance(q_taken, goal, reduction="none") * weights).sum() / weights.sum()
        return loss, (q_taken - goal).detach().pow(2)

    return torch.func.vmap(member_loss, in_dims=(0, 0, 0, 0))


def _update_inputs(samples: Sequence[TensorDictBase], in_keys: Sequence[str], weight_key: str) -> dict:
    """The members' sampled batches as [members, batch, ...] tensors, under flat names for vmap."""
    def stack(key: Any) -> torch.Tensor:
        return torch.stack([s.get(key) for s in samples])

    batch = {k: stack(k) for k in in_keys}
    batch.update({"next_" + k: stack(("next", k)) for k in in_keys})
    batch["action"] = stack("action").float()
    batch["reward"] = stack(("next", "reward")).squeeze(-1)
    batch["terminated"] = stack(("next", "terminated")).squeeze(-1).float()
    steps = [s.get("steps_to_next_obs", None) for s in samples]
    batch["steps"] = torch.ones_like(batch["reward"]) if steps[0] is None else \
        torch.stack(steps).reshape(batch["reward"].shape).float()
    batch["weight"] = stack(weight_key).reshape(batch["reward"].shape).float()
    return batch


def _clip_per_member(grads: Sequence[torch.Tensor], max_norm: float) -> torch.Tensor:
    """`clip_grad_norm_` applied to each member's slice of the stacked gradients; returns the norms."""
    norms = torch.stack([g.pow(2).flatten(1).sum(1) for g in grads]).sum(0).sqrt()
    coef = (max_norm / (norms + 1e-6)).clamp(max=1.0)
    for g in grads:
        g.mul_(coef.view(-1, *([1] * (g.dim() - 1))))
    return norms


def _train_lockstep(members: list[Member]) -> list[Path]:
    """Members at the same point of training, stepped together to the end."""
    job0 = members[0].job
    L = job0.learner
    device = torch.device(job0.device)
    m_count = len(members)
    for member in members:
        member.resume = _read_resume(member.job, member.checkpoint_dir)
    resume0 = members[0].resume

    if L.torch_threads > 0:
        torch.set_num_threads(L.torch_threads)
    # The process-wide generators (replay sampling, weight init) are seeded by the group: the same
    # group gives the same results twice.
    torch.manual_seed(job0.seed)
    np.random.seed(job0.seed)
    random.seed(job0.seed)

    n_envs = L.n_envs
    total_steps = math.ceil(L.total_steps / n_envs) * n_envs
    warmup_steps = math.ceil(L.warmup_steps / n_envs) * n_envs
    n_batches = total_steps // n_envs
    learn_from = min(warmup_steps, L.buffer_size)
    updates_per_target = max(1, round(L.target_update_steps / L.update_every))
    steps_done = int(resume0["env_steps"]) if resume0 else 0
    updates_done = int(resume0["updates"]) if resume0 else 0
    update_credit = float(resume0["update_credit"]) if resume0 else 0.0
    target_counter = int(resume0["target_counter"]) if resume0 else 0

    env = make_env(job0, job0.train_scenario, n_envs=m_count * n_envs, seed=[m.job.seed for m in members])
    sim = env.simulator
    parts = []
    for k, member in enumerate(members):
        job = member.job
        torch.manual_seed(job.seed)  # a member starts from the weights its solo run would start from
        net = make_network(job).to(device)
        actor = make_actor(net).to(device)
        loss_module = make_loss(L, actor).to(device)
        # Registered only so that TorchRL knows the target is updated: the group copies the
        # stacked target itself, with HardUpdate's rule.
        HardUpdate(loss_module, value_network_update_interval=updates_per_target - 1)
        optimizer = make_optimizer(L, loss_module.parameters())
        exploration = make_exploration(L, device)
        buffer = make_replay_buffer(L, device)
        beta = LinearScheduler(buffer, "beta", final_value=L.per_beta_end, num_steps=n_batches)
        explore_rng = torch.Generator(device=device)
        explore_rng.manual_seed(job.seed + EXPLORATION_SEED_OFFSET)
        resume = member.resume
        best_val = -math.inf
        if resume:
            best_val = float(resume.get("best_val_return", -math.inf))
            net.load_state_dict(resume["network"])
            loss_module.load_state_dict(resume["loss"])
            optimizer.load_state_dict(resume["optimizer"])
            exploration.load_state_dict(resume["exploration"])
            beta.load_state_dict(resume["beta_schedule"])
            buffer.sampler.beta = resume["beta"]
            if resume["replay_buffer"] is not None:
                buffer.load_state_dict(resume["replay_buffer"])
            sim.generators[k].set_state(resume["env_rng"])
            if "explore_rng" in resume:
                explore_rng.set_state(resume["explore_rng"])
            else:  # a solo checkpoint: a fresh stream, still a function of seed and step
                explore_rng.manual_seed(job.seed + EXPLORATION_SEED_OFFSET + steps_done)
        val_env = make_env(job, job.train_scenario, n_envs=L.val_envs, seed=job.seed + VAL_SEED_OFFSET) \
            if L.eval_every > 0 else None
        member.net = net
        parts.append({"actor": actor, "loss": loss_module, "optimizer": optimizer, "exploration": exploration,
                      "buffer": buffer, "beta": beta, "explore_rng": explore_rng,
                      "n_step": NStepReturns(L.n_step, L.gamma),
                      "val_env": val_env, "best_val": best_val, "train_key": train_key(job),
                      "config": recorded_training_config(job),
                      "episodes": {key: [] for key in TRAINING_CURVE_METRICS}, "losses": []})
    torch.manual_seed(job0.seed)
    if resume0:
        _set_rng_state(resume0["rng"])

    # --- the stacked online and target weights, and one Adam over them -----------------------------
    nets = [m.net for m in members]
    params, buffers = stack_module_state(nets)
    names = list(params)
    target_nets = []
    for member, p in zip(members, parts, strict=True):
        target_net = copy.deepcopy(member.net)
        _load_target_into(p["loss"], member.net, target_net)
        target_nets.append(target_net)
    target_params = {k: v.detach() for k, v in stack_module_state(target_nets)[0].items()}
    base = copy.deepcopy(nets[0]).to("meta")
    optimizer = make_optimizer(L, [params[n] for n in names])
    if resume0:
        _stack_adam_state(optimizer, params, names, nets, [p["optimizer"] for p in parts])
    in_keys = list(nets[0].in_keys)
    weight_key = parts[0]["loss"].tensor_keys.priority_weight
    # learner.update_dtype=bfloat16: the forward passes in bf16 (CUDA only; validation refuses it
    # elsewhere); weights, Adam and the priorities stay float32.
    bf16 = L.update_dtype == "bfloat16" and device.type == "cuda"
    stacked_loss = _stacked_loss(base, in_keys, L.gamma, L.double_dqn, L.loss_function)
    forward = torch.func.vmap(lambda p, b, *obs: functional_call(base, (p, b), obs))

    def act(td: TensorDictBase, random_only: bool) -> torch.Tensor:
        """Epsilon-greedy per member (random during the warm-up), each from its own stream."""
        actions = []
        greedy = None
        if not random_only:
            with torch.no_grad():
                obs = [td.get(k).reshape(m_count, n_envs, *td.get(k).shape[1:]) for k in in_keys]
                greedy = forward({n: params[n].detach() for n in names}, buffers, *obs).argmax(-1)
        for k, p in enumerate(parts):
            rng = p["explore_rng"]
            random_action = p["exploration"].random_actions(n_envs, generator=rng)
            if random_only:
                actions.append(random_action)
                continue
            explore = torch.rand(n_envs, generator=rng, device=device) < float(p["exploration"].eps)
            actions.append(torch.where(explore, random_action, greedy[k]))
        return F.one_hot(torch.cat(actions), N_ACTIONS).to(torch.bool)

    def sync_member(k: int) -> None:
        """Write member k's slices of the stacked state into its solo modules (for checkpoints and
        validation)."""
        p, net = parts[k], members[k].net
        with torch.no_grad():
            for name, tensor in net.named_parameters():
                tensor.copy_(params[name][k])
            for name, tensor in target_nets[k].named_parameters():
                tensor.copy_(target_params[name][k])
        _store_target_from(p["loss"], net, target_nets[k])
        _unstack_adam_state(optimizer, params, names, net, p["optimizer"], k)

    def checkpoint_state(k: int, finished: bool) -> dict[str, Any]:
        sync_member(k)
        p, job = parts[k], members[k].job
        small = _buffer_megabytes(p["buffer"]) <= L.checkpoint_buffer_max_mb
        return {
            "format": 1, "model": job.model.name, "train_key": p["train_key"], "training_config": p["config"],
            "finished": finished, "env_steps": steps_done, "updates": updates_done, "update_credit": update_credit,
            "network": members[k].net.state_dict(), "loss": p["loss"].state_dict(),
            "optimizer": p["optimizer"].state_dict(),
            "exploration": p["exploration"].state_dict(), "epsilon": float(p["exploration"].eps),
            "beta_schedule": p["beta"].state_dict(), "beta": float(p["buffer"].sampler.beta),
            "target_counter": target_counter,
            "replay_buffer": p["buffer"].state_dict() if small else None,
            "rng": _rng_state(), "env_rng": sim.generators[k].get_state(), "best_val_return": p["best_val"],
            "explore_rng": p["explore_rng"].get_state(), "grouped_with": [m.job.seed for m in members],
        }

    def save_all(finished: bool) -> None:
        for k, member in enumerate(members):
            save_checkpoint(checkpoint_state(k, finished), member.last_path)

    def validate(k: int) -> dict[str, float]:
        """As the solo loop's validation: greedy episodes in validation traffic; keeps best.pt."""
        p, member = parts[k], members[k]
        sync_member(k)
        member.net.eval()
        episodes = run_episodes(p["val_env"], p["actor"], L.val_episodes, member.job.seed + VAL_SEED_OFFSET)
        member.net.train()
        metrics = episode_means(episodes, "val")
        if metrics["val/episode_return"] > p["best_val"]:
            p["best_val"] = metrics["val/episode_return"]
            save_checkpoint(weights_only(checkpoint_state(k, finished=False)), member.checkpoint_dir / BEST_CHECKPOINT)
        metrics["val/best_episode_return"] = p["best_val"]
        return metrics

    logger.info("grouped training: %d members of '%s' (seeds %s) in one process, %d envs each",
                m_count, job0.model.name, [m.job.seed for m in members], n_envs)
    td = env.reset()
    last_log_steps, last_log_time = steps_done, time.perf_counter()
    # --- the loop: one decision in every env of every member, store, learn, log, checkpoint ---------
    while steps_done < total_steps:
        td.set("action", act(td, random_only=steps_done < warmup_steps))
        step, td = env.step_and_maybe_reset(td)
        steps_before, steps_done = steps_done, steps_done + n_envs
        transitions = step.exclude(*NOT_TRANSITION_KEYS)
        for k, p in enumerate(parts):
            rows = slice(k * n_envs, (k + 1) * n_envs)
            p["exploration"].step(n_envs)
            p["beta"].step()
            member_steps = transitions[rows]
            if L.reward_scale != 1.0 or L.collision_weight != 1.0:
                member_steps.set(("next", "reward"), training_reward(step[rows], L.reward_scale, L.collision_weight))
            windows = p["n_step"](member_steps.reshape(n_envs, 1))
            if windows is not None and windows.numel() > 0:
                p["buffer"].extend(windows.reshape(-1))
            done = step.get(("next", "done"))[rows].reshape(-1)
            if bool(done.any()):
                finished = step.get(("next", "episode"))[rows][done]
                for key in TRAINING_CURVE_METRICS:
                    p["episodes"][key].extend(finished[key].tolist())

        if len(parts[0]["buffer"]) >= learn_from:
            update_credit += n_envs / L.update_every
            loss = None
            while update_credit >= 1.0:
                update_credit -= 1.0
                samples = [p["buffer"].sample() for p in parts]
                with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
                    loss, td_error = stacked_loss({n: params[n] for n in names}, buffers, target_params,
                                                  _update_inputs(samples, in_keys, weight_key))
                loss, td_error = loss.float(), td_error.float()
                optimizer.zero_grad(set_to_none=False)
                loss.sum().backward()  # member k's loss reaches only member k's slice
                _clip_per_member([params[n].grad for n in names], L.max_grad_norm)
                optimizer.step()
                priority = torch.nan_to_num(td_error.sqrt(), nan=1.0, posinf=1.0)
                for k, p in enumerate(parts):
                    p["buffer"].update_priority(samples[k]["index"], priority[k])
                    p["losses"].append(loss[k].detach())
                if target_counter == updates_per_target - 1:  # HardUpdate's rule, per member alike
                    target_counter = 0
                    for n in names:
                        target_params[n].copy_(params[n].detach())
                else:
                    target_counter += 1
                updates_done += 1
            if loss is not None and not bool(torch.isfinite(loss).all()):
                bad = [members[k].job.seed for k in range(m_count) if not math.isfinite(float(loss[k]))]
                raise NonFiniteLossError(
                    f"training loss became non-finite at env step {steps_done} (update {updates_done}) for model "
                    f"'{job0.model.name}' seeds {bad} of a training group; stopped. The last good checkpoints are "
                    f"the members' last.pt. Try a lower learner.lr (now {L.lr}) or learner.max_grad_norm.")

        if steps_done // L.log_every > steps_before // L.log_every or steps_done >= total_steps:
            now = time.perf_counter()
            for k, p in enumerate(parts):
                metrics = {f"train/{key}": float(np.mean(v)) for key, v in p["episodes"].items() if v}
                if p["losses"]:
                    metrics["train/loss"] = float(torch.stack(p["losses"]).mean())
                metrics.update({"train/epsilon": float(p["exploration"].eps),
                                "train/beta": float(p["buffer"].sampler.beta),
                                "train/steps_per_s": (steps_done - last_log_steps) / max(now - last_log_time, 1e-9),
                                "train/episodes": float(len(p["episodes"]["avg_speed_kmh"])),
                                "train/updates": float(updates_done)})
                if p["val_env"] is not None and (steps_done // L.eval_every > steps_before // L.eval_every
                                                 or steps_done >= total_steps):
                    try:
                        metrics.update(validate(k))
                    except JobInterrupted:  # stopped between validation steps: checkpoint, then stop
                        save_all(finished=False)
                        raise
                with deferred():
                    members[k].log(metrics, steps_done)
                p["episodes"] = {key: [] for key in TRAINING_CURVE_METRICS}
                p["losses"] = []
            logger.info("grouped training '%s': %d/%d env steps per member, %.0f steps/s per member",
                        job0.model.name, steps_done, total_steps,
                        (steps_done - last_log_steps) / max(now - last_log_time, 1e-9))
            last_log_steps, last_log_time = steps_done, now

        if steps_done // L.checkpoint_every > steps_before // L.checkpoint_every and steps_done < total_steps:
            save_all(finished=False)
        if pending() and steps_done < total_steps:
            # A stop signal ends the group between batches: every member's last.pt first.
            save_all(finished=False)
            raise_if_pending()

    finals = []
    for k, member in enumerate(members):
        final = checkpoint_state(k, finished=True)
        finals.append(save_final(final, member.checkpoint_dir))
    return finals


# --- between the stacked tensors and a member's solo modules ---------------------------------------
def _target_entries(loss_module: torch.nn.Module, net: torch.nn.Module) -> dict[str, Any]:
    """The loss module's target-weight keys, by the network's parameter names."""
    name_of = {id(p): n for n, p in net.named_parameters()}
    online = loss_module.value_network_params
    entries = {}
    for key in online.keys(include_nested=True, leaves_only=True):
        name = name_of.get(id(online.get(key)))
        if name is not None:
            entries[name] = key
    return entries


def _load_target_into(loss_module: torch.nn.Module, net: torch.nn.Module, target_net: torch.nn.Module) -> None:
    entries = _target_entries(loss_module, net)
    target = loss_module.target_value_network_params
    with torch.no_grad():
        for name, tensor in target_net.named_parameters():
            tensor.copy_(target.get(entries[name]))


def _store_target_from(loss_module: torch.nn.Module, net: torch.nn.Module, target_net: torch.nn.Module) -> None:
    entries = _target_entries(loss_module, net)
    target = loss_module.target_value_network_params
    with torch.no_grad():
        for name, tensor in target_net.named_parameters():
            target.get(entries[name]).data.copy_(tensor)


def _stack_adam_state(optimizer: torch.optim.Adam, params: dict, names: list[str], nets: Sequence[torch.nn.Module],
                      member_optimizers: Sequence[torch.optim.Adam]) -> None:
    """Adam's moments of every member (restored into their solo optimisers) stacked into the group's."""
    for name in names:
        member_states = [opt.state.get(dict(net.named_parameters())[name])
                         for opt, net in zip(member_optimizers, nets, strict=True)]
        if any(not s for s in member_states):
            continue  # no update yet
        optimizer.state[params[name]] = {
            "step": member_states[0]["step"].clone(),
            "exp_avg": torch.stack([s["exp_avg"] for s in member_states]),
            "exp_avg_sq": torch.stack([s["exp_avg_sq"] for s in member_states]),
        }


def _unstack_adam_state(optimizer: torch.optim.Adam, params: dict, names: list[str], net: torch.nn.Module,
                        member_optimizer: torch.optim.Adam, k: int) -> None:
    """Member k's slices of the group's Adam moments, into its solo optimiser."""
    by_name = dict(net.named_parameters())
    for name in names:
        state = optimizer.state.get(params[name])
        if not state:
            continue
        member_optimizer.state[by_name[name]] = {"step": state["step"].clone(), "exp_avg": state["exp_avg"][k].clone(),
                                                 "exp_avg_sq": state["exp_avg_sq"][k].clone()}
