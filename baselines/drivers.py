"""Hosts that do not learn: the paper's non-intelligent (human-driven) host, a rule-based
IDM + MOBIL host the paper lacks, and a uniformly random host as the floor.

Each driver has `.safety_layer` (whether the simulator's NPC safety layer and gap acceptance
also guard the host: set it on the simulator with `hgm_repro.simulator.driver.attach`) and `.act(sim) -> LongTensor[N]`,
one `Action` per env, computed for all envs at once. They are built by Hydra from the
`driver` node of conf/model/{human,idm_mobil,random}.yaml, so they take keyword arguments only.
"""

from __future__ import annotations

import dataclasses

import torch

from hgm_repro.simulator.driver import Driver, attach
from hgm_repro.simulator.highway import HighwaySimulator
from hgm_repro.simulator.neighbours import gather_vehicles
from hgm_repro.simulator.state import HOST, N_ACTIONS, Action

INF = float("inf")


class HumanDriver:
    """The non-intelligent host: random actions at the rates of a human type of Table 1.

    The host's own type (HV) has r_lon = r_lat = 0, so the rates come from `type_name`; the
    draw is the simulator's own NPC rule, so this host behaves as that type's NPCs do."""

    def __init__(self, *, type_name: str = "CHV", safety_layer: bool = True):
        self.type_name = type_name
        self.safety_layer = safety_layer

    def act(self, sim: HighwaySimulator) -> torch.Tensor:
        s = sim.state
        as_human = dataclasses.replace(s, vtype=torch.full_like(s.vtype, sim.config.type_index(self.type_name)))
        return sim.npc_actions(as_human)[:, HOST]


class RandomDriver:
    """Each of the five actions with equal probability, unguarded."""

    def __init__(self, *, safety_layer: bool = False):
        self.safety_layer = safety_layer

    def act(self, sim: HighwaySimulator) -> torch.Tensor:
        return torch.randint(0, N_ACTIONS, (sim.n_envs,), generator=sim.generator, device=sim.device)


