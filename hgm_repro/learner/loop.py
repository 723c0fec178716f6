"""Dueling DQN + prioritized replay on TorchRL: the one training loop, for one member or many.

`train(job, ...)` trains one model seed; `train_group(jobs, ...)` trains the seeds of one model in
one process (`runtime.grouped`, see `grouped.py` for when). Both run `_train_together`: one batched
simulator holds every member's envs in contiguous blocks, each block drawing its traffic from its
member's own generator (`HighwaySimulator(seed=[...])`), so a member meets the same traffic alone or
in any group; TorchRL's `Collector` steps it with every member's epsilon-greedy policy on its own
block; each member (`member.py`) stores its transitions, learns from its own prioritized replay
with its own `DQNLoss`, target rule, Adam and moving average, validates, logs and checkpoints. The
group's `Progress` (`progress.py`: env steps, updates, update credit) is what every member's
checkpoint records and a resume starts from. A solo run is a group of one, and a group of one gives
exactly the solo run.

What a member of a larger group draws differently from its solo run is only the exploration and the
replay sampling (the process's generator serves the members in turn); its traffic and its first
weights are its solo run's. See the package docstring (`hgm_repro.learner`) for what a checkpoint
holds and what a resume restores.
"""

from __future__ import annotations

import logging
import math
import random
import sys
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector
from tqdm import tqdm

from ..contracts.interrupts import JobInterrupted, deferred, pending, raise_if_pending
from ..contracts.runtime_choice import use_overlap
from ..contracts.schema import JobConfig
from ..envs import make_env
from ..models.builders import make_actor
from .builders import make_policy
from .grouped import check_group
from .member import Log, Member, set_rng_state
from .overlap import ActingCopies, Prefetcher
from .progress import Progress

logger = logging.getLogger(__name__)


def train(job: JobConfig, checkpoint_dir: Path, log: Log) -> Path:
    """Train `job.model` on `job.train_scenario`; returns the final checkpoint's path.

    Resumes from `checkpoint_dir/last.pt` when it exists (and belongs to this config), and
    returns `final.pt` at once when the run already finished.
    """
    return train_group([job], [checkpoint_dir], [log])[0]


def train_group(jobs: Sequence[JobConfig], checkpoint_dirs: Sequence[Path], logs: Sequence[Log]) -> list[Path]:
    """Train every member (`jobs[k]` into `checkpoint_dirs[k]`, curves to `logs[k]`); returns each
    member's final checkpoint, in order.

    Finished members return at once, the others resume from their `last.pt`. Members that stopped at
    different env steps train in separate groups, one after the other (a group steps in lockstep).
    """
    jobs = list(jobs)
    check_group(jobs)
    members = [Member(job, Path(d), log) for job, d, log in zip(jobs, checkpoint_dirs, logs, strict=True)]
    finals: dict[int, Path] = {}
    waiting: dict[tuple, list[int]] = {}
    for k, member in enumerate(members):
        resume = member.read_resume()
        if resume is not None and resume["finished"]:
            finals[k] = member.finished_path()
            continue
        progress = Progress.from_checkpoint(resume)
        point = (progress.env_steps, progress.updates, resume is None or resume["replay_buffer"] is not None)
        waiting.setdefault(point, []).append(k)
    for ks in waiting.values():
        finals.update(zip(ks, _train_together([members[k] for k in ks]), strict=True))
    return [finals[k] for k in range(len(jobs))]


class MemberPolicies(TensorDictModuleBase):
    """Every member's epsilon-greedy policy, each on its own block of the group's envs."""

    def __init__(self, policies: Sequence[TensorDictModuleBase], member_envs: int):
        super().__init__()
        self.policies = torch.nn.ModuleList(policies)
        self.member_envs = member_envs
        self.in_keys = list(policies[0].in_keys)
        self.out_keys = list(policies[0].out_keys)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        n = self.member_envs
        outs = [policy(td[k * n:(k + 1) * n].copy()).select(*self.out_keys) for k, policy in enumerate(self.policies)]
        td.update(torch.cat(outs, 0))  # only what the policies wrote: the observations stay where they are
        return td


