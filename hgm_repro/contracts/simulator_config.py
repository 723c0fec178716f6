"""Typed, validated parameters of the simulator and of a traffic scenario.

Everything the simulator needs comes through `SimulatorConfig` and `ScenarioConfig`; both are
checked when built, so a bad value fails before any step with a message that names the value
and what is allowed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from .errors import ConfigError, finite_number

HOST_TYPE = "HV"
KMH = 1.0 / 3.6


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise ConfigError(message)


@dataclass(frozen=True)
class VehicleType:
    """One row of the paper's Table 1, plus the body size and gap acceptance it leaves open."""

    name: str
    a_lon: float  # m/s^2, eq. 2
    v_lat: float  # m/s, eq. 3
    r_lon: float  # probability of a random longitudinal action per decision
    r_lat: float  # probability of a random lane change per decision
    connected: bool  # sends V2X data (appears in the HGM and the coordinate vector)
    length: float  # m
    width: float  # m
    lane_change_time_gap: float  # s: the smallest time gap it accepts in the target lane

    @classmethod
    def from_mapping(cls, name: str, raw: Mapping[str, Any]) -> VehicleType:
        where = f"simulator.vehicle_types.{name}"
        allowed = {f for f in cls.__dataclass_fields__ if f != "name"}
        unknown = set(raw) - allowed
        _require(not unknown, f"{where} has unknown field(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
        missing = allowed - set(raw)
        _require(not missing, f"{where} misses field(s) {sorted(missing)}")
        values = {k: (bool(v) if k == "connected" else finite_number(f"{where}.{k}", v)) for k, v in raw.items()}
        vt = cls(name=name, **values)
        _require(vt.a_lon > 0, f"{where}.a_lon={vt.a_lon} is not allowed: must be > 0 (m/s^2)")
        _require(vt.v_lat > 0, f"{where}.v_lat={vt.v_lat} is not allowed: must be > 0 (m/s)")
        for rate in ("r_lon", "r_lat"):
            r = getattr(vt, rate)
            _require(0.0 <= r <= 1.0, f"{where}.{rate}={r} is not allowed: a rate must lie in [0, 1]")
        _require(vt.length > 0 and vt.width > 0, f"{where}: length and width must be > 0")
        _require(vt.lane_change_time_gap >= 0, f"{where}.lane_change_time_gap must be >= 0")
        return vt


@dataclass(frozen=True)
class SafetyConfig:
    """The other vehicles' safe-speed rule (paper silent)."""

    reaction_time: float  # s
    emergency_decel: float  # m/s^2
    min_gap: float  # m bumper to bumper at standstill


@dataclass(frozen=True)
class RewardConfig:
    """Table 2's reward values and the thresholds Algorithm 2 leaves open."""

    collision: float
    dangerous: float
    lane_change: float
    overtake: float
    dangerous_time_gap: float  # s
    overtake_per_vehicle: bool


@dataclass(frozen=True)
class SimulatorConfig:
    """The highway (conf/simulator/highway.yaml: the one place of every value and its meaning)."""

    lanes: int
    lane_width: float
    v_min_kmh: float
    v_max_kmh: float
    decision_dt: float
    physics_dt: float
    episode_seconds: float
    window_behind: float
    window_ahead: float
    density_per_km_per_lane: float
    host_start_lane: int
    host_start_speed_kmh: float
    host_safety_layer: bool
    vehicle_types: tuple[VehicleType, ...]
    safety: SafetyConfig
    reward: RewardConfig
    name: str

    # Derived quantities, in SI units.
    @property
    def v_min(self) -> float:
        return self.v_min_kmh * KMH

    @property
    def v_max(self) -> float:
        return self.v_max_kmh * KMH

    @property
    def substeps(self) -> int:
        return int(round(self.decision_dt / self.physics_dt))

    @property
    def episode_decisions(self) -> int:
        return int(round(self.episode_seconds / self.decision_dt))

    @property
    def vehicles_per_lane(self) -> int:
        return max(1, int(round(self.density_per_km_per_lane * (self.window_behind + self.window_ahead) / 1000)))

    @property
    def n_vehicles(self) -> int:
        """Slots per env: the host (slot 0) and the other vehicles."""
        return self.lanes * self.vehicles_per_lane

    @property
    def type_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.vehicle_types)

    def type_index(self, name: str) -> int:
        if name not in self.type_names:
            raise ConfigError(f"unknown vehicle type {name!r}; allowed: {list(self.type_names)}")
        return self.type_names.index(name)

    @classmethod
    def from_mapping(cls, raw: Mapping[str, Any]) -> SimulatorConfig:
        raw = dict(raw)
        allowed = set(cls.__dataclass_fields__)
        unknown = set(raw) - allowed
        _require(not unknown, f"simulator has unknown field(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
        missing = allowed - set(raw)
        _require(not missing, f"simulator misses field(s) {sorted(missing)}: give the whole node "
                              "(conf/simulator/highway.yaml; config_files.simulator_config starts from it)")
        types_raw = raw.pop("vehicle_types", None)
        _require(bool(types_raw), "simulator.vehicle_types is empty: at least the host type 'HV' is needed")
        _require(HOST_TYPE in types_raw, f"simulator.vehicle_types lacks the host type {HOST_TYPE!r}")
        # The host's type comes first so that type index 0 always means the host.
        names = [HOST_TYPE] + [n for n in types_raw if n != HOST_TYPE]
        types = tuple(VehicleType.from_mapping(str(n), types_raw[n]) for n in names)
        safety_raw, reward_raw = dict(raw.pop("safety") or {}), dict(raw.pop("reward") or {})
        for group, sub, klass in (("safety", safety_raw, SafetyConfig), ("reward", reward_raw, RewardConfig)):
            unknown = set(sub) - set(klass.__dataclass_fields__)
            _require(not unknown, f"simulator.{group} has unknown field(s) {sorted(unknown)}; "
                                  f"allowed: {sorted(klass.__dataclass_fields__)}")
            missing = set(klass.__dataclass_fields__) - set(sub)
            _require(not missing, f"simulator.{group} misses field(s) {sorted(missing)}")
        safety = SafetyConfig(**{k: finite_number(f"simulator.safety.{k}", v) for k, v in safety_raw.items()})
        reward = RewardConfig(**{
            k: (bool(v) if k == "overtake_per_vehicle" else finite_number(f"simulator.reward.{k}", v))
            for k, v in reward_raw.items()})
        cfg = cls(vehicle_types=types, safety=safety, reward=reward, **raw)
        cfg.validate()
        return cfg

    def validate(self) -> None:
        _require(isinstance(self.lanes, int) and self.lanes >= 1,
                 f"simulator.lanes={self.lanes!r} is not allowed: need a whole number >= 1")
        for name in ("lane_width", "decision_dt", "physics_dt", "episode_seconds", "window_behind",
                     "window_ahead", "density_per_km_per_lane"):
            v = finite_number(f"simulator.{name}", getattr(self, name))
            _require(v > 0, f"simulator.{name}={v} is not allowed: must be > 0")
        _require(0 <= finite_number("simulator.v_min_kmh", self.v_min_kmh),
                 f"simulator.v_min_kmh={self.v_min_kmh} is not allowed: must be >= 0")
        _require(self.v_min_kmh < self.v_max_kmh,
                 f"simulator.v_min_kmh={self.v_min_kmh} >= v_max_kmh={self.v_max_kmh} is not allowed: "
                 "need v_min < v_max")
        ratio = self.decision_dt / self.physics_dt
        _require(abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1,
                 f"simulator.decision_dt={self.decision_dt} is not allowed: must be a whole multiple of "
                 f"physics_dt={self.physics_dt}")
        _require(isinstance(self.host_start_lane, int) and 0 <= self.host_start_lane < self.lanes,
                 f"simulator.host_start_lane={self.host_start_lane!r} is not allowed: need 0..{self.lanes - 1}")
        _require(self.v_min_kmh <= self.host_start_speed_kmh <= self.v_max_kmh,
                 f"simulator.host_start_speed_kmh={self.host_start_speed_kmh} is not allowed: "
                 f"need {self.v_min_kmh}..{self.v_max_kmh}")
        _require(self.safety.emergency_decel > 0 and self.safety.reaction_time > 0 and self.safety.min_gap >= 0,
                 "simulator.safety: emergency_decel and reaction_time must be > 0, min_gap >= 0")
        for t in self.vehicle_types:
            # The simulator tracks at most two lanes per vehicle (the one it leaves, the one it enters).
            _require(t.width < self.lane_width,
                     f"simulator.vehicle_types.{t.name}.width={t.width} is not allowed: must be narrower than "
                     f"lane_width={self.lane_width}")
        _require(self.reward.dangerous_time_gap >= 0, "simulator.reward.dangerous_time_gap must be >= 0")
        _require(self.vehicles_per_lane >= 2,
                 f"simulator.density_per_km_per_lane={self.density_per_km_per_lane} gives fewer than 2 vehicles "
                 "per lane in the window: raise the density or the window")


@dataclass(frozen=True)
class ScenarioConfig:
    """The traffic mix: the share of each non-host vehicle type among spawned vehicles (Table 5)."""

    name: str
    ratios: tuple[tuple[str, float], ...]

    @classmethod
    def from_mapping(cls, raw: Mapping[str, Any], simulator: SimulatorConfig) -> ScenarioConfig:
        name = str(raw.get("name", "?"))
        ratios_raw = raw.get("ratios")
        _require(isinstance(ratios_raw, Mapping) and len(ratios_raw) > 0,
                 f"scenario {name}: ratios must map vehicle types to shares, got {ratios_raw!r}")
        npc_types = [t for t in simulator.type_names if t != HOST_TYPE]
        ratios = []
        for type_name, share in ratios_raw.items():
            _require(type_name in npc_types,
                     f"scenario {name}: unknown vehicle type {type_name!r} in ratios; allowed: {npc_types}")
            s = finite_number(f"scenario.ratios.{type_name}", share)
            _require(s >= 0, f"scenario {name}: ratios.{type_name}={s} is not allowed: a share must be >= 0")
            ratios.append((str(type_name), s))
        total = sum(s for _, s in ratios)
        _require(abs(total - 1.0) < 1e-6,
                 f"scenario {name}: ratios sum to {total:g}, not 1 ({dict(ratios)}); the shares must sum to 1")
        return cls(name=name, ratios=tuple(ratios))

    def ratio_of(self, type_name: str) -> float:
        return dict(self.ratios).get(type_name, 0.0)
