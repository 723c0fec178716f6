"""When the seeds of one model train together in one process (`runtime.grouped`), and which jobs may.

The loop itself is `loop.py`'s, the same for one member or many: grouping changes how many seeds
share one simulator, one process and one Collector, never what a member's training is (its
train_key, checkpoint format, resume and logs are a solo run's).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from ..contracts.schema import JobConfig
from ..contracts.train_key import training_config


def use_grouped(setting: str | bool, device: str) -> bool:
    """`runtime.grouped`: true / false force it; auto groups on CUDA only. On the 2-core CPU a group
    gave no gain per member (one thread: 43 member-updates/s alone, 44 in a group of 5), while on a
    GPU one small batch of envs and one small update leave most of the chip idle."""
    if setting == "auto":
        return torch.device(device).type == "cuda"
    if isinstance(setting, bool):
        return setting
    raise ValueError(f"runtime.grouped={setting!r} is not allowed: use auto, true or false")


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
    seeds = [job.seed for job in jobs]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"members of a training group need distinct seeds; got seeds {seeds}")
