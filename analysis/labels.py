"""Names, orders, colours and number formats shared by the figures, tables and report."""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal

import pandas as pd

LEARNED = ("proposed", "min", "coordinate")
# Drawn as horizontal lines on the training figures; idm_mobil_limits is the fair bar for a learned
# host (the same rule inside the host's own limits, no safety layer). idm_limits (IDM alone inside
# the same limits, the bar for a host that keeps its lane) is a study host, labelled when present.
REFERENCE_HOSTS = ("human", "idm_mobil", "idm_mobil_limits")
# proposed_enriched (conf/model/proposed_enriched.yaml) is a labelled variant, not the paper's method: it is
# drawn and tabled beside the three, and no claim reads it.
# The guarded forms (conf/model/*_guarded.yaml) are the three methods trained and tested under the
# human-driven host's safety layer: not the paper's methods, named so wherever they appear; the claims
# read them only in their own section ("On equal terms"), in place of the methods they guard.
GUARDED = {"proposed_guarded": "proposed", "min_guarded": "min", "coordinate_guarded": "coordinate"}
# A network trained without the layer and tested under it (eval.host_safety_layer): a probe, not a method.
LAYER_AT_TEST = {"proposed_layer_at_test": "proposed", "min_layer_at_test": "min",
                 "coordinate_layer_at_test": "coordinate"}
# The same training tested from its safest kept validation pass (eval.checkpoint=safest), beside the test
# of the preset's own network: a choice of network, not a method; named after the host it was chosen for.
SAFEST = {f"{host}_safest": host for host in (*LEARNED, *GUARDED)}
# Tests of a method's trainings under another test option (the layer at test, the safest network): each has
# a section of its own; the hosts' figure and the first table leave them out.
PROBES = (*LAYER_AT_TEST, *SAFEST)
MODEL_ORDER = ("proposed", "min", "coordinate", "proposed_enriched", *GUARDED, *LAYER_AT_TEST, *SAFEST, "human",
               "idm_mobil", "idm_mobil_limits", "idm_limits", "random")
MODEL_LABELS = {
    "proposed": "Proposed (HGM + camera)",
    "min": "Min (camera only)",
    "coordinate": "Coordinate (V2X vector + camera)",
    "proposed_enriched": "Variant: proposed with the enriched HGM (not the paper's)",
    "proposed_guarded": "Guarded: proposed under the safety layer (not the paper's)",
    "min_guarded": "Guarded: Min under the safety layer (not the paper's)",
    "coordinate_guarded": "Guarded: Coordinate under the safety layer (not the paper's)",
    "proposed_layer_at_test": "Proposed, under the layer at test only (trained without it)",
    "min_layer_at_test": "Min, under the layer at test only (trained without it)",
    "coordinate_layer_at_test": "Coordinate, under the layer at test only (trained without it)",
    "human": "Human-driven host",
    "idm_mobil": "IDM + MOBIL host",
    "idm_mobil_limits": "IDM + MOBIL inside the host's limits",
    "idm_limits": "IDM lane keeping inside the host's limits",
    "random": "Random host",
}
MODEL_LABELS.update({name: f"{MODEL_LABELS[host]}, tested from its safest network" for name, host in SAFEST.items()})
SHORT_LABELS = {"proposed": "Proposed", "min": "Min", "coordinate": "Coordinate",
                "proposed_enriched": "Variant: enriched HGM", "proposed_guarded": "Proposed (guarded)",
                "min_guarded": "Min (guarded)", "coordinate_guarded": "Coordinate (guarded)",
                "proposed_layer_at_test": "Proposed (layer at test)", "min_layer_at_test": "Min (layer at test)",
                "coordinate_layer_at_test": "Coordinate (layer at test)", "human": "Human", "idm_mobil": "IDM+MOBIL",
                "idm_mobil_limits": "IDM+MOBIL (host limits)", "idm_limits": "IDM (host limits)", "random": "Random"}
SHORT_LABELS.update({name: f"{SHORT_LABELS[host]} (safest)" for name, host in SAFEST.items()})
PALETTE = {"proposed": "#1b6ca8", "min": "#d1495b", "coordinate": "#2e933c", "proposed_enriched": "#e7298a",
           "proposed_guarded": "#0b3c61", "min_guarded": "#8a1f30", "coordinate_guarded": "#175c22",
           "proposed_layer_at_test": "#7f9db9", "min_layer_at_test": "#e3a1aa", "coordinate_layer_at_test": "#94c99c",
           "human": "#555555", "idm_mobil": "#8c5fbf", "idm_mobil_limits": "#e08a1e", "idm_limits": "#c9a227",
           "random": "#b08d57"}
