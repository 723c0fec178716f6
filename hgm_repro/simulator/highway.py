"""The batched heterogeneous-traffic highway: one `step` advances every env by one decision.

No Python loop runs over vehicles or envs; the only loop is over the physics sub-steps of a
decision (5 by default). Works on any torch device: keep the state and the actions there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from ..contracts import events
from ..contracts.simulator_config import HOST_TYPE, ScenarioConfig, SimulatorConfig
from .neighbours import Neighbours, gather_vehicles, lane_occupancy, nearest_per_lane
from .randomness import TrafficRandomness
from .reward import RewardTerms, speed_reward
from .state import HOST, Action, TrafficState

INF = float("inf")
# Vehicles come back in a band this long (m) at each edge of the window, and leave only once
# past it: spawning at one exact point would jam whenever every lane has a car there.
SPAWN_ZONE = 20.0


@dataclass
class StepResult:
    """What one decision produced, per env ([N] tensors)."""

    reward: torch.Tensor
    terms: RewardTerms
    terminated: torch.Tensor  # host collision
    truncated: torch.Tensor  # episode time is up
    lane_change: torch.Tensor  # the host started a lane change
    overtakes: torch.Tensor  # vehicles overtaken by the host in this decision
    dangerous: torch.Tensor
    collision: torch.Tensor
    episode: dict[str, torch.Tensor]  # per-episode metrics, valid where terminated | truncated

    @property
    def done(self) -> torch.Tensor:
        return self.terminated | self.truncated


def episode_metrics(state: TrafficState) -> dict[str, torch.Tensor]:
    """The `hgm_repro.contracts.names.EPISODE_METRICS` of every env's episode so far, [N] each, from its accumulators
    (what `StepResult.episode` reports where an episode ends)."""
    decisions = state.decision.float()
    metrics = {
        "avg_speed_kmh": state.ep_speed_sum / decisions.clamp(min=1) * 3.6,
        "lane_changes": state.ep_lane_changes,
        "overtakes": state.ep_overtakes,
        "collisions": state.ep_collisions,
        "dangerous_actions": state.ep_dangerous,
        "distance_m": state.ep_distance,
        "episode_return": state.ep_return,
        "decisions": decisions,
        # The `contracts.events` records. The age counts from the episode's start when the host began no
        # lane change (ep_last_lane_change = -1).
        events.LANE_CHANGE_AGE: decisions - 1 - state.ep_last_lane_change,
        events.LANE_CHANGE_REQUESTS: state.ep_lane_change_requests,
        events.REFUSED_BY_GAP: state.ep_refused_gap,
        events.REFUSED_BY_PARITY: state.ep_refused_parity,
        events.CRASH_INTO_LEADER: state.ep_crash_into_leader,
        events.CRASH_FROM_BEHIND: state.ep_crash_from_behind,
        events.CRASH_PARTNER_CHANGING: state.ep_crash_partner_changing,
        events.CRASH_HOST_CHANGING: state.ep_crash_host_changing,
    }
    return metrics


class HighwaySimulator:
    """Holds the parameters, the random draws and the state of `n_envs` envs.

    `seed` is one seed, or one seed per training member of a group (`hgm_repro.learner.grouped`);
    `randomness.py` keeps each member's traffic its own, and the physics here draws for the whole batch.
    """

    def __init__(self, config: SimulatorConfig, scenario: ScenarioConfig, n_envs: int,
                 device: torch.device | str = "cpu", seed: int | Sequence[int] = 0):
        if not isinstance(n_envs, int) or n_envs < 1:
            raise ValueError(f"n_envs={n_envs!r} is not allowed: need a whole number >= 1")
        self.config = config
        self.scenario = scenario
        self.n_envs = n_envs
        self.device = torch.device(device)
        self.randomness = TrafficRandomness(seed, n_envs, self.device)
        self.host_safety_layer = config.host_safety_layer
        # Switched off only to script situations by hand (tests, figures): vehicles that leave the
        # window or crash then stay away instead of coming back at the far edge.
        self.respawn = True
        self._build_type_tables()
        self.state = self._initial_state(torch.ones(n_envs, dtype=torch.bool, device=self.device), None)

    # ----------------------------------------------------------------------------------- setup
    def _build_type_tables(self) -> None:
        c, d = self.config, self.device
        types = c.vehicle_types

        def table(attr: str) -> torch.Tensor:
            return torch.tensor([float(getattr(t, attr)) for t in types], device=d)

        self.a_lon_by_type = table("a_lon")
        self.v_lat_by_type = table("v_lat")
        self.r_lon_by_type = table("r_lon")
        self.r_lat_by_type = table("r_lat")
        self.half_len_by_type = table("length") / 2
        self.half_wid_by_type = table("width") / 2
        self.gap_time_by_type = table("lane_change_time_gap")
        self.connected_by_type = torch.tensor([t.connected for t in types], device=d)
        # The largest collision box, as Python floats read once: drawing sizes its patches by it.
        self.max_half_len = float(self.half_len_by_type.max())
        self.max_half_wid = float(self.half_wid_by_type.max())
        probs = torch.tensor([self.scenario.ratio_of(t.name) if t.name != HOST_TYPE else 0.0 for t in types],
                             device=d)
        self.spawn_probs = probs / probs.sum()
        self.spawn_cdf = self.spawn_probs.cumsum(0)
        self.spawn_cdf[-1] = 1.0  # guard against rounding: every u in [0, 1) finds a type
        self.lane_centres = (torch.arange(c.lanes, device=d, dtype=torch.float32) + 0.5) * c.lane_width

    @property
    def generator(self) -> torch.Generator:
        """A solo simulator's one generator: what seeding a batch of envs (evaluation, Gymnasium) sets."""
        return self.randomness.generator

    def _types(self, u: torch.Tensor) -> torch.Tensor:
        """Vehicle types in the scenario's mix from uniform draws `u`, by inverse CDF (much cheaper than
        torch.multinomial for many small draws)."""
        return torch.searchsorted(self.spawn_cdf, u.reshape(-1), right=True).clamp(max=len(self.spawn_cdf) - 1) \
            .reshape(u.shape)

    def _colors(self, hue: torch.Tensor) -> torch.Tensor:
        # Bright, saturated colours drawn independently of the type, so that pixels never tell
        # a connected vehicle from a human-driven one.
        k = (torch.arange(3, device=self.device) / 3.0)
        rgb = 0.5 + 0.5 * torch.cos(2 * torch.pi * (hue.unsqueeze(-1) + k))
        return (40 + 200 * rgb).to(torch.uint8)

    def _initial_state(self, mask: torch.Tensor, old: TrafficState | None) -> TrafficState:
        """A fresh episode for envs where `mask` is True (others copied from `old`)."""
        c, d, n = self.config, self.device, self.n_envs
        # Envs that do not reset draw nothing (None: none resets), so that a member's traffic never
        # depends on when another member's episodes end.
        draws = self.randomness.draws(None if old is None else mask)
        if draws is None:
            return old
        per_lane, lanes = c.vehicles_per_lane, c.lanes
        span = c.window_behind + c.window_ahead
        spacing = span / per_lane
        # Vehicles start on a jittered grid: every lane evenly filled, no overlap by construction.
        base = -c.window_behind + (torch.arange(per_lane, device=d) + 0.5) * spacing
        jitter = (draws.rand(lanes, per_lane) * 2 - 1) * 0.2 * spacing
        pos_lon = (base.view(1, 1, -1) + jitter).reshape(n, lanes * per_lane)
        lane = torch.arange(lanes, device=d).repeat_interleave(per_lane).expand(n, -1).clone()
        # The grid slot nearest the origin in the host's start lane becomes the host, moved to slot 0.
        host_slot = c.host_start_lane * per_lane + int(base.abs().argmin())
        perm = torch.arange(lanes * per_lane, device=d)
        perm[0], perm[host_slot] = host_slot, 0
        pos_lon, lane = pos_lon[:, perm], lane[:, perm]
        pos_lon[:, HOST] = 0.0
        vtype = self._types(draws.rand(lanes * per_lane))
        vtype[:, HOST] = 0
        speed = c.v_min + draws.rand(lanes * per_lane) * (c.v_max - c.v_min)
        speed[:, HOST] = c.host_start_speed_kmh / 3.6
        m = lanes * per_lane
        zeros_f = torch.zeros(n, device=d)
        fresh = TrafficState(
            pos_lon=pos_lon, pos_lat=self.lane_centres[lane], speed=speed, cruise=speed.clone(), target_lane=lane,
            vtype=vtype,
            active=torch.ones(n, m, dtype=torch.bool, device=d), color=self._colors(draws.rand(m)),
            was_ahead=pos_lon > 0, passed=torch.zeros(n, m, dtype=torch.bool, device=d),
            decision=torch.zeros(n, dtype=torch.long, device=d),
            ep_speed_sum=zeros_f.clone(), ep_lane_changes=zeros_f.clone(), ep_overtakes=zeros_f.clone(),
            ep_collisions=zeros_f.clone(), ep_dangerous=zeros_f.clone(), ep_distance=zeros_f.clone(),
            ep_return=zeros_f.clone(), ep_last_lane_change=torch.full((n,), -1.0, device=d),
            ep_lane_change_requests=zeros_f.clone(), ep_refused_gap=zeros_f.clone(), ep_refused_parity=zeros_f.clone(),
            ep_crash_into_leader=zeros_f.clone(), ep_crash_from_behind=zeros_f.clone(),
            ep_crash_partner_changing=zeros_f.clone(), ep_crash_host_changing=zeros_f.clone(),
            npc_collisions=zeros_f.clone(), npc_distance=zeros_f.clone(),
        )
        fresh.color[:, HOST] = torch.tensor([230, 30, 30], dtype=torch.uint8, device=d)  # the paper's red host
        if old is None:
            return fresh
        out = {}
        for k, new_v in fresh.tensors().items():
            old_v = getattr(old, k)
            if k in ("npc_collisions", "npc_distance"):
                out[k] = old_v
                continue
            msk = mask.view(-1, *([1] * (new_v.dim() - 1)))
            out[k] = torch.where(msk, new_v, old_v)
        return TrafficState(**out)

    # ----------------------------------------------------------------------------------- api
    def reset(self, mask: torch.Tensor | None = None) -> TrafficState:
        """Start new episodes in the envs where `mask` is True (all envs when None)."""
        if mask is None:
            mask = torch.ones(self.n_envs, dtype=torch.bool, device=self.device)
        self.state = self._initial_state(mask.to(self.device).reshape(-1), self.state)
        return self.state

    def neighbours(self, state: TrafficState | None = None) -> Neighbours:
        s = self.state if state is None else state
        occ = lane_occupancy(s.pos_lat, self.half_wid_by_type[s.vtype], s.target_lane, s.active,
                             self.config.lanes, self.config.lane_width)
        return nearest_per_lane(s.pos_lon, occ)

    def npc_actions(self, state: TrafficState) -> torch.Tensor:
        """Table 1's random behaviour: a random lane change with probability r_lat, else a random
        longitudinal action with probability r_lon, else no action."""
        n, m = state.pos_lon.shape
        u_lat, u_lon, u_dir = self.randomness.rand(m), self.randomness.rand(m), self.randomness.rand(m)
        r_lat, r_lon = self.r_lat_by_type[state.vtype], self.r_lon_by_type[state.vtype]
        act = torch.full((n, m), int(Action.NO_ACTION), device=self.device, dtype=torch.long)
        lon_act = torch.where(u_dir < 0.5, int(Action.ACCELERATE), int(Action.DECELERATE))
        lat_act = torch.where(u_dir < 0.5, int(Action.LANE_LEFT), int(Action.LANE_RIGHT))
        act = torch.where(u_lon < r_lon, lon_act, act)
        return torch.where(u_lat < r_lat, lat_act, act)

    def step(self, host_action: torch.Tensor) -> StepResult:
        """Advance every env by one decision; `host_action` is [N] of `Action` values."""
        c, s = self.config, self.state
        n, m = s.pos_lon.shape
        d = self.device
        host_action = host_action.to(d).reshape(n).long()
        v_min, v_max = c.v_min, c.v_max
        half_len, half_wid = self.half_len_by_type[s.vtype], self.half_wid_by_type[s.vtype]
        a_lon, v_lat = self.a_lon_by_type[s.vtype], self.v_lat_by_type[s.vtype]

        actions = self.npc_actions(s)
        actions[:, HOST] = host_action
        # Which vehicles obey the safety layer: every NPC, and the host only when asked to.
        guarded = torch.ones(n, m, dtype=torch.bool, device=d)
        guarded[:, HOST] = self.host_safety_layer

        # --- lane changes (eq. 3): start only when none is under way and the lane exists.
        nb = self.neighbours(s)
        centre = self.lane_centres[s.target_lane]
        changing = (s.pos_lat - centre).abs() > 1e-4
        wants_left = actions == int(Action.LANE_LEFT)
        wants_right = actions == int(Action.LANE_RIGHT)
        wants = wants_left | wants_right
        desired = s.target_lane - wants_left.long() + wants_right.long()
        off_road = wants & ((desired < 0) | (desired >= c.lanes))
        desired_c = desired.clamp(0, c.lanes - 1)
        lead_in_target = nb.lead.gather(2, desired_c.unsqueeze(-1)).squeeze(-1)
        follow_in_target = nb.follow.gather(2, desired_c.unsqueeze(-1)).squeeze(-1)
        front_gap = gather_vehicles(s.pos_lon, lead_in_target, INF) - s.pos_lon - half_len \
            - gather_vehicles(half_len, lead_in_target, 0.0)
        rear_gap = s.pos_lon - gather_vehicles(s.pos_lon, follow_in_target, -INF) - half_len \
            - gather_vehicles(half_len, follow_in_target, 0.0)
        rear_speed = gather_vehicles(s.speed, follow_in_target, 0.0)
        lead_speed_in_target = gather_vehicles(s.speed, lead_in_target, INF)
        gap_time = self.gap_time_by_type[s.vtype]
        s0, tau = c.safety.min_gap, c.safety.reaction_time
        gap_ok = (front_gap >= s0 + gap_time * s.speed + (s.speed - lead_speed_in_target).clamp(min=0) * tau) & \
                 (rear_gap >= s0 + gap_time * rear_speed + (rear_speed - s.speed).clamp(min=0) * tau)
        # Guarded drivers change to the left only on even decisions and to the right only on
        # odd ones, so that two of them never merge into the same lane from both sides at once.
        even = (s.decision % 2 == 0).unsqueeze(1)
        direction_ok = torch.where(even, wants_left, wants_right)
        start = wants & ~changing & ~off_road & (~guarded | (gap_ok & direction_ok))
        target_lane = torch.where(start, desired_c, s.target_lane)
        # What the layer refused the host (contracts.events): by the gaps, or by the parity alone.
        host_request = wants[:, HOST] & ~changing[:, HOST] & ~off_road[:, HOST] & guarded[:, HOST]
        refused_gap = host_request & ~gap_ok[:, HOST]
        refused_parity = host_request & gap_ok[:, HOST] & ~direction_ok[:, HOST]

        # --- longitudinal command (eq. 2).
        # Guarded drivers hold a cruise speed that their random actions move by a_lon per second;
        # when the safety layer has braked them they work back up to it, so braking for others
        # does not drag the whole traffic down to v_min over time.
        accelerate, decelerate = actions == int(Action.ACCELERATE), actions == int(Action.DECELERATE)
        dv = a_lon * c.decision_dt
        cruise = (s.cruise + torch.where(accelerate, dv, 0.0) - torch.where(decelerate, dv, 0.0)).clamp(v_min, v_max)
        accel_cmd = torch.where(accelerate, a_lon, torch.where(decelerate, -a_lon, 0.0))
        accel_cmd = torch.where(guarded, ((cruise - s.speed) / c.decision_dt).clamp(-a_lon, a_lon), accel_cmd)

        # --- physics sub-steps. The order along the road cannot change within a decision without a
        # crash, so each vehicle's leaders are found once, in the (at most two) lanes it occupies.
        nb2 = nearest_per_lane(s.pos_lon, lane_occupancy(s.pos_lat, half_wid, target_lane, s.active,
                                                          c.lanes, c.lane_width), with_follow=False)
        w = c.lane_width
        lane_lo = torch.minimum(((s.pos_lat - half_wid) / w).floor().long(), target_lane).clamp(0, c.lanes - 1)
        lane_hi = torch.maximum(((s.pos_lat + half_wid) / w).ceil().long() - 1, target_lane).clamp(0, c.lanes - 1)
        lead = nb2.lead.gather(2, torch.stack([lane_lo, lane_hi], -1))  # [N, M, 2]
        has_lead = (lead >= 0) & s.active.unsqueeze(-1)
        len_sum = half_len.unsqueeze(-1) + gather_vehicles(half_len, lead, 0.0)
        wid_sum = half_wid.unsqueeze(-1) + gather_vehicles(half_wid, lead, 0.0)
        dt = c.physics_dt
        b = c.safety.emergency_decel
        pos_lon, pos_lat, speed = s.pos_lon, s.pos_lat, s.speed
        target_lat = self.lane_centres[target_lane]
        hit = torch.zeros(n, m, dtype=torch.bool, device=d)
        npc_crashes = torch.zeros(n, device=d)
        start_pos = pos_lon
        lat_step = v_lat * dt

        def gap_to_lead(pos: torch.Tensor) -> torch.Tensor:
            return torch.where(has_lead, gather_vehicles(pos, lead, INF) - pos.unsqueeze(-1) - len_sum, INF)

        gap = gap_to_lead(pos_lon)
        # The host's crash as it was at its first overlap (contracts.events): into a leader, from behind,
        # the partner and the host changing lanes (mid-way, or beginning in this decision).
        lane_moving = changing | start
        crash_facts = torch.zeros(n, 4, device=d)
        for _ in range(c.substeps):
            # Longitudinal: eq. 2 for everyone, then the Krauss safe speed for guarded drivers.
            v_cmd = speed + accel_cmd * dt
            v_cmd = torch.where(accel_cmd > 0, torch.minimum(v_cmd, speed.clamp(min=v_max)), v_cmd)
            v_cmd = torch.where(accel_cmd < 0, torch.maximum(v_cmd, speed.clamp(max=v_min)), v_cmd)
            v_l = gather_vehicles(speed, lead, 0.0)
            v_safe = v_l + ((gap - s0).clamp(min=0) - v_l * tau) / ((speed.unsqueeze(-1) + v_l) / (2 * b) + tau)
            v_safe = torch.where(has_lead, v_safe, INF).amin(-1)
            v_guard = torch.maximum(torch.minimum(v_cmd, v_safe), (speed - b * dt).clamp(min=0))
            v_new = torch.where(guarded & s.active, v_guard, v_cmd)
            pos_lon = pos_lon + 0.5 * (speed + v_new) * dt
            speed = v_new
            # Lateral (eq. 3): v_lat towards the target lane's centre, stopping there.
            dlat = target_lat - pos_lat
            pos_lat = pos_lat + dlat.sign() * torch.minimum(dlat.abs(), lat_step)
            # Collisions, checked after every move (the last sub-step's included, so that a crash
            # is charged to the decision it happens in): a leader in a shared lane whose body
            # overlaps ours; a pair is (i, lead).
            gap = gap_to_lead(pos_lon)
            overlap = (gap < 0) & ((gather_vehicles(pos_lat, lead, 0.0) - pos_lat.unsqueeze(-1)).abs() < wid_sum)
            # On CPU skipping the bookkeeping when nothing overlaps pays; on a GPU the check itself
            # would stall the stream, so the bookkeeping always runs there.
            if self.device.type != "cpu" or bool(overlap.any()):
                host_was_hit = hit[:, HOST]
                hit, npc_crashes = self._record_crashes(overlap, lead, hit, npc_crashes)
                first = (hit[:, HOST] & ~host_was_hit).unsqueeze(1)
                crash_facts = torch.where(first, self._host_crash_facts(overlap, lead, lane_moving), crash_facts)
        final_gap = gap[:, HOST]

        # --- host events
        host_pos = pos_lon[:, HOST]
        ahead_now = pos_lon > host_pos.unsqueeze(1)
        # A host collision ends the decision: nothing is overtaken in it, neither the vehicle the
        # sub-steps carried the host through nor any other, so a crash never pays R_o.
        host_collision = hit[:, HOST]
        overtaken = s.was_ahead & ~ahead_now & ~s.passed & s.active & ~host_collision.unsqueeze(1)
        overtaken[:, HOST] = False
        n_overtakes = overtaken.sum(1).float()
        host_v = speed[:, HOST].clamp(min=1e-3)
        th = c.reward.dangerous_time_gap
        tailgating = final_gap.amin(-1) / host_v < th
        host_start = start[:, HOST]
        cut_in = host_start & (rear_gap[:, HOST] / rear_speed[:, HOST].clamp(min=1e-3) < th)
        dangerous = tailgating | cut_in | off_road[:, HOST]

        terms = RewardTerms(
            speed=speed_reward(speed[:, HOST], v_min, v_max),
            collision=host_collision.float() * c.reward.collision,
            dangerous=dangerous.float() * c.reward.dangerous,
            lane_change=host_start.float() * c.reward.lane_change,
            overtake=(n_overtakes if c.reward.overtake_per_vehicle else (n_overtakes > 0).float())
            * c.reward.overtake,
        )
        reward = terms.total()

        # --- bookkeeping
        travelled = pos_lon - start_pos
        decision = s.decision + 1
        ep = dict(
            ep_speed_sum=s.ep_speed_sum + speed[:, HOST],
            ep_lane_changes=s.ep_lane_changes + host_start.float(),
            ep_overtakes=s.ep_overtakes + n_overtakes,
            ep_collisions=s.ep_collisions + host_collision.float(),
            ep_dangerous=s.ep_dangerous + dangerous.float(),
            ep_distance=s.ep_distance + travelled[:, HOST],
            ep_return=s.ep_return + reward,
            ep_last_lane_change=torch.where(host_start, s.decision.float(), s.ep_last_lane_change),
            ep_lane_change_requests=s.ep_lane_change_requests + (wants[:, HOST] & ~changing[:, HOST]
                                                                 & ~off_road[:, HOST]).float(),
            ep_refused_gap=s.ep_refused_gap + refused_gap.float(),
            ep_refused_parity=s.ep_refused_parity + refused_parity.float(),
            ep_crash_into_leader=s.ep_crash_into_leader + crash_facts[:, 0],
            ep_crash_from_behind=s.ep_crash_from_behind + crash_facts[:, 1],
            ep_crash_partner_changing=s.ep_crash_partner_changing + crash_facts[:, 2],
            ep_crash_host_changing=s.ep_crash_host_changing + crash_facts[:, 3],
        )
        npc_collisions = s.npc_collisions + npc_crashes
        npc_distance = s.npc_distance + (travelled[:, 1:] * s.active[:, 1:]).sum(1)

        # --- NPCs that crashed or left the window wait for a free spot at the far edge.
        active = s.active & ~(hit & (torch.arange(m, device=d) != HOST))
        rel = pos_lon - host_pos.unsqueeze(1)
        left_behind = rel < -c.window_behind - SPAWN_ZONE
        left_ahead = rel > c.window_ahead + SPAWN_ZONE
        active = active & ~left_behind & ~left_ahead
        active[:, HOST] = True
        self.state = TrafficState(
            pos_lon=pos_lon, pos_lat=pos_lat, speed=speed, cruise=cruise, target_lane=target_lane, vtype=s.vtype,
            active=active, color=s.color, was_ahead=ahead_now, passed=s.passed | overtaken,
            decision=decision, npc_collisions=npc_collisions, npc_distance=npc_distance, **ep,
        )
        # Who fell behind comes back ahead and vice versa; crashed NPCs by the side they were on.
        if self.respawn:
            spawn_front = ~active & (left_behind | (~left_ahead & (rel <= 0)))
            st = self.state
            occ = lane_occupancy(st.pos_lat, self.half_wid_by_type[st.vtype], st.target_lane, st.active, c.lanes,
                                 c.lane_width)
            self._respawn(~st.active & spawn_front, front=True, occupancy=occ)
            self._respawn(~st.active & ~spawn_front, front=False, occupancy=occ)

        terminated = host_collision
        truncated = (decision >= c.episode_decisions) & ~terminated
        done = terminated | truncated
        return StepResult(reward=reward, terms=terms, terminated=terminated, truncated=truncated & done,
                          lane_change=host_start, overtakes=n_overtakes, dangerous=dangerous,
                          collision=host_collision, episode=episode_metrics(self.state))

    # ----------------------------------------------------------------------------------- spawning
    def _record_crashes(self, overlap: torch.Tensor, lead: torch.Tensor, hit: torch.Tensor,
                        npc_crashes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mark vehicles in overlapping (vehicle, lead) pairs; count new NPC-NPC crashes once each."""
        m = overlap.shape[1]
        is_host = torch.arange(m, device=overlap.device) == HOST
        host_pair = overlap & (is_host.view(1, m, 1) | (lead == HOST))
        in_host_crash = self._involved(host_pair, lead)
        in_npc_crash = self._involved(overlap & ~host_pair, lead)
        npc_crashes = npc_crashes + (in_npc_crash & ~hit).sum(1).float() / 2
        return hit | in_host_crash | in_npc_crash, npc_crashes

    @staticmethod
    def _host_crash_facts(overlap: torch.Tensor, lead: torch.Tensor, lane_moving: torch.Tensor) -> torch.Tensor:
        """[N, 4] floats (0/1) of the host's overlaps now: it overlaps a leader; a follower overlaps it;
        the vehicle it overlaps is changing lanes (its leader first); the host is changing lanes."""
        ahead = overlap[:, HOST, :]  # [N, 2]: the host's leader in either lane its body covers
        behind = (overlap & (lead == HOST)).any(-1)  # [N, M]: vehicles whose leader is the host
        behind[:, HOST] = False
        partner = torch.where(ahead[:, 0], lead[:, HOST, 0],
                              torch.where(ahead[:, 1], lead[:, HOST, 1], behind.float().argmax(1)))
        partner_moving = lane_moving.gather(1, partner.clamp(min=0).unsqueeze(1)).squeeze(1)
        return torch.stack([ahead.any(-1), behind.any(1), partner_moving, lane_moving[:, HOST]], 1).float()

    @staticmethod
    def _involved(pairs: torch.Tensor, lead: torch.Tensor) -> torch.Tensor:
        """[N, M] bool: vehicles on either side of a True (vehicle, lead in lane) pair."""
        n, m, _ = pairs.shape
        as_lead = torch.zeros(n, m, device=pairs.device).scatter_add_(
            1, lead.clamp(min=0).reshape(n, -1), pairs.reshape(n, -1).float())
        return pairs.any(-1) | (as_lead > 0)

    def _respawn(self, candidates: torch.Tensor, front: bool, occupancy: torch.Tensor, count: int = 2) -> None:
        """Bring back up to `count` waiting vehicles per env among `candidates`, at the front edge
        of the window or at its rear edge. Each goes just beyond the outermost vehicle of a lane
        drawn among those with room in the spawn band; where no lane has room it waits."""
        c, s, d = self.config, self.state, self.device
        n, m = s.pos_lon.shape
        draws = self.randomness.draws(candidates)
        if draws is None:
            return
        candidates = candidates.clone()
        half_len = self.half_len_by_type[s.vtype]
        pos = s.pos_lon.unsqueeze(-1).expand_as(occupancy)
        if front:
            near_pos, near_idx = pos.masked_fill(~occupancy, -INF).max(1)  # [N, L]
        else:
            near_pos, near_idx = pos.masked_fill(~occupancy, INF).min(1)
        near_speed = s.speed.gather(1, near_idx)
        near_hl = half_len.gather(1, near_idx)
        edge = (s.pos_lon[:, HOST] + (c.window_ahead if front else -c.window_behind)).unsqueeze(1)
        inner = edge - (5.0 if front else -5.0)
        slot_idx = torch.arange(m, device=d)
        for _ in range(count):
            # The waiting vehicle with the lowest slot index in each env.
            slot = torch.where(candidates, slot_idx, m).amin(1)
            has = slot < m
            slot = slot.clamp(max=m - 1)
            new_type = self._types(draws.rand())
            new_speed = c.v_min + draws.rand() * (c.v_max - c.v_min)
            hl_new = self.half_len_by_type[new_type].unsqueeze(1)
            # The newcomer never closes in on its neighbour: ahead of the field it drives at least
            # as fast as the vehicle behind it, behind the field at most as fast as the one ahead.
            lane_speed = (torch.maximum if front else torch.minimum)(new_speed.unsqueeze(1), near_speed)
            need = c.safety.min_gap + 0.5 * (near_speed if front else lane_speed) + hl_new + near_hl
            empty = ~torch.isfinite(near_pos)
            if front:
                spot = torch.where(empty, inner, torch.maximum(inner, near_pos + need))
                free = spot <= edge + SPAWN_ZONE - 5.0
            else:
                spot = torch.where(empty, inner, torch.minimum(inner, near_pos - need))
                free = spot >= edge - SPAWN_ZONE + 5.0
            score = torch.where(free, draws.rand(c.lanes), -1.0)
            lane = score.argmax(1, keepdim=True)
            spawn_pos = spot.gather(1, lane).squeeze(1)
            new_speed = torch.where(empty.gather(1, lane), new_speed.unsqueeze(1),
                                    lane_speed.gather(1, lane)).squeeze(1)
            lane = lane.squeeze(1)
            ok = draws.narrow(has & free.any(1))
            if ok is None:
                return
            rows = torch.nonzero(ok).squeeze(1)
            cols, lanes = slot[rows], lane[rows]
            s.pos_lon[rows, cols] = spawn_pos[rows]
            s.pos_lat[rows, cols] = self.lane_centres[lanes]
            s.speed[rows, cols] = new_speed[rows]
            s.cruise[rows, cols] = new_speed[rows]
            s.target_lane[rows, cols] = lanes
            s.vtype[rows, cols] = new_type[rows]
            s.active[rows, cols] = True
            s.color[rows, cols] = self._colors(draws.rand_rows(rows))
            s.was_ahead[rows, cols] = front
            s.passed[rows, cols] = False
            candidates[rows, cols] = False
            # The newcomer is now the outermost vehicle of its lane.
            near_pos[rows, lanes] = spawn_pos[rows]
            near_speed[rows, lanes] = new_speed[rows]
            near_hl[rows, lanes] = hl_new[rows, 0]
