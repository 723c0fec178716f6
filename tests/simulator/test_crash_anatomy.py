"""Crash anatomy and the safety layer's refusals, where the events meet: hand-placed scenes drive the
simulator into each kind of crash, and the per-episode records classify it (`contracts.events`)."""

from __future__ import annotations

import pandas as pd
import pytest
import torch

from hgm_repro.contracts import events
from hgm_repro.simulator import HOST, Action, episode_metrics
from tests.helpers.sim import calm, empty_road, make_sim, place

V_MIN, V_MAX = 40 / 3.6, 80 / 3.6


def drive(sim, actions: list[Action], until_crash: bool = True) -> pd.DataFrame:
    """Step the host through `actions` (the last one repeated until a crash, at most 40 decisions);
    the episode's records as one row, read where it ended."""
    for k in range(40):
        action = actions[min(k, len(actions) - 1)]
        result = sim.step(torch.full((sim.n_envs,), int(action)))
        if bool(result.done.all()) or (not until_crash and k == len(actions) - 1):
            break
    row = {k: float(v[0]) for k, v in (result.episode if bool(result.done[0]) else episode_metrics(sim.state)).items()}
    return pd.DataFrame([row])


def scene(**overrides):
    return calm(empty_road(make_sim(**overrides), host_lane=2, host_speed=60 / 3.6))


def test_a_crash_during_the_hosts_lane_change_is_the_lane_changes():
    sim = scene()
    place(sim, 1, lon=1.0, lane=1, speed=60 / 3.6)  # alongside, in the lane to the left
    row = drive(sim, [Action.LANE_LEFT, Action.NO_ACTION])
    assert row["collisions"][0] == 1 and row["lane_changes"][0] == 1
    # Its body reaches the car beside it after 4 decisions (1.7 m sideways at 1 m/s): within the window.
    assert 3 <= row[events.LANE_CHANGE_AGE][0] < events.LANE_CHANGE_CRASH_DECISIONS
    assert row[events.CRASH_HOST_CHANGING][0] == 1
    assert list(events.crash_kind(row)) == ["lane_change"]


def test_a_rear_end_in_the_hosts_own_lane():
    sim = scene()
    sim.state.speed[:, HOST] = V_MAX
    place(sim, 1, lon=12.0, lane=2, speed=V_MIN)
    row = drive(sim, [Action.ACCELERATE])
    assert row["collisions"][0] == 1 and row["lane_changes"][0] == 0
    assert (row[events.CRASH_INTO_LEADER][0], row[events.CRASH_FROM_BEHIND][0]) == (1, 0)
    assert row[events.CRASH_PARTNER_CHANGING][0] == 0
    assert list(events.crash_kind(row)) == ["rear_end"]


def test_hit_from_behind():
    sim = scene()
    sim.state.speed[:, HOST] = V_MIN
    # Closing at 11 m/s from 3.5 m bumper to bumper: no braking of 6 m/s^2 stops that in time.
    place(sim, 1, lon=-8.0, lane=2, speed=V_MAX)
    row = drive(sim, [Action.DECELERATE])
    assert row["collisions"][0] == 1
    assert (row[events.CRASH_INTO_LEADER][0], row[events.CRASH_FROM_BEHIND][0]) == (0, 1)
    assert list(events.crash_kind(row)) == ["hit_from_behind"]


def test_a_car_cutting_in_is_other_and_a_lane_change_long_before_does_not_count():
    sim = scene()
    place(sim, 1, lon=2.0, lane=1, speed=60 / 3.6)
    sim.state.target_lane[0, 1] = 2  # it is moving into the host's lane, right beside it
    row = drive(sim, [Action.NO_ACTION])
    assert row["collisions"][0] == 1 and row[events.CRASH_PARTNER_CHANGING][0] == 1
    assert list(events.crash_kind(row)) == ["other"]
    # The same records with a lane change of the host's begun long before: still not the lane change's.
    long_ago = row.assign(lane_changes=1.0, **{events.LANE_CHANGE_AGE: float(events.LANE_CHANGE_CRASH_DECISIONS)})
    assert list(events.crash_kind(long_ago)) == ["other"]
    # And an episode without a crash has no kind.
    assert events.crash_kind(row.assign(collisions=0.0)).isna().all()


def test_the_layer_refuses_by_gap_and_by_parity_and_counts_each():
    sim = scene(host_safety_layer=True)
    place(sim, 1, lon=1.0, lane=1, speed=60 / 3.6)
    # Decision 0 (even): right, into an empty lane, is refused by the parity alone. Decisions 1 and 2: left,
    # refused by the car alongside (whatever the parity). Decision 3 (odd): right starts.
    row = drive(sim, [Action.LANE_RIGHT, Action.LANE_LEFT, Action.LANE_LEFT, Action.LANE_RIGHT], until_crash=False)
    assert row["collisions"][0] == 0
    assert row[events.LANE_CHANGE_REQUESTS][0] == 4
    assert row[events.REFUSED_BY_PARITY][0] == 1
    assert row[events.REFUSED_BY_GAP][0] == 2
    assert row["lane_changes"][0] == 1 and int(sim.state.target_lane[0, HOST]) == 3
    assert row[events.LANE_CHANGE_AGE][0] == 0  # began in the last decision


@pytest.mark.parametrize("guarded", [False, True])
def test_only_a_guarded_host_is_refused(guarded):
    sim = scene(host_safety_layer=guarded)
    row = drive(sim, [Action.LANE_RIGHT], until_crash=False)  # decision 0 is even: right is the wrong parity
    assert row[events.LANE_CHANGE_REQUESTS][0] == 1
    assert row[events.REFUSED_BY_PARITY][0] == (1 if guarded else 0)
    assert row["lane_changes"][0] == (0 if guarded else 1)
