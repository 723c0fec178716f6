"""Benchmark: how fast the simulator, the observation builders and the learner run here.

    python -m hgm_repro.bench                 # everything that applies to this machine
    python -m hgm_repro.bench --only simulator --n-envs 1,1024

Prints one JSON object per measured configuration on stdout (progress goes to stderr), with at
least `what`, `device`, `n_envs`, `camera`, `env_steps_per_s` (and `updates_per_s` for the
learner). The TorchRL env and the Gymnasium VectorEnv are measured side by side (N=256 by
default; `vs_torchrl_env` on the VectorEnv's line). With the `highway` extra installed it measures
highway-env's `highway-v0` (5 lanes, 50 vehicles) in the same run, so the ratio is taken side by
side on the same machine.
"""

from __future__ import annotations

import argparse
import json
import logging
import platform
import sys
import time
from collections.abc import Callable
from typing import Any

import torch

from .contracts.config_files import observation_config, scenario_config, simulator_config
from .contracts.runtime_choice import bf16_supported
from .simulator import HOST, HighwaySimulator

OBS_VARIANTS = {  # name -> the model streams it stands for
    "hgm": dict(camera="none", hgm="paper", coordinates=False),
    "hgm_enriched": dict(camera="none", hgm="enriched", coordinates=False),
    "camera": dict(camera="front", hgm="none", coordinates=False),
    "birdseye": dict(camera="birdseye", hgm="none", coordinates=False),
    "coordinates": dict(camera="none", hgm="none", coordinates=True),
    "proposed": dict(camera="front", hgm="paper", coordinates=False),
    "min": dict(camera="front", hgm="none", coordinates=False),
    "coordinate_model": dict(camera="front", hgm="none", coordinates=True),
}


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _timed(fn: Callable[[], Any], device: torch.device, seconds: float, warmup: int = 3) -> tuple[int, float]:
    """Calls fn until `seconds` have passed; returns (calls, elapsed)."""
    for _ in range(warmup):
        fn()
    _sync(device)
    calls, start = 0, time.perf_counter()
    while True:
        fn()
        calls += 1
        if calls % 5 == 0 or seconds <= 0:
            _sync(device)
            elapsed = time.perf_counter() - start
            if elapsed >= seconds:
                return calls, elapsed


def _simulator(n_envs: int, device: torch.device, seed: int = 0) -> HighwaySimulator:
    cfg = simulator_config(host_safety_layer=True)
    return HighwaySimulator(cfg, scenario_config("train", cfg), n_envs, device=device, seed=seed)


def bench_simulator(n_envs: int, device: torch.device, seconds: float) -> dict[str, Any]:
    sim = _simulator(n_envs, device)

    def one_step() -> None:
        res = sim.step(sim.npc_actions(sim.state)[:, HOST])
        sim.reset(res.done)

    calls, elapsed = _timed(one_step, device, seconds)
    return dict(what="simulator", device=str(device), n_envs=n_envs, camera="none", hgm="none",
                env_steps_per_s=round(calls * n_envs / elapsed, 1))


def bench_observations(variant: str, n_envs: int, device: torch.device, seconds: float,
                       size: int = 84, frame_stack: int = 4) -> dict[str, Any]:
    from .observations import ObservationBuilder

    streams = OBS_VARIANTS[variant]
    obs_cfg = observation_config(streams, height=size, width=size, frame_stack=frame_stack)
    sim = _simulator(n_envs, device)
    builder = ObservationBuilder(sim, obs_cfg)
    builder.reset()

    def one_step() -> None:
        res = sim.step(sim.npc_actions(sim.state)[:, HOST])
        builder.step()
        if bool(res.done.any()):
            sim.reset(res.done)
            builder.reset(res.done)

    calls, elapsed = _timed(one_step, device, seconds)
    return dict(what=f"simulator+{variant}", device=str(device), n_envs=n_envs, camera=streams["camera"],
                hgm=streams["hgm"], coordinates=streams["coordinates"], image=f"{size}x{size}",
                frame_stack=frame_stack, env_steps_per_s=round(calls * n_envs / elapsed, 1))


