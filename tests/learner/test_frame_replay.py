"""The frame-indexed replay memory rebuilds exactly the stacks the env built, across resets,
time-ups and crashes, and trains exactly as the flat memory does."""

from __future__ import annotations

import pytest
import torch
from torchrl.collectors import Collector

from hgm_repro.contracts.checkpoint import load_checkpoint
from hgm_repro.envs import make_env
from hgm_repro.learner import train
from hgm_repro.learner.builders import make_replay_buffer
from hgm_repro.learner.frame_replay import FrameReplay
from hgm_repro.learner.n_step import NStepReturns
from hgm_repro.simulator import N_ACTIONS, Action
from tests.helpers.learner import Recorder, compose_job

NOT_TRANSITION = ("episode", "reward_terms", ("next", "episode"), ("next", "reward_terms"), "collector")


def _policy(td):
    """Mostly accelerate (crashes), sometimes change lanes (lane changes into traffic, more crashes)."""
    n = td.batch_size[0]
    choice = torch.where(torch.rand(n) < 0.8, int(Action.ACCELERATE), int(Action.LANE_LEFT))
    td.set("action", torch.nn.functional.one_hot(choice, N_ACTIONS).bool())
    return td


@pytest.mark.parametrize("model, n_step, frames", [
    ("proposed", 3, 2),
    pytest.param("coordinate", 1, 3, marks=pytest.mark.slow),
    pytest.param("min", 4, 4, marks=pytest.mark.slow),
])
def test_rebuilt_stacks_equal_the_envs_across_resets_time_ups_and_crashes(model, n_step, frames):
    # 12-decision episodes in dense traffic: time-ups and crashes both happen many times over.
    job = compose_job(f"model={model}", "simulator.episode_seconds=6", "scenario='3'", f"learner.n_step={n_step}",
                      f"observation.frame_stack={frames}", "learner.buffer_size=600")
    n_envs = 6
    env = make_env(job, job.scenario, n_envs=n_envs, seed=1)
    torch.manual_seed(0)
    collector = Collector(env, _policy, frames_per_batch=n_envs, total_frames=n_envs * 70)
    flat, indexed = NStepReturns(n_step, 0.99), NStepReturns(n_step, 0.99)
    memory = FrameReplay.for_env(make_replay_buffer(job.learner, torch.device("cpu")), env, n_step)
    originals = []
    for batch in collector:
        steps = batch.reshape(n_envs, -1).exclude(*NOT_TRANSITION)
        full = flat(steps.clone())
        slim = indexed(memory.observe(steps))
        if full is not None and full.numel():
            originals.append(full.reshape(-1))
            memory.extend(slim.reshape(-1))
    collector.shutdown()
    original = torch.cat(originals)
    stored = memory.buffer.storage[: len(memory)]
    assert len(original) == len(stored) <= 600
    crashed = original["next", "terminated"].reshape(-1)
    timed_out = original["next", "truncated"].reshape(-1)
    assert int(crashed.sum()) >= 5 and int(timed_out.sum()) >= 5
    env_, pos, start = stored["frame_env"], stored["frame_pos"], stored["episode_start"]
    steps_ahead = stored.get("steps_to_next_obs", None)
    steps_ahead = torch.ones_like(pos) if steps_ahead is None else steps_ahead.reshape(-1).long()
    for key in memory.keys:
        assert torch.equal(memory.stack(key, env_, pos, start), original[key])
        rebuilt_next = memory.stack(key, env_, pos + steps_ahead - crashed.long(), start)
        # A crash's next observation is never read by the target; every other one is the env's.
        assert torch.equal(rebuilt_next[~crashed], original["next", key][~crashed])
    # And the sampler puts the same stacks where the loss reads them.
    sample = memory.sample()
    index = sample["index"]
    for key in memory.keys:
        assert torch.equal(sample[key], original[key][index])


def test_frame_memory_trains_exactly_as_the_flat_one(tmp_path):
    overrides = ("model=proposed", "learner.n_step=3", "learner.double_dqn=true")
    flat_job, frame_job = compose_job(*overrides), compose_job(*overrides, "runtime.replay_frames=true")
    flat = load_checkpoint(train(flat_job, tmp_path / "flat", Recorder()), flat_job)
    framed = load_checkpoint(train(frame_job, tmp_path / "frames", Recorder()), frame_job)
    assert flat["updates"] == framed["updates"] > 0
    for name, weights in flat["network"].items():
        assert torch.equal(weights, framed["network"][name]), name
    assert framed["replay_buffer"]["frames"]  # the smoke memory is small enough to be kept


def test_frame_memory_resumes_after_a_kill(tmp_path):
    job = compose_job("model=proposed", "learner.n_step=3", "runtime.replay_frames=true")
    with pytest.raises(KeyboardInterrupt):
        train(job, tmp_path, Recorder(stop_at=96))
    last = load_checkpoint(tmp_path / "last.pt", job)
    assert last["env_steps"] == 64 and last["replay_buffer"] is not None
    state = load_checkpoint(train(job, tmp_path, Recorder()), job)
    assert state["finished"] and state["env_steps"] == 128 and state["updates"] > last["updates"]
