"""How much memory a replay memory of N transitions takes at a preset, flat or frame-indexed.

    python research/studies/replay_memory_size.py [--transitions 320000] [--overrides experiment=quick model=proposed]

Fills both memories with a few hundred real transitions of the preset's env, reads the bytes one
stored transition takes, and scales to N (the frame rings are sized for N as training sizes them).
"""

from __future__ import annotations

import argparse
import json

import torch
from hydra import compose, initialize_config_dir

from hgm_repro.contracts.conf_dir import CONF_DIR
from hgm_repro.contracts.schema import check_config
from hgm_repro.envs import make_env
from hgm_repro.learner.builders import make_replay_buffer
from hgm_repro.learner.frame_replay import FrameReplay
from hgm_repro.learner.n_step import NStepReturns

NOT_TRANSITION = ("episode", "reward_terms", ("next", "episode"), ("next", "reward_terms"))


def sizes(transitions: int, overrides: list[str]) -> dict[str, float]:
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        job = check_config(compose("config", overrides=[*overrides, f"learner.buffer_size={transitions}"]))
    n_envs = job.learner.n_envs
    env = make_env(job, job.train_scenario, n_envs=n_envs, seed=0)
    flat_buffer = make_replay_buffer(job.learner, torch.device("cpu"))
    framed = FrameReplay.for_env(make_replay_buffer(job.learner, torch.device("cpu")), env, job.learner.n_step)
    flat_steps, frame_steps = NStepReturns(job.learner.n_step, 0.99), NStepReturns(job.learner.n_step, 0.99)
    td = env.reset()
    for _ in range(20):
        td["action"] = env.action_spec.rand()
        td = env.step(td)
        step = td.exclude(*NOT_TRANSITION).unsqueeze(1)
        full, slim = flat_steps(step.clone()), frame_steps(framed.observe(step))
        if full is not None and full.numel():
            flat_buffer.extend(full.reshape(-1))
            framed.extend(slim.reshape(-1))
        td = env.step_mdp(td)
    mib = 2**20
    flat_one = flat_buffer.storage[0].bytes()
    record_one = framed.buffer.storage[0].bytes()
    rings = sum(t.numel() * t.element_size() for t in framed.frames.values())
    return {"transitions": transitions, "flat_MiB": round(flat_one * transitions / mib),
            "frames_MiB": round((rings + record_one * transitions) / mib),
            "flat_bytes_per_transition": flat_one, "frame_record_bytes": record_one,
            "frame_ring_MiB": round(rings / mib)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--transitions", type=int, default=320_000)
    p.add_argument("--overrides", nargs="*", default=["experiment=quick", "model=proposed"])
    a = p.parse_args()
    print(json.dumps(sizes(a.transitions, a.overrides)))


if __name__ == "__main__":
    main()