def bench_observations_under_resets(variant: str, n_envs: int, device: torch.device, seconds: float,
                                    reset_fraction: float = 1 / 16, size: int = 84,
                                    frame_stack: int = 4) -> dict[str, Any]:
    """Observation cost when every step also resets a few envs, as early in training (short
    episodes that end in crashes): each step a random `reset_fraction` of the envs restarts, and the
    builder pushes a frame for all envs and refills the stacks of the reset ones, as the TorchRL env
    does. `observation_env_steps_per_s` counts only the builders' time; `reset_cost_vs_step` is the
    time spent refilling the reset envs' stacks over the time of pushing one frame for all envs (a
    ratio taken within the run, so that it holds on a busy machine)."""
    from .observations import ObservationBuilder

    streams = OBS_VARIANTS[variant]
    obs_cfg = observation_config(streams, height=size, width=size, frame_stack=frame_stack)
    sim = _simulator(n_envs, device)
    builder = ObservationBuilder(sim, obs_cfg)
    builder.reset()
    gen = torch.Generator(device=device).manual_seed(0)
    builder_seconds: list[tuple[float, float]] = []  # (push a frame for all envs, refill the reset ones)

    def one_step() -> None:
        sim.step(sim.npc_actions(sim.state)[:, HOST])
        restart = torch.rand(n_envs, generator=gen, device=device) < reset_fraction
        sim.reset(restart)
        _sync(device)
        start = time.perf_counter()
        builder.step()
        _sync(device)
        pushed = time.perf_counter()
        builder.reset(restart)
        _sync(device)
        builder_seconds.append((pushed - start, time.perf_counter() - pushed))

    calls, elapsed = _timed(one_step, device, seconds)
    push, refill = (sum(t) for t in zip(*builder_seconds[-calls:], strict=True))  # without the warm-up calls
    return dict(what=f"simulator+{variant} under resets", device=str(device), n_envs=n_envs,
                camera=streams["camera"], hgm=streams["hgm"], coordinates=streams["coordinates"],
                image=f"{size}x{size}", frame_stack=frame_stack, reset_fraction=reset_fraction,
                env_steps_per_s=round(calls * n_envs / elapsed, 1),
                observation_env_steps_per_s=round(calls * n_envs / (push + refill), 1),
                reset_cost_vs_step=round(refill / push, 3))


def bench_envs(n_envs: int, device: torch.device, seconds: float, rounds: int = 3) -> list[dict[str, Any]]:
    """The TorchRL env (stepped as its collector does: `step_and_maybe_reset`) and the Gymnasium
    VectorEnv (`make_vec`, numpy out) at the same batch size, with the same configs and
    observations (the proposed model's camera + HGM, 84x84, 4 frames), random actions, autoreset.
    They take turns over `rounds` rounds, so that a change of load on a shared machine hits both."""
    import gymnasium as gym
    import numpy as np

    from .envs import ENV_ID
    from .envs.torchrl_env import HeterogeneousHighwayEnv
    from .simulator import N_ACTIONS

    vec = gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode="vector_entry_point", observation="hgm",
                       device=device, seed=0)
    core = vec.unwrapped.core
    env = HeterogeneousHighwayEnv(core.sim_config, core.scenario, core.observations.builder.cfg, n_envs,
                                  device=device, seed=0)
    rng = np.random.default_rng(0)
    gen = torch.Generator(device=device).manual_seed(0)
    vec.reset(seed=0)
    td = env.reset()

    def torchrl_step() -> None:
        nonlocal td
        action = torch.randint(0, N_ACTIONS, (n_envs,), device=device, generator=gen)
        td["action"] = torch.nn.functional.one_hot(action, N_ACTIONS)
        _, td = env.step_and_maybe_reset(td)

    def vector_step() -> None:
        vec.step(rng.integers(0, N_ACTIONS, n_envs))

    totals = {"torchrl env": [0, 0.0], "gymnasium vector env": [0, 0.0]}
    for _ in range(rounds):
        for what, fn in (("torchrl env", torchrl_step), ("gymnasium vector env", vector_step)):
            calls, elapsed = _timed(fn, device, seconds / rounds)
            totals[what][0] += calls
            totals[what][1] += elapsed
    vec.close()
    cfg = core.observations.builder.cfg
    rows = [dict(what=what, device=str(device), n_envs=n_envs, camera=cfg.camera, hgm=cfg.hgm,
                 image=f"{cfg.height}x{cfg.width}", frame_stack=cfg.frame_stack,
                 env_steps_per_s=round(calls * n_envs / elapsed, 1)) for what, (calls, elapsed) in totals.items()]
    rows[1]["vs_torchrl_env"] = round(rows[1]["env_steps_per_s"] / rows[0]["env_steps_per_s"], 3)
    return rows


def _compose(*overrides: str) -> Any:
    """The validated `JobConfig` of the root config plus `overrides`."""
    from hydra import compose, initialize_config_dir

    from .contracts.conf_dir import CONF_DIR
    from .contracts.schema import check_config

    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return check_config(compose("config", overrides=list(overrides)))


