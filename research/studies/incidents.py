"""Why does a host crash? Drive a host policy and classify every collision and dangerous action.

Collision kinds (from the state just before the decision in which the crash happened, because a
crashed vehicle is respawned within that decision):
- `host_into_leader`: the partner was ahead of the host and neither was changing lanes;
- `follower_into_host`: the partner was behind the host and neither was changing lanes;
- `host_lane_change`: the host was changing lanes (or started to in that decision);
- `other_lane_change`: the partner was changing lanes into or out of the host's lane.
It also records whether the host could still brake (speed above v_min), its last action, and
what its sensors could show of the partner: connected (in the HGM) and wholly ahead of the host
(in the front camera).

Dangerous-action kinds follow the simulator's rule (Algorithm 2 reading in paper-notes):
`off_road` (a lane change off the road), `cut_in` (a lane change leaving the new follower under
the time gap), `tailgating` (under the time gap to the vehicle ahead after the decision).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import pandas as pd
import torch

from hgm_repro.simulator import HOST, Action, HighwaySimulator

COLLISION_KINDS = ("host_into_leader", "follower_into_host", "host_lane_change", "other_lane_change")
DANGER_KINDS = ("tailgating", "cut_in", "off_road")


@dataclass
class Snapshot:
    """The few pre-decision tensors the classification needs (cloned: the simulator mutates)."""

    pos_lon: torch.Tensor
    pos_lat: torch.Tensor
    speed: torch.Tensor
    target_lane: torch.Tensor
    active: torch.Tensor
    vtype: torch.Tensor

    @classmethod
    def of(cls, sim: HighwaySimulator) -> Snapshot:
        s = sim.state
        return cls(s.pos_lon.clone(), s.pos_lat.clone(), s.speed.clone(), s.target_lane.clone(), s.active.clone(),
                   s.vtype.clone())


def _changing(sim: HighwaySimulator, snap: Snapshot) -> torch.Tensor:
    return (snap.pos_lat - sim.lane_centres[snap.target_lane]).abs() > 1e-4


def classify_collisions(sim: HighwaySimulator, before: Snapshot, action: torch.Tensor, collided: torch.Tensor
                        ) -> pd.DataFrame:
    """One row per env in `collided`: kind, partner speed and gap before, host speed and action."""
    rows = torch.nonzero(collided).squeeze(1)
    if rows.numel() == 0:
        return pd.DataFrame(columns=["kind", "host_speed_kmh", "partner_speed_kmh", "gap_m", "host_action",
                                     "host_at_v_min", "partner_connected", "partner_in_camera"])
    half_len = sim.half_len_by_type[before.vtype]
    half_wid = sim.half_wid_by_type[before.vtype]
    dlon = before.pos_lon - before.pos_lon[:, HOST:HOST + 1]
    # Lateral reach of the host over the decision: its body now and at its target lane's centre.
    host_lat = torch.stack([before.pos_lat[:, HOST], sim.lane_centres[before.target_lane[:, HOST]]], 1)
    lat_lo = host_lat.amin(1, keepdim=True) - half_wid[:, HOST:HOST + 1]
    lat_hi = host_lat.amax(1, keepdim=True) + half_wid[:, HOST:HOST + 1]
    other_lat = torch.stack([before.pos_lat, sim.lane_centres[before.target_lane]], -1)
    overlaps = (other_lat.amax(-1) + half_wid > lat_lo) & (other_lat.amin(-1) - half_wid < lat_hi)
    gap = dlon.abs() - half_len - half_len[:, HOST:HOST + 1]
    candidate = before.active & overlaps
    candidate[:, HOST] = False
    partner = torch.where(candidate, gap, torch.inf).argmin(1)
    changing = _changing(sim, before)
    host_starts = (action == int(Action.LANE_LEFT)) | (action == int(Action.LANE_RIGHT))
    out = []
    for r in rows.tolist():
        j = int(partner[r])
        if bool(changing[r, HOST]) or bool(host_starts[r]):
            kind = "host_lane_change"
        elif bool(changing[r, j]):
            kind = "other_lane_change"
        elif float(dlon[r, j]) > 0:
            kind = "host_into_leader"
        else:
            kind = "follower_into_host"
        v_host = float(before.speed[r, HOST])
        out.append({"kind": kind, "host_speed_kmh": v_host * 3.6, "partner_speed_kmh": float(before.speed[r, j]) * 3.6,
                    "gap_m": float(gap[r, j]), "host_action": Action(int(action[r])).name,
                    "host_at_v_min": v_host <= sim.config.v_min + 1e-3,
                    # What the host's sensors could show of the partner a decision before: the HGM
                    # only connected vehicles, the front camera only vehicles wholly ahead of it.
                    "partner_connected": bool(sim.connected_by_type[before.vtype[r, j]]),
                    "partner_in_camera": float(dlon[r, j] - half_len[r, j] - half_len[r, HOST]) > 0})
    return pd.DataFrame(out)


def classify_dangerous(sim: HighwaySimulator, action: torch.Tensor, lane_change_started: torch.Tensor,
                       dangerous: torch.Tensor, before: Snapshot) -> dict[str, int]:
    """Counts of the kinds of this decision's dangerous actions (an action may be of one kind only:
    off-road first, then a cut-in, else tailgating, the order in which the rule checks them)."""
    lane = before.target_lane[:, HOST]
    wants_left = action == int(Action.LANE_LEFT)
    wants_right = action == int(Action.LANE_RIGHT)
    off_road = (wants_left & (lane == 0)) | (wants_right & (lane == sim.config.lanes - 1))
    kinds = {"off_road": dangerous & off_road, "cut_in": dangerous & ~off_road & lane_change_started}
    kinds["tailgating"] = dangerous & ~kinds["off_road"] & ~kinds["cut_in"]
    return {k: int(v.sum()) for k, v in kinds.items()}


Policy = Callable[[], torch.Tensor]


def drive_and_classify(sim: HighwaySimulator, act: Policy, decisions: int,
                       after_step: Callable[[torch.Tensor], None] | None = None
                       ) -> tuple[pd.DataFrame, dict[str, float]]:
    """Drive `decisions` decisions in every env with `act()` (reads the simulator, returns [N]
    actions); finished episodes restart, then `after_step(done)` runs (a learned policy updates
    its observations there). Returns the collision rows and per-episode rates of every
    collision and dangerous-action kind (events per decision x decisions per episode)."""
    collisions: list[pd.DataFrame] = []
    danger = dict.fromkeys(DANGER_KINDS, 0)
    speed_sum = 0.0
    returns: list[float] = []  # of the episodes that ended (a crash or the time limit)
    for _ in range(decisions):
        action = act()
        before = Snapshot.of(sim)
        result = sim.step(action)
        speed_sum += float(sim.state.speed[:, HOST].sum())
        if bool(result.collision.any()):
            collisions.append(classify_collisions(sim, before, action, result.collision))
        if bool(result.dangerous.any()):
            for k, v in classify_dangerous(sim, action, result.lane_change, result.dangerous, before).items():
                danger[k] += v
        if bool(result.done.any()):
            returns.extend(result.episode["episode_return"][result.done].tolist())
            sim.reset(result.done)
        if after_step is not None:
            after_step(result.done)
    table = pd.concat(collisions, ignore_index=True) if collisions else classify_collisions(
        sim, Snapshot.of(sim), torch.zeros(sim.n_envs, dtype=torch.long), torch.zeros(sim.n_envs, dtype=torch.bool))
    per_episode = sim.config.episode_decisions / (decisions * sim.n_envs)
    rates = {f"collision/{k}": float((table["kind"] == k).sum()) * per_episode for k in COLLISION_KINDS}
    rates.update({f"dangerous/{k}": v * per_episode for k, v in danger.items()})
    rates["collisions"] = len(table) * per_episode
    rates["avg_speed_kmh"] = speed_sum / (decisions * sim.n_envs) * 3.6
    rates["episode_return"] = sum(returns) / max(len(returns), 1)
    rates["episodes_ended"] = len(returns)
    return table, rates
