"""What a test records per episode beyond the paper's metrics, and the one rule that reads it.

Two questions the paper's metrics cannot answer come from the same per-episode columns
(`HighwaySimulator.step` fills them, `simulator.episode_metrics` reports them, every test's
`episodes.csv` keeps them):

- Where a crash comes from (crash anatomy). A host collision ends its episode, so an episode holds
  at most one, and the columns describe it: who ran into whom at the first overlap, whether the
  partner was changing lanes, and how many decisions before it the host last began a lane change.
  `crash_kind` turns them into one of `CRASH_KINDS`.
- What the safety layer refused. A guarded host's lane-change request (a lane action while no lane
  change is under way and the target lane exists) starts only when the gaps allow it and the
  decision's parity does (left on even decisions, right on odd ones: two guarded drivers never merge
  into one lane from both sides at once). A learned host cannot see the parity, so these columns
  measure what it costs: requests refused by the gaps, and requests the gaps allowed but the parity
  refused. An unguarded host is never refused.

No torch here: analysis reads these names too.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .names import EPISODE_METRICS

# Per-episode columns, in the order the simulator reports them after `names.EPISODE_METRICS`.
LANE_CHANGE_AGE = "lane_change_age"  # decisions from the host's last lane-change start to the episode's last decision
LANE_CHANGE_REQUESTS = "lane_change_requests"
REFUSED_BY_GAP = "lane_changes_refused_gap"
REFUSED_BY_PARITY = "lane_changes_refused_parity"
CRASH_INTO_LEADER = "crash_into_leader"  # the host ran into a vehicle ahead of it
CRASH_FROM_BEHIND = "crash_from_behind"  # a vehicle behind ran into the host
CRASH_PARTNER_CHANGING = "crash_partner_changing"  # the vehicle the host met was changing lanes
CRASH_HOST_CHANGING = "crash_host_changing"  # the host was changing lanes when it crashed
EPISODE_EVENTS = (LANE_CHANGE_AGE, LANE_CHANGE_REQUESTS, REFUSED_BY_GAP, REFUSED_BY_PARITY, CRASH_INTO_LEADER,
                  CRASH_FROM_BEHIND, CRASH_PARTNER_CHANGING, CRASH_HOST_CHANGING)

# Everything a test records per episode: the paper's metrics, then these.
RECORDED_PER_EPISODE = (*EPISODE_METRICS, *EPISODE_EVENTS)

# A crash within this many decisions of the host beginning a lane change (the decision that began
# it counts as the first) is the lane change's. The host (HV, v_lat 1 m/s) takes 7 decisions to cross
# a 3.5 m lane, and its body first reaches a vehicle beside it in the target lane after 4 (it must
# move 1.7 m sideways): 3 decisions would miss every such side-swipe. 10 covers the whole manoeuvre
# and the 1.5 s after it in which a follower it cut in front of runs into it.
LANE_CHANGE_CRASH_DECISIONS = 10

# The kinds, in the order tables and figures show them:
# - lane_change: the host began a lane change within the last LANE_CHANGE_CRASH_DECISIONS decisions;
# - rear_end: the host ran into the vehicle ahead in its own lane (neither was changing lanes);
# - hit_from_behind: a vehicle behind in the host's lane ran into it (neither was changing lanes);
# - other: the rest (a vehicle cutting in or out, a lane change of the host's begun earlier and still
#   under way, both at once).
CRASH_KINDS = ("lane_change", "rear_end", "hit_from_behind", "other")
CRASH_KIND_LABELS = {"lane_change": f"lane change begun in the last {LANE_CHANGE_CRASH_DECISIONS} decisions",
                     "rear_end": "rear-end: the host into the vehicle ahead",
                     "hit_from_behind": "hit from behind",
                     "other": "other"}


def has_events(episodes: pd.DataFrame) -> bool:
    """Whether a test's episodes carry the event columns (tests before them did not record them)."""
    return all(c in episodes.columns for c in EPISODE_EVENTS)


def crash_kind(episodes: pd.DataFrame) -> pd.Series:
    """Each episode's crash kind (one of `CRASH_KINDS`), or missing where the episode did not crash.
    `episodes` holds `collisions`, `lane_changes` and the `EPISODE_EVENTS` columns."""
    crashed = episodes["collisions"].to_numpy() > 0
    # lane_changes > 0: with none, the age counts from the episode's start, not from a lane change.
    recent = (episodes["lane_changes"].to_numpy() > 0) \
        & (episodes[LANE_CHANGE_AGE].to_numpy() < LANE_CHANGE_CRASH_DECISIONS)
    changing = (episodes[CRASH_PARTNER_CHANGING].to_numpy() > 0) | (episodes[CRASH_HOST_CHANGING].to_numpy() > 0)
    into_leader = episodes[CRASH_INTO_LEADER].to_numpy() > 0
    from_behind = episodes[CRASH_FROM_BEHIND].to_numpy() > 0
    in_lane = ~changing & (into_leader != from_behind)
    kind = np.select([recent, in_lane & into_leader, in_lane & from_behind], list(CRASH_KINDS[:3]), CRASH_KINDS[3])
    return pd.Series(np.where(crashed, kind, None), index=episodes.index, dtype="object")


def event_means(episodes: pd.DataFrame, prefix: str) -> dict[str, float]:
    """What a test logs of the events, as `<prefix>/<name>`: crashes per episode of each kind
    (`crashes_<kind>`), lane-change requests per episode, and of all requests the share the gaps
    refused (`refused_gap_share`) and the share only the parity refused (`refused_parity_share`; both
    left out when the host asked for no lane change)."""
    kinds = crash_kind(episodes)
    out = {f"{prefix}/crashes_{k}": float((kinds == k).sum()) / len(episodes) for k in CRASH_KINDS}
    out[f"{prefix}/{LANE_CHANGE_REQUESTS}"] = float(episodes[LANE_CHANGE_REQUESTS].mean())
    requests = float(episodes[LANE_CHANGE_REQUESTS].sum())
    if requests > 0:
        out[f"{prefix}/refused_gap_share"] = float(episodes[REFUSED_BY_GAP].sum()) / requests
        out[f"{prefix}/refused_parity_share"] = float(episodes[REFUSED_BY_PARITY].sum()) / requests
    return out