def _update_batch(job: Any, device: torch.device, gen: torch.Generator) -> Any:
    """A replay sample of random images at `job`'s observation size and batch size."""
    from tensordict import TensorDict

    from .simulator import N_ACTIONS

    b, h, w, f = job.learner.batch_size, job.observation.height, job.observation.width, job.observation.frame_stack

    def images() -> torch.Tensor:
        return torch.randint(0, 256, (b, 3 * f, h, w), dtype=torch.uint8, device=device, generator=gen)

    action = torch.nn.functional.one_hot(torch.randint(0, N_ACTIONS, (b,), device=device, generator=gen), N_ACTIONS)
    flags = torch.zeros(b, 1, dtype=torch.bool, device=device)
    return TensorDict({
        "camera": images(), "hgm": images(), "action": action.bool(),
        "next": {"camera": images(), "hgm": images(), "reward": torch.randn(b, 1, device=device, generator=gen),
                 "done": flags, "terminated": flags.clone(), "truncated": flags.clone()},
    }, batch_size=[b], device=device)


def _member_update(job: Any, device: torch.device) -> tuple[Any, torch.nn.Module]:
    """One member's update step, built by the learner's own builders, and its network."""
    from .learner.builders import make_loss, make_optimizer, make_update
    from .models.builders import make_actor, make_network

    net = make_network(job).to(device)
    loss = make_loss(job.learner, make_actor(net).to(device)).to(device)
    capturable = job.runtime.cuda_graph and device.type == "cuda"
    optimizer = make_optimizer(job.learner, loss.parameters(), capturable=capturable)
    return make_update(job.learner, job.runtime, loss, optimizer, device), net


def bench_learner_updates(device: torch.device, seconds: float, batch_size: int = 64,
                          mode: str = "eager") -> dict[str, Any]:
    """Gradient updates per second of the paper's network (84x84, 4 frames) at Table 4's batch size,
    built by the learner's own builders; `mode` is eager, compile or cuda_graph."""
    job = _compose("experiment=paper", f"device={device}", f"learner.batch_size={batch_size}",
                   f"runtime.compile={mode == 'compile'}", f"runtime.cuda_graph={mode == 'cuda_graph'}")
    update, net = _member_update(job, device)
    batch = _update_batch(job, device, torch.Generator(device=device).manual_seed(0))
    calls, elapsed = _timed(lambda: update(batch.clone()), device, seconds, warmup=12)
    params = sum(p.numel() for p in net.parameters())
    return dict(what="learner update", device=str(device), n_envs=0, camera="front", hgm="paper", mode=mode,
                batch_size=batch_size, image=f"{job.observation.height}x{job.observation.width}", parameters=params,
                env_steps_per_s=None, updates_per_s=round(calls / elapsed, 1))


def bench_learner_training(device: torch.device, total_steps: int) -> dict[str, Any]:
    """Training env-steps per second end to end (collection, replay, updates) with the quick preset."""
    import tempfile
    from pathlib import Path

    from .learner import train

    n_envs = 16 if device.type == "cpu" else 64
    job = _compose("experiment=quick", f"device={device}", f"learner.total_steps={total_steps}",
                   f"learner.warmup_steps={total_steps // 4}", f"learner.n_envs={n_envs}",
                   f"logging.checkpoint_every={total_steps * 10}", f"logging.log_every={total_steps * 10}")
    threads = torch.get_num_threads()  # the preset may pin its own thread count: put ours back after
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        train(job, Path(tmp), lambda metrics, step: None)
        _sync(device)
        elapsed = time.perf_counter() - start
    used = torch.get_num_threads()
    torch.set_num_threads(threads)
    return dict(what="learner training (quick preset, end to end)", device=str(device), n_envs=n_envs,
                camera="front", hgm="paper", image=f"{job.observation.height}x{job.observation.width}",
                update_every=job.learner.update_every, env_steps_per_s=round(total_steps / elapsed, 1),
                torch_threads=used)


GROUPED_PATHS = ("grouped", "sequential", "parallel")
PARTS = ("simulator", "observations", "envs", "learner", "grouped", "highway")  # the default parts