# A safest network is drawn in its host's colour, paler.
PALETTE.update({name: PALETTE[host] + "99" for name, host in SAFEST.items()})

# The paper's test scenarios (Table 5), in its order; their traffic mix is what the runs logged
# (analysis/scenarios.py).
SCENARIOS = ("1", "2", "3", "4", "5")

METRIC_LABELS = {
    "episode_return": "Episode return",
    "avg_speed_kmh": "Mean speed (km/h)",
    "lane_changes": "Lane changes per episode",
    "overtakes": "Overtakes per episode",
    "collisions": "Collisions per episode",
    "dangerous_actions": "Dangerous actions per episode",
    "distance_m": "Distance per episode (m)",
    "loss": "TD loss",
    "epsilon": "Exploration epsilon",
    "steps_per_s": "Env steps per second",
}
METRIC_DIGITS = {"episode_return": 1, "avg_speed_kmh": 1, "lane_changes": 2, "overtakes": 2,
                 "collisions": 3, "dangerous_actions": 2, "distance_m": 0}


def model_label(model: str, short: bool = False) -> str:
    table = SHORT_LABELS if short else MODEL_LABELS
    return table.get(model, model)


def listed(items: list[str]) -> str:
    """'a', 'a and b', 'a, b and c': items as a sentence lists them."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def ordered_models(models: object) -> list[str]:
    """Known models in the paper's order first, then any user variant alphabetically."""
    present = {str(m) for m in pd.Series(list(models)).dropna().unique()}
    known = [m for m in MODEL_ORDER if m in present]
    return known + sorted(present - set(known))


def ordered_scenarios(scenarios: object) -> list[str]:
    present = {str(s) for s in pd.Series(list(scenarios)).dropna().unique() if str(s)}
    known = [s for s in SCENARIOS if s in present]
    return known + sorted(present - set(known))


# What a table or figure says where a method has no seed tested: under way while one of its trainings is stopped
# part-way (it resumes), else not run.
NOT_RUN = "not run"
UNDER_WAY = "under way"


def fmt(value: float, metric: str = "", digits: int | None = None) -> str:
    """The one number format used everywhere (tables, claims, tests compare against it)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    d = METRIC_DIGITS.get(metric, 2) if digits is None else digits
    if not math.isfinite(value):
        return f"{value:.{d}f}"
    # Half rounds away from zero, on the value cut to the digits a float32 holds: the same mean reached through
    # float32 metrics (0.62500006) and through float64 (0.625) then prints alike, where plain formatting gives
    # 0.63 and 0.62.
    whole = len(str(int(abs(value))))
    kept = Decimal(f"{value:.{max(6, whole + d)}g}")
    return f"{kept.quantize(Decimal(1).scaleb(-d), rounding=ROUND_HALF_UP):f}"


# What the simulator's parameters mean and their units (conf/simulator/highway.yaml), for the
# report's tables: the paper's symbols (Table 1) are not self-explanatory.
VEHICLE_PARAMETERS = {
    "a_lon": "a_lon: acceleration and braking of one action (m/s^2, eq. 2)",
    "v_lat": "v_lat: lateral speed of a lane change (m/s, eq. 3)",
    "r_lon": "r_lon: chance of a random longitudinal action per decision",
    "r_lat": "r_lat: chance of a random lane change per decision",
    "connected": "connected: sends V2X messages (appears in the HGM)",
    "length": "length (m)",
    "width": "width (m)",
    "lane_change_time_gap": "lane_change_time_gap: smallest gap accepted for a lane change (s)",
}
PARAMETER_UNITS = {
    "lane_width": "m", "v_min_kmh": "km/h", "v_max_kmh": "km/h", "decision_dt": "s", "physics_dt": "s",
    "episode_seconds": "s", "window_behind": "m", "window_ahead": "m", "density_per_km_per_lane": "veh/km/lane",
    "host_start_speed_kmh": "km/h", "safety.reaction_time": "s", "safety.emergency_decel": "m/s^2",
    "safety.min_gap": "m", "reward.dangerous_time_gap": "s",
}


def parameter_label(key: str) -> str:
    """`lane_width` -> `lane_width (m)`; keys without a unit stay as they are."""
    unit = PARAMETER_UNITS.get(key)
    return f"{key} ({unit})" if unit else key