class IdmMobilDriver:
    """IDM car following and MOBIL lane changes (Treiber, Kesting), read onto the five actions.

    IDM gives the acceleration the host would like; above `accel_threshold` the host accelerates,
    below its negative it decelerates, otherwise it holds its speed. MOBIL changes lane when the
    host's gain plus `politeness` times the followers' gains beats `change_threshold`, and the new
    follower would not have to brake harder than `safe_decel`. With `lane_changes=False` it only
    follows (IDM in its lane). All parameters are SI units."""

    def __init__(self, *, desired_speed: float | None = None, time_headway: float = 1.5, min_gap: float = 2.0,
                 comfortable_decel: float = 2.0, delta: float = 4.0, accel_threshold: float = 0.3,
                 politeness: float = 0.2, change_threshold: float = 0.2, safe_decel: float = 4.0,
                 safety_layer: bool = True, lane_changes: bool = True):
        self.desired_speed = desired_speed  # None: the simulator's v_max
        self.time_headway = time_headway
        self.min_gap = min_gap
        self.comfortable_decel = comfortable_decel
        self.delta = delta
        self.accel_threshold = accel_threshold
        self.politeness = politeness
        self.change_threshold = change_threshold
        self.safe_decel = safe_decel
        self.safety_layer = safety_layer
        self.lane_changes = lane_changes

    def idm(self, speed: torch.Tensor, lead_speed: torch.Tensor, gap: torch.Tensor, a_max: torch.Tensor,
            v0: float) -> torch.Tensor:
        """IDM acceleration for a gap (bumper to bumper, m) to a leader; gap = inf means no leader."""
        b = self.comfortable_decel
        dynamic = speed * self.time_headway + speed * (speed - lead_speed) / (2 * torch.sqrt(a_max * b))
        s_star = self.min_gap + dynamic.clamp(min=0)
        interaction = torch.where(torch.isfinite(gap), (s_star / gap.clamp(min=0.1)) ** 2, 0.0)
        return a_max * (1 - (speed / v0).clamp(min=0) ** self.delta - interaction)

    def act(self, sim: HighwaySimulator) -> torch.Tensor:
        s, cfg = sim.state, sim.config
        n, d = s.n_envs, sim.device
        v0 = cfg.v_max if self.desired_speed is None else self.desired_speed
        nb = sim.neighbours()
        half_len, a_lon = sim.half_len_by_type[s.vtype], sim.a_lon_by_type[s.vtype]
        rows = torch.arange(n, device=d)

        def gap(back: torch.Tensor, front: torch.Tensor) -> torch.Tensor:
            # Bumper-to-bumper gap between vehicle indices (NONE on either side gives inf).
            g = gather_vehicles(s.pos_lon, front, INF) - gather_vehicles(half_len, front, 0.0) \
                - gather_vehicles(s.pos_lon, back, -INF) - gather_vehicles(half_len, back, 0.0)
            return torch.where((front >= 0) & (back >= 0), g, INF)

        def idm_of(back: torch.Tensor, front: torch.Tensor) -> torch.Tensor:
            # Acceleration IDM gives vehicle `back` behind `front`; 0 where `back` does not exist.
            v = gather_vehicles(s.speed, back, 0.0)
            acc = self.idm(v, gather_vehicles(s.speed, front, 0.0), gap(back, front),
                           gather_vehicles(a_lon, back, 1.0), v0)
            return torch.where(back >= 0, acc, 0.0)

        host = torch.full_like(rows, HOST)
        lead, follow = nb.lead[:, HOST, :], nb.follow[:, HOST, :]  # [N, lanes]
        # Now: the host follows the nearest leader of every lane its body or lane change covers.
        per_lane = idm_of(host.unsqueeze(1).expand_as(lead), lead)
        accel_now = torch.where(nb.occupancy[:, HOST, :], per_lane, INF).amin(1)

        lane = s.target_lane[:, HOST]
        changing = (s.pos_lat[:, HOST] - sim.lane_centres[lane]).abs() > 1e-4
        old_lead = lead.gather(1, lane[:, None]).squeeze(1)
        old_follow = follow.gather(1, lane[:, None]).squeeze(1)
        # The old follower loses the host in front of it and follows the host's leader instead.
        old_follow_gain = idm_of(old_follow, old_lead) - idm_of(old_follow, host)

        best_gain = torch.full((n,), -INF, device=d)
        best_action = torch.full((n,), int(Action.NO_ACTION), device=d, dtype=torch.long)
        # A lane keeper (lane_changes=False) skips MOBIL's evaluation altogether.
        for step, action in ((-1, Action.LANE_LEFT), (1, Action.LANE_RIGHT)) if self.lane_changes else ():
            target = lane + step
            exists = (target >= 0) & (target < cfg.lanes)
            t = target.clamp(0, cfg.lanes - 1)[:, None]
            new_lead, new_follow = lead.gather(1, t).squeeze(1), follow.gather(1, t).squeeze(1)
            accel_there = idm_of(host, new_lead)
            new_follow_after = idm_of(new_follow, host)
            new_follow_gain = new_follow_after - idm_of(new_follow, new_lead)
            gain = accel_there - accel_now + self.politeness * (new_follow_gain + old_follow_gain)
            safe = (new_follow_after >= -self.safe_decel) & (accel_there >= -self.safe_decel)
            ok = exists & ~changing & safe & (gain > self.change_threshold) & (gain > best_gain)
            best_gain = torch.where(ok, gain, best_gain)
            best_action = torch.where(ok, int(action), best_action)

        longitudinal = torch.full((n,), int(Action.NO_ACTION), device=d, dtype=torch.long)
        longitudinal = torch.where(accel_now > self.accel_threshold, int(Action.ACCELERATE), longitudinal)
        longitudinal = torch.where(accel_now < -self.accel_threshold, int(Action.DECELERATE), longitudinal)
        return torch.where(best_action != int(Action.NO_ACTION), best_action, longitudinal)


def drive(sim: HighwaySimulator, driver: Driver, decisions: int) -> dict[str, float]:
    """Run `driver` for `decisions` decisions in every env of `sim` (restarting finished episodes)
    and summarise. Counts are per episode length of driving (events per decision times the
    configured decisions per episode), so episodes cut short by a crash do not hide events."""
    attach(driver, sim)
    sim.reset()
    speed_sum = torch.zeros((), device=sim.device)
    totals = {"collisions": 0.0, "lane_changes": 0.0, "overtakes": 0.0, "dangerous_actions": 0.0}
    for _ in range(decisions):
        result = sim.step(driver.act(sim))
        speed_sum = speed_sum + sim.state.speed[:, HOST].sum()
        totals["collisions"] += float(result.collision.sum())
        totals["lane_changes"] += float(result.lane_change.sum())
        totals["overtakes"] += float(result.overtakes.sum())
        totals["dangerous_actions"] += float(result.dangerous.sum())
        if bool(result.done.any()):
            sim.reset(result.done)
    env_decisions = decisions * sim.n_envs
    per_episode = sim.config.episode_decisions / env_decisions
    out = {"avg_speed_kmh": float(speed_sum) / env_decisions * 3.6}
    out.update({f"{k}_per_episode": v * per_episode for k, v in totals.items()})
    return out