def _member_job(device: torch.device, total_steps: int, seed: int, threads: int, preset: str = "quick",
                warmup_steps: int | None = None, log_every: int | None = None, overrides: tuple[str, ...] = ()) -> Any:
    """One training member of the grouped-training lines: `preset` (the quick one's env count resized
    to the device), no validation, no logs but the last (or every `log_every` env steps)."""
    sized = [f"learner.n_envs={16 if device.type == 'cpu' else 64}"] if preset == "quick" else []
    return _compose(f"experiment={preset}", f"device={device}", f"seed={seed}", f"learner.total_steps={total_steps}",
                    f"learner.warmup_steps={total_steps // 4 if warmup_steps is None else warmup_steps}", *sized,
                    f"runtime.torch_threads={threads}", "eval.val_every=0",
                    "eval.checkpoint=final",  # no validation, so no best.pt for the preset's test to drive
                    f"logging.checkpoint_every={total_steps * 10}",
                    f"logging.log_every={log_every or total_steps * 10}", *overrides)


def _quiet_torchrl() -> None:
    """stdout carries only the JSON lines: TorchRL logs its storage set-up there at INFO level (and
    sets that level when first imported, so import it before turning it down). Each process that
    trains calls this: the parallel path's workers are fresh processes."""
    import torchrl  # noqa: F401

    logging.getLogger("torchrl").setLevel(logging.WARNING)


def _train_member(device: str, total_steps: int, seed: int, threads: int, directory: str) -> tuple[int, int]:
    """Train one member alone (in whichever process calls it); its (env steps, updates)."""
    from pathlib import Path

    from .contracts.checkpoint import load_checkpoint
    from .learner import train

    _quiet_torchrl()
    job = _member_job(torch.device(device), total_steps, seed, threads)
    final = load_checkpoint(train(job, Path(directory), lambda metrics, step: None))
    return int(final["env_steps"]), int(final["updates"])


def bench_grouped_training(device: torch.device, total_steps: int, members: int, path: str,
                           threads: int, preset: str = "quick", warmup_steps: int | None = None,
                           log_every: int | None = None, overrides: tuple[str, ...] = ()) -> dict[str, Any]:
    """Aggregate training speed of `members` seeds with `preset` (default quick), end to end, by one of
    three paths: `grouped` (one process, one simulator and one Collector for the members, `threads` torch threads),
    `sequential` (one process, the members one after another on `threads` threads) or `parallel`
    (one solo job per core at once, one thread each: what a joblib sweep of solo jobs does).
    `env_steps_per_s` and `updates_per_s` are summed over the members. The grouped path also gives
    `member_env_steps_per_s`, one member's rate in the training loop alone (its `train/steps_per_s`
    over the last `log_every` steps, or the whole loop), and `fixed_s`, the rest of the time (building
    the group, the first updates' start, the final checkpoints): what a longer training of the same
    group costs is about fixed_s + steps / member_env_steps_per_s."""
    import tempfile
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context
    from pathlib import Path

    from .contracts.checkpoint import load_checkpoint
    from .learner import train_group

    if path not in GROUPED_PATHS:
        raise ValueError(f"path={path!r} is not one of {GROUPED_PATHS}")
    jobs = [_member_job(device, total_steps, seed, threads, preset, warmup_steps, log_every, overrides)
            for seed in range(members)]
    before = torch.get_num_threads()
    processes = 1
    loop_rates: list[float] = []  # the members' train/steps_per_s since their previous log

    def log(metrics: dict[str, float], step: int) -> None:
        loop_rates.append(metrics["train/steps_per_s"])

    with tempfile.TemporaryDirectory() as tmp:
        dirs = [Path(tmp) / f"member{k}" for k in range(members)]
        start = time.perf_counter()
        if path == "grouped":
            finals = [load_checkpoint(f) for f in train_group(jobs, dirs, [log] * members)]
            counts = [(int(f["env_steps"]), int(f["updates"])) for f in finals]
        elif path == "sequential":
            counts = [_train_member(str(device), total_steps, seed, threads, str(d)) for seed, d in enumerate(dirs)]
        else:
            # Fresh interpreters (spawn): a forked child would inherit this process's torch threads.
            processes = min(members, threads)
            with ProcessPoolExecutor(processes, mp_context=get_context("spawn")) as pool:
                counts = list(pool.map(_train_member, [str(device)] * members, [total_steps] * members,
                                       range(members), [1] * members, [str(d) for d in dirs]))
        _sync(device)
        elapsed = time.perf_counter() - start
    torch.set_num_threads(before)
    steps, updates = sum(c[0] for c in counts), sum(c[1] for c in counts)
    label = {"grouped": "grouped", "sequential": "solo, one after another",
             "parallel": f"solo, {processes} jobs at once"}[path]
    row = dict(what=f"learner training, members ({preset} preset, end to end)", device=str(device), members=members,
               path=label, n_envs=jobs[0].learner.n_envs * members, camera="front", hgm="paper",
               image=f"{jobs[0].observation.height}x{jobs[0].observation.width}",
               env_steps_per_s=round(steps / elapsed, 1), updates_per_s=round(updates / elapsed, 2),
               torch_threads=1 if path == "parallel" else threads, processes=processes)
    if path == "grouped" and loop_rates:
        member_rate = loop_rates[-1]
        row.update(preset=preset, member_steps=counts[0][0], warmup_steps=jobs[0].learner.warmup_steps,
                   update_every=jobs[0].learner.update_every, member_env_steps_per_s=round(member_rate, 1),
                   fixed_s=round(max(elapsed - counts[0][0] / member_rate, 0.0), 2))
    if overrides:
        row["overrides"] = " ".join(overrides)
    return row