def _train_together(members: list[Member]) -> list[Path]:
    """Members at the same point of training, stepped together to the end."""
    job0 = members[0].job
    L = job0.learner
    device = torch.device(job0.device)
    count, n_envs = len(members), L.n_envs
    log_every, checkpoint_every, val_every = job0.logging.log_every, job0.logging.checkpoint_every, job0.eval.val_every
    resume0 = members[0].resume

    if job0.runtime.torch_threads > 0:
        torch.set_num_threads(job0.runtime.torch_threads)
    # The process-wide generators (replay sampling, exploration, the warm-up's random actions) are
    # seeded by the group's first member: the same group gives the same results twice.
    torch.manual_seed(job0.seed)
    np.random.seed(job0.seed)
    random.seed(job0.seed)

    # Round the total up to whole batches so that a fresh and a resumed run stop at the same step.
    total_steps = math.ceil(L.total_steps / n_envs) * n_envs
    warmup_steps = math.ceil(L.warmup_steps / n_envs) * n_envs
    seeds = [m.job.seed for m in members]
    progress = Progress.from_checkpoint(resume0, group=seeds if count > 1 else None)

    env = make_env(job0, job0.train_scenario, n_envs=count * n_envs, seed=seeds[0] if count == 1 else seeds)
    for k, member in enumerate(members):
        if count > 1:
            torch.manual_seed(member.job.seed)  # a member starts from the weights its solo run starts from
        member.build(env, slice(k * n_envs, (k + 1) * n_envs), n_batches=total_steps // n_envs)
    for member in members:
        member.restore()
    if resume0:
        set_rng_state(resume0["rng"])

    # Updates start once the memory holds the warm-up's worth of transitions. On a fresh run that
    # is exactly `warmup_steps` steps of random actions; on a resume without a stored memory the
    # restored epsilon-greedy policy refills it first (those steps count as env steps).
    learn_from = min(warmup_steps, L.buffer_size)
    # runtime.overlap: the next batch is collected in a second thread while this one trains
    # (overlap.py), by acting copies of the networks that the updates never write.
    overlap = use_overlap(job0.runtime.overlap, device)
    acting = ActingCopies([m.net for m in members]) if overlap else None
    policies = [m.policy for m in members] if acting is None else \
        [make_policy(make_actor(net).to(device), m.exploration) for net, m in zip(acting.acting, members, strict=True)]
    policy = policies[0] if count == 1 else MemberPolicies(policies, n_envs)
    collector = Collector(
        env, policy, frames_per_batch=count * n_envs, total_frames=(total_steps - progress.env_steps) * count,
        init_random_frames=max(0, warmup_steps - progress.env_steps) * count, device=device, storing_device=device,
        auto_register_policy_transforms=False)  # the Q-network is feed-forward: no InitTracker needed

    name = job0.model.name if count == 1 else f"{job0.model.name} seeds {seeds}"
    bar = tqdm(total=total_steps, initial=progress.env_steps, unit="step", desc=f"train {name}",
               disable=not sys.stdout.isatty(), dynamic_ncols=True)
    if count > 1:
        logger.info("grouped training: %d members of '%s' (seeds %s) in one process, %d envs each",
                    count, job0.model.name, seeds, n_envs)
    # CPU time as well as wall time: on a shared machine the wall rate measures the other load too.
    last_log_steps, last_log_time, last_log_cpu = progress.env_steps, time.perf_counter(), time.process_time()
    batches = iter(collector)
    prefetch = Prefetcher(batches) if overlap else None

    # --- the loop: one decision in every env, store it, learn, log, checkpoint ----------------------
    try:
        collected = next(batches, None)
        while collected is not None:
            batch: TensorDictBase = collected.reshape(count * n_envs, -1)  # [envs, time]
            steps_before = progress.env_steps
            progress.env_steps += batch.numel() // count
            finished = progress.env_steps >= total_steps
            for member in members:
                member.observe(batch[member.rows])
            if prefetch is not None:
                prefetch.start()  # the next batch, collected while this one trains

            if len(members[0].memory) >= learn_from:
                updates = progress.earn_updates(batch.numel() // count, L.update_every)
                for member in members:
                    member.learn(updates, progress)
                progress.updates += updates
                if prefetch is None:
                    collector.update_policy_weights_()
            if prefetch is not None:
                collected = prefetch.result()
                acting.refresh()  # the collector is idle now: the next batch acts with these weights

            bar.update(progress.env_steps - steps_before)
            if bar.n % (50 * n_envs) < n_envs:
                bar.set_postfix(eps=f"{float(members[0].exploration.eps):.3f}",
                                speed_kmh=f"{members[0].recent_speed:.1f}", refresh=False)

            if progress.crossed(steps_before, log_every) or finished:
                now, cpu = time.perf_counter(), time.process_time()
                rate = (progress.env_steps - last_log_steps) / max(now - last_log_time, 1e-9)
                cpu_rate = (progress.env_steps - last_log_steps) / max(cpu - last_log_cpu, 1e-9)
                validating = val_every > 0 and (progress.crossed(steps_before, val_every) or finished)
                try:
                    _log_interval(members, progress, total_steps, rate, validating, lines=bar.disable,
                                  cpu_rate=cpu_rate)
                except JobInterrupted:  # stopped between validation steps: last.pt first, as below
                    _save_last(members, progress, finished)
                    raise
                last_log_steps, last_log_time, last_log_cpu = progress.env_steps, now, cpu

            if progress.crossed(steps_before, checkpoint_every) and not finished:
                _save_last(members, progress)
            # A stop signal ends training between batches, never inside one: every member's last.pt
            # holds everything up to this batch (a resume loses nothing), then the signal is raised.
            if pending() and not finished:
                _save_last(members, progress)
                raise_if_pending()
            if prefetch is None:
                collected = next(batches, None)
    finally:  # however the loop ends (done, a stop signal, a non-finite loss): nothing goes on stepping the envs
        bar.close()
        if prefetch is not None:
            prefetch.close()
        collector.shutdown()

    if progress.env_steps < total_steps:  # pragma: no cover - the collector stops exactly at total_frames
        warnings.warn(f"collector stopped at {progress.env_steps} of {total_steps} env steps", stacklevel=2)
    return [member.save_final(progress) for member in members]


def _save_last(members: Sequence[Member], progress: Progress, finished: bool = False) -> None:
    for member in members:
        member.save_last(progress, finished)


def _log_interval(members: Sequence[Member], progress: Progress, total_steps: int, rate: float, validating: bool,
                  lines: bool, cpu_rate: float | None = None) -> None:
    """A log point: each member's curves since the last one (and a greedy validation pass when one
    is due) go to its log; with `lines` (no progress bar: output goes to a file) a line per member.
    `rate`, `cpu_rate`: env steps per member per second of wall time and of the process's CPU time."""
    grouped = len(members) > 1
    for member in members:
        metrics = member.interval_metrics(rate, progress.updates, cpu_rate)
        if validating:
            metrics.update(member.validate(progress))
        with deferred():  # a signal during the store write waits for the loop's stop, after last.pt
            member.log(metrics, progress.env_steps)
        if lines:
            # The greedy validation is named only on the lines of a pass (a "nan" on the others read
            # as a failed validation).
            greedy = (f"; greedy validation: return {metrics['val/episode_return']:.0f}, crashes per "
                      f"episode {metrics['val/collisions']:.2f}" if "val/collisions" in metrics else "")
            logger.info("train %s: %d/%d env steps, %.0f steps/s, epsilon %.3f, mean speed %.1f km/h, "
                        "crashes per episode %.2f%s",
                        f"{member.job.model.name} seed {member.job.seed}" if grouped else member.job.model.name,
                        progress.env_steps, total_steps, rate, metrics["train/epsilon"],
                        metrics.get("train/avg_speed_kmh", float("nan")),
                        metrics.get("train/collisions", float("nan")), greedy)
    if grouped:  # one line per group (scripts/gpu/protocol.sh reads its rate)
        logger.info("grouped training '%s': %d/%d env steps per member, %.0f steps/s per member",
                    members[0].job.model.name, progress.env_steps, total_steps, rate)
