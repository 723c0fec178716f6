"""Grouped training (`hgm_repro.learner.grouped`): members' traffic, update and results."""

from __future__ import annotations

import pytest
import torch

from hgm_repro.simulator import HighwaySimulator
from hgm_repro.simulator.loading import scenario_config, simulator_config


def _trajectory(seeds: list[int], member_envs: int, steps: int, scenario: str = "train") -> list[torch.Tensor]:
    """Per step, the whole state flattened (positions, speeds, types, colours, activity) under a
    fixed action pattern that is the same in every member's block of envs."""
    cfg = simulator_config()
    sim = HighwaySimulator(cfg, scenario_config(scenario, cfg), member_envs * len(seeds), seed=seeds)
    actions = torch.arange(member_envs) % 5
    out = []
    for t in range(steps):
        result = sim.step(((actions + t) % 5).repeat(len(seeds)))
        if bool(result.done.any()):
            sim.reset(result.done)
        s = sim.state
        out.append(torch.cat([s.pos_lon, s.speed, s.vtype.float(), s.active.float(),
                              s.color.float().flatten(1)], 1))
    return out


@pytest.mark.parametrize("scenario", ["train", "5"])
def test_member_traffic_is_the_same_alone_and_in_a_group(scenario: str):
    steps, envs = 60, 3
    alone = _trajectory([7], envs, steps, scenario)
    group = _trajectory([3, 7, 11], envs, steps, scenario)
    for t in range(steps):
        torch.testing.assert_close(group[t][envs:2 * envs], alone[t], rtol=0, atol=0)
    # and the members do not share traffic
    assert not torch.equal(group[-1][:envs], group[-1][envs:2 * envs])


def test_group_of_seeds_needs_whole_blocks():
    cfg = simulator_config()
    with pytest.raises(ValueError, match=r"seed=\[1, 2\] is not allowed with n_envs=3"):
        HighwaySimulator(cfg, scenario_config("train", cfg), 3, seed=[1, 2])