TRAINING_PATHS = {
    # What one training ran before the CPU's second core and bf16 were used: float32, one thread,
    # collect then update.
    "baseline": ("runtime.update_dtype=float32", "runtime.overlap=false", "runtime.torch_threads=1"),
    # The preset as the main job runs it: the baseline's algorithm with torch's threads on every core
    # the job may use (runtime.torch_threads: 0), float32 (runtime.update_dtype: auto on a CPU).
    "default": (),
    # The default with the update's forward passes in bf16 autocast (opt-in on a CPU with native bf16).
    "bf16": ("runtime.update_dtype=bfloat16",),
    # The opt-in overlap: the next batch collected in a second thread while this one trains.
    "overlap": ("runtime.update_dtype=float32", "runtime.overlap=true", "runtime.torch_threads=1"),
}


def bench_training(device: torch.device, path: str, total_steps: int, warmup_steps: int = 1000,
                   log_every: int = 1000) -> dict[str, Any]:
    """One quick-preset training end to end by `path` (`TRAINING_PATHS`): env steps and updates per
    second over the loop after its first log point (the warm-up's random steps and the first
    updates' one-off costs excluded), and what the path resolved to."""
    import tempfile
    from pathlib import Path

    from .contracts.runtime_choice import update_dtype, use_overlap
    from .learner import train

    if path not in TRAINING_PATHS:
        raise ValueError(f"path={path!r} is not one of {sorted(TRAINING_PATHS)}")
    job = _compose("experiment=quick", f"device={device}", f"learner.total_steps={total_steps}",
                   f"learner.warmup_steps={warmup_steps}", "eval.val_every=0", "eval.checkpoint=final",
                   f"logging.checkpoint_every={total_steps * 10}", f"logging.log_every={log_every}",
                   *TRAINING_PATHS[path])
    points: list[tuple[float, int, float]] = []  # (time, env steps, updates) at each log point

    def log(metrics: dict[str, float], step: int) -> None:
        points.append((time.perf_counter(), step, metrics["train/updates"]))

    threads = torch.get_num_threads()
    with tempfile.TemporaryDirectory() as tmp:
        train(job, Path(tmp), log)
    torch.set_num_threads(threads)
    # From the first log point after the warm-up to the last: the loop with its updates.
    start = next(k for k, point in enumerate(points) if point[1] > warmup_steps)
    (t0, s0, u0), (t1, s1, u1) = points[start], points[-1]
    return dict(what="training", path=path, device=str(device), n_envs=job.learner.n_envs, camera="front",
                hgm="paper", preset="quick", image=f"{job.observation.height}x{job.observation.width}",
                update_dtype=str(update_dtype(job.runtime.update_dtype, device)).removeprefix("torch."),
                overlap=use_overlap(job.runtime.overlap, device), env_steps=s1 - s0,
                env_steps_per_s=round((s1 - s0) / (t1 - t0), 1), updates_per_s=round((u1 - u0) / (t1 - t0), 1),
                torch_threads=job.runtime.torch_threads)


PRECISIONS = ("float32", "float32+channels_last", "bf16", "bf16+channels_last")


def bench_precision(device: torch.device, preset: str, seconds: float, rounds: int = 3) -> list[dict[str, Any]]:
    """Updates per second of one member's update (`preset`'s network and batch size) in float32 and
    bf16 autocast, each with and without channels_last weights and inputs; the variants take turns
    for `rounds` rounds so that a busy machine slows them alike, and each line gives its median round."""
    # Each variant is the learner's own update, built with its runtime.update_dtype (an autocast around it
    # from here would be switched off by the update's own, which follows that setting).
    jobs = {p: _compose(f"experiment={preset}", f"device={device}",
                        f"runtime.update_dtype={'bfloat16' if p.startswith('bf16') else 'float32'}")
            for p in PRECISIONS}
    job = jobs["float32"]
    batch = _update_batch(job, device, torch.Generator(device=device).manual_seed(0))
    steps = {}
    for precision in PRECISIONS:
        update, net = _member_update(jobs[precision], device)
        if precision.endswith("channels_last"):
            net.to(memory_format=torch.channels_last)
        steps[precision] = update
    rates: dict[str, list[float]] = {p: [] for p in PRECISIONS}
    for _ in range(rounds):
        for precision, update in steps.items():
            channels_last = precision.endswith("channels_last")

            def one_update(update=update, channels_last=channels_last) -> None:
                sample = batch.clone()
                if channels_last:
                    sample = sample.apply(lambda x: x.contiguous(memory_format=torch.channels_last) if x.dim() == 4
                                          else x)
                update(sample)

            calls, elapsed = _timed(one_update, device, seconds / rounds)
            rates[precision].append(calls / elapsed)
    return [dict(what="update precision", device=str(device), n_envs=0, camera="front", hgm="paper", preset=preset,
                 precision=precision, batch_size=job.learner.batch_size,
                 image=f"{job.observation.height}x{job.observation.width}x{job.observation.frame_stack}",
                 env_steps_per_s=None, updates_per_s=round(sorted(r)[len(r) // 2], 1),
                 vs_float32=round(sorted(r)[len(r) // 2] / sorted(rates["float32"])[len(r) // 2], 2))
            for precision, r in rates.items()]


GROUPED_UPDATE_MODES = ("eager", "bf16", "cuda_graph", "compile")


def bench_grouped_update(device: torch.device, seconds: float, members: int, mode: str,
                         preset: str = "paper") -> dict[str, Any]:
    """Updates per second of a training group's learning step: each of `members` networks (`preset`'s
    network and batch size) takes one update on its own sample, as the training loop runs them, one
    member after the other. `mode`: eager, bf16 (forward passes autocast to bf16, as
    runtime.update_dtype=bfloat16), cuda_graph (each member's step captured by tensordict's
    CudaGraphModule, as runtime.cuda_graph) or compile (torch.compile, as runtime.compile)."""
    if mode not in GROUPED_UPDATE_MODES:
        raise ValueError(f"mode={mode!r} is not one of {GROUPED_UPDATE_MODES}")
    if mode in ("bf16", "cuda_graph") and device.type != "cuda":
        raise ValueError(f"mode={mode!r} needs a CUDA device")
    job = _compose(f"experiment={preset}", f"device={device}", f"runtime.compile={mode == 'compile'}",
                   f"runtime.cuda_graph={mode == 'cuda_graph'}",
                   f"runtime.update_dtype={'bfloat16' if mode == 'bf16' else 'float32'}")
    gen = torch.Generator(device=device).manual_seed(0)
    steps = [_member_update(job, device) for _ in range(members)]
    batches = [_update_batch(job, device, gen) for _ in range(members)]

    def round_of_updates() -> None:
        for (update, _), batch in zip(steps, batches, strict=True):
            update(batch.clone())

    start = time.perf_counter()
    round_of_updates()  # the first call compiles or captures
    _sync(device)
    first_s = time.perf_counter() - start
    calls, elapsed = _timed(round_of_updates, device, seconds, warmup=12)
    return dict(what="grouped update", device=str(device), n_envs=0, camera="front", hgm="paper", mode=mode,
                members=members, batch_size=job.learner.batch_size,
                image=f"{job.observation.height}x{job.observation.width}", preset=preset,
                parameters=sum(p.numel() for p in steps[0][1].parameters()), first_call_s=round(first_s, 2),
                env_steps_per_s=None, updates_per_s=round(calls / elapsed, 1),
                member_updates_per_s=round(calls * members / elapsed, 1))


def bench_highway_env(seconds: float, observation: str = "Kinematics") -> dict[str, Any] | None:
    try:
        import gymnasium as gym
        import highway_env  # noqa: F401  (registers highway-v0)
    except ImportError:
        return None
    config = {"lanes_count": 5, "vehicles_count": 50, "duration": 10_000}
    if observation != "Kinematics":
        config["observation"] = {"type": "GrayscaleObservation", "observation_shape": (84, 84),
                                 "stack_size": 4, "weights": [0.2989, 0.5870, 0.1140]}
    env = gym.make("highway-v0", config=config)
    env.reset(seed=0)

    def one_step() -> None:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()

    calls, elapsed = _timed(one_step, torch.device("cpu"), seconds, warmup=2)
    env.close()
    return dict(what="highway-env highway-v0", device="cpu", n_envs=1,
                camera="none" if observation == "Kinematics" else "grayscale84", observation=observation,
                env_steps_per_s=round(calls / elapsed, 1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hgm_repro.bench", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=[*PARTS, "rate", "grouped_update", "training", "precision"],
                        action="append", help="measure only these parts (repeatable); default: all but rate, "
                        "grouped_update, training and precision")
    parser.add_argument("--n-envs", default="1,64,256,1024,4096",
                        help="comma-separated batch sizes for the simulator on CPU (default: %(default)s)")
    parser.add_argument("--cuda-n-envs", default="1024,8192,32768",
                        help="batch sizes for the simulator on CUDA, when a GPU is there (default: %(default)s)")
    parser.add_argument("--obs-n-envs", default=None,
                        help="comma-separated batch sizes for the observation lines (default: 256 on CPU, the "
                             "largest --cuda-n-envs on CUDA)")
    parser.add_argument("--variants", default=",".join(OBS_VARIANTS),
                        help="comma-separated observation variants (default: all, and the proposed one under "
                             "resets; naming them leaves that line out)")
    parser.add_argument("--env-n-envs", type=int, default=256,
                        help="batch size for the TorchRL env and the Gymnasium VectorEnv (%(default)s)")
    parser.add_argument("--seconds", type=float, default=3.0, help="time per measurement (default: %(default)s)")
    parser.add_argument("--train-steps", type=int, default=2048,
                        help="env steps of the end-to-end training measurement (x8 on CUDA) (%(default)s)")
    parser.add_argument("--training-steps", type=int, default=6000,
                        help="env steps of each training line (1,000 of them warm-up) (default: %(default)s)")
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    parser.add_argument("--members", default="1,5",
                        help="training members of the grouped-training lines (default: %(default)s; 15 on a GPU "
                             "is the paper's grid)")
    parser.add_argument("--grouped-steps", type=int, default=None,
                        help="env steps per member of the grouped-training lines (default: --train-steps)")
    parser.add_argument("--preset", default="paper",
                        help="experiment preset of the rate and grouped_update lines (default: %(default)s)")
    parser.add_argument("--rate-members", type=int, default=5,
                        help="members of the rate line: one grouped training, its loop's rate per member and its "
                             "fixed cost, what a training budget is sized from (default: %(default)s)")
    parser.add_argument("--rate-overrides", default="",
                        help="Hydra overrides for the rate line's trainings, space-separated, e.g. "
                             "'runtime.cuda_graph=true' (default: none)")
    parser.add_argument("--rate-steps", type=int, default=4096,
                        help="env steps per member of the rate line (default: %(default)s)")
    parser.add_argument("--update-members", default="15",
                        help="comma-separated member counts of the grouped_update lines (default: %(default)s, "
                             "every seed of the paper's grid)")
    parser.add_argument("--update-modes", default=None,
                        help=f"comma-separated modes of the grouped_update lines, of {', '.join(GROUPED_UPDATE_MODES)} "
                             "(default: all on CUDA, eager on CPU); a mode that fails gives a line with its error")
    parser.add_argument("--device", choices=["cpu", "cuda", "all"], default="all",
                        help="which devices to measure (default: every one present)")
    args = parser.parse_args(argv)
    _quiet_torchrl()
    if args.threads:
        torch.set_num_threads(args.threads)
    parts = set(args.only or PARTS)
    variants = [v for v in args.variants.split(",") if v]
    unknown = sorted(set(variants) - set(OBS_VARIANTS))
    if unknown:
        parser.error(f"--variants: unknown {unknown}; known: {', '.join(OBS_VARIANTS)}")
    devices = []
    if args.device in ("cpu", "all"):
        devices.append(torch.device("cpu"))
    if args.device in ("cuda", "all") and torch.cuda.is_available():
        devices.append(torch.device("cuda"))
    elif args.device == "cuda":
        parser.error("--device cuda asked for, but torch sees no CUDA device")

    def emit(row: dict[str, Any] | None) -> None:
        if row is None:
            return
        row.setdefault("torch_threads", torch.get_num_threads())
        row.setdefault("host", platform.node())
        print(json.dumps(row), flush=True)

    for device in devices:
        gpu = device.type == "cuda"
        sizes = [int(x) for x in (args.cuda_n_envs if gpu else args.n_envs).split(",") if x]
        if "simulator" in parts:
            for n in sizes:
                print(f"simulator n_envs={n} on {device}...", file=sys.stderr)
                emit(bench_simulator(n, device, args.seconds))
        if "observations" in parts:
            obs_sizes = [int(x) for x in args.obs_n_envs.split(",") if x] if args.obs_n_envs else \
                [max(sizes) if gpu else 256]
            for n in obs_sizes:
                for variant in variants:
                    print(f"simulator+{variant} n_envs={n} on {device}...", file=sys.stderr)
                    emit(bench_observations(variant, n, device, args.seconds))
            if len(variants) == len(OBS_VARIANTS):
                n = max(obs_sizes)
                print(f"simulator+proposed under resets n_envs={n} on {device}...", file=sys.stderr)
                emit(bench_observations_under_resets("proposed", n, device, args.seconds))
        if "envs" in parts:
            print(f"torchrl env and gymnasium vector env n_envs={args.env_n_envs} on {device}...", file=sys.stderr)
            for row in bench_envs(args.env_n_envs, device, 2 * args.seconds):
                emit(row)
        if "learner" in parts:
            modes = ["eager", "compile", "cuda_graph"] if gpu else ["eager"]
            for mode in modes:
                print(f"learner update ({mode}) on {device}...", file=sys.stderr)
                emit(bench_learner_updates(device, args.seconds, mode=mode))
            print(f"learner training on {device}...", file=sys.stderr)
            emit(bench_learner_training(device, total_steps=args.train_steps * (8 if gpu else 1)))
        if "grouped" in parts:
            cores = torch.get_num_threads()
            steps = (args.grouped_steps or args.train_steps) * (8 if gpu else 1)
            # The acceptance line: one member alone on one thread, the baseline the rest compare to.
            print(f"learner training, one member solo on one thread, on {device}...", file=sys.stderr)
            alone = bench_grouped_training(device, steps, 1, "sequential", threads=1)
            emit(alone)
            for members in [int(x) for x in args.members.split(",") if x]:
                # Solo jobs side by side compete for the cores only on a CPU; on a GPU they would
                # share one device, which the grouped path exists to do better.
                paths = ("sequential", "grouped", *(("parallel",) if not gpu and members > 1 and cores > 1 else ()))
                for path in paths:
                    print(f"learner training, {members} members {path} on {device}...", file=sys.stderr)
                    row = bench_grouped_training(device, steps, members, path, threads=cores)
                    row["vs_one_member_one_thread"] = round(row["env_steps_per_s"] / alone["env_steps_per_s"], 3)
                    emit(row)
        if "training" in parts:
            # One run, the paths in turn, twice: a busy machine slows both alike.
            for _ in range(2):
                for path in TRAINING_PATHS:
                    if path == "bf16" and not bf16_supported(device):
                        continue  # refused where the device has no native bf16
                    print(f"training, quick preset, {path} path, on {device}...", file=sys.stderr)
                    emit(bench_training(device, path, total_steps=args.training_steps))
        if "precision" in parts:
            for preset in ("paper", "quick"):
                print(f"update precision, {preset} preset's network, on {device}...", file=sys.stderr)
                for row in bench_precision(device, preset, 4 * args.seconds):
                    emit(row)
        if "rate" in parts:
            # Warm-up of one batch per member: the line measures the loop with its updates, as most of a
            # longer training runs (the warm-up's random steps are faster, so a budget from it is safe);
            # the rate is the second half's, after the first updates' one-off costs.
            members = args.rate_members
            print(f"training rate: {members} members grouped, {args.preset} preset, on {device}...", file=sys.stderr)
            emit(bench_grouped_training(device, args.rate_steps, members, "grouped", threads=torch.get_num_threads(),
                                        preset=args.preset, log_every=max(1, args.rate_steps // 2),
                                        warmup_steps=_compose(f"experiment={args.preset}").learner.batch_size,
                                        overrides=tuple(args.rate_overrides.split())))
        if "grouped_update" in parts:
            modes = args.update_modes.split(",") if args.update_modes else \
                (list(GROUPED_UPDATE_MODES) if gpu else ["eager"])
            for members in [int(x) for x in args.update_members.split(",") if x]:
                for mode in modes:
                    print(f"grouped update, {members} members, {mode}, on {device}...", file=sys.stderr)
                    try:
                        emit(bench_grouped_update(device, args.seconds, members, mode, args.preset))
                    except Exception as error:  # one mode failing must not cost the lines after it
                        emit(dict(what="grouped update", device=str(device), n_envs=0, camera="front", hgm="paper",
                                  mode=mode, members=members, preset=args.preset, env_steps_per_s=None,
                                  error=f"{type(error).__name__}: {str(error)[:300]}"))
    if "highway" in parts:
        for observation in ("Kinematics", "Grayscale"):
            print(f"highway-env ({observation})...", file=sys.stderr)
            row = bench_highway_env(args.seconds, observation)
            if row is None:
                print("highway-env not installed: pip install -e '.[highway]' to compare", file=sys.stderr)
                break
            emit(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
