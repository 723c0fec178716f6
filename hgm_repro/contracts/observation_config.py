"""What the observation builders make: which streams, at which size, with which camera.

Built from two Hydra nodes: the root config's `observation` node (sizes, ranges, camera
optics) and the model's `streams` node (which streams the network reads). Every value is
checked here, so a bad one fails before the first frame with a message naming it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from .config_tree import plain
from .simulator_config import finite_number
from .table3 import MIN_IMAGE_SIDE, PAPER_CONV, conv_stack_output

CAMERAS = ("front", "birdseye", "none")
HGM_VARIANTS = ("paper", "enriched", "none")
HGM_HOST_CELLS = ("paper", "own_range")
# The model's `streams` node: which observations its network reads.
STREAM_KEYS = ("camera", "hgm", "coordinates")


def _mapping(node: Any, what: str) -> dict[str, Any]:
    node = plain(node)
    if node is None:
        return {}
    if not isinstance(node, Mapping):
        raise ValueError(f"expected a mapping for {what}, got {type(node).__name__}: {node!r}")
    return dict(node)


def _positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"observation.{name}={value!r} is not allowed: expected a whole number")
    return value


@dataclass(frozen=True)
class ObservationConfig:
    """Which observation streams to build and how (see docs/interfaces.md)."""

    # No defaults here: the one place of each value is the root config's `observation` node
    # (conf/config.yaml) and the model's `streams` node; `config_files.observation_config` builds
    # one from them for code that runs without Hydra.
    camera: str  # front | birdseye | none
    hgm: str  # paper | enriched | none
    coordinates: bool  # the Coordinate method's raw V2X vector
    height: int  # camera and HGM share height and width (one shared conv stack)
    width: int
    frame_stack: int
    v2x_range: float  # D_r, m (Algorithm 1)
    hgm_ahead: float  # m the HGM reaches ahead of the host (0: D_r, the paper's symmetric window)
    hgm_host_cell: str  # paper | own_range (see hyper_grid_matrix.host_cell_values)
    coord_k: int  # K nearest connected vehicles in the coordinate vector
    camera_fov_deg: float  # horizontal field of view
    camera_height: float  # m above the road
    camera_pitch_deg: float  # downward aim (shifted-lens model: the horizon moves up)
    vehicle_height: float  # m; every vehicle's box height in the camera
    camera_max_range: float  # m; vehicles farther ahead are not drawn

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        if self.camera not in CAMERAS:
            raise ValueError(f"observation camera={self.camera!r} is not allowed; allowed: {list(CAMERAS)}")
        if self.hgm not in HGM_VARIANTS:
            raise ValueError(f"observation hgm={self.hgm!r} is not allowed; allowed: {list(HGM_VARIANTS)}")
        if not isinstance(self.coordinates, bool):
            raise ValueError(f"observation coordinates={self.coordinates!r} is not allowed: expected true/false")
        for name in ("height", "width"):
            side = _positive_int(name, getattr(self, name))
            if side < MIN_IMAGE_SIDE:
                raise ValueError(
                    f"observation.{name}={side} is not allowed: Table 3's conv stack (kernel/stride "
                    f"{', '.join(f'{k}/{st}' for _f, k, st in PAPER_CONV)}) needs at least "
                    f"{MIN_IMAGE_SIDE} pixels (it would output {conv_stack_output(side)})")
        if _positive_int("frame_stack", self.frame_stack) < 1:
            raise ValueError(f"observation.frame_stack={self.frame_stack} is not allowed: need >= 1")
        if _positive_int("coord_k", self.coord_k) < 1:
            raise ValueError(f"observation.coord_k={self.coord_k} is not allowed: need >= 1")
        if finite_number("observation.v2x_range", self.v2x_range) <= 0:
            raise ValueError(f"observation.v2x_range={self.v2x_range} is not allowed: need > 0 (m)")
        if finite_number("observation.hgm_ahead", self.hgm_ahead) < 0:
            raise ValueError(f"observation.hgm_ahead={self.hgm_ahead} is not allowed: need >= 0 (m; 0 = v2x_range)")
        if self.hgm_host_cell not in HGM_HOST_CELLS:
            raise ValueError(f"observation hgm_host_cell={self.hgm_host_cell!r} is not allowed; allowed: "
                             f"{list(HGM_HOST_CELLS)}")
        fov = finite_number("observation.camera_fov_deg", self.camera_fov_deg)
        if not 1.0 <= fov <= 170.0:
            raise ValueError(f"observation.camera_fov_deg={fov} is not allowed: need 1..170 degrees "
                             "(a pinhole camera cannot see 180 degrees)")
        if finite_number("observation.camera_height", self.camera_height) <= 0:
            raise ValueError(f"observation.camera_height={self.camera_height} is not allowed: need > 0 (m)")
        pitch = finite_number("observation.camera_pitch_deg", self.camera_pitch_deg)
        if not 0.0 <= pitch <= 45.0:
            raise ValueError(f"observation.camera_pitch_deg={pitch} is not allowed: need 0..45 degrees (down)")
        if finite_number("observation.vehicle_height", self.vehicle_height) <= self.camera_height:
            raise ValueError(f"observation.vehicle_height={self.vehicle_height} is not allowed: must exceed "
                             f"camera_height={self.camera_height} (the camera's occlusion rule needs every vehicle "
                             "to reach above the camera)")
        if finite_number("observation.camera_max_range", self.camera_max_range) <= 0:
            raise ValueError(f"observation.camera_max_range={self.camera_max_range} is not allowed: need > 0 (m)")

    @property
    def keys(self) -> tuple[str, ...]:
        """The observation keys the streams ask for, in a fixed order."""
        out = []
        if self.camera != "none":
            out.append("camera")
        if self.hgm != "none":
            out.append("hgm")
        if self.coordinates:
            out.append("coordinates")
        return tuple(out)

    @classmethod
    def from_config(cls, observation_node: Any, streams_node: Any = None) -> ObservationConfig:
        """From the root config's `observation` node and the model's `streams` node
        (plain dicts or OmegaConf DictConfigs)."""
        obs = _mapping(observation_node, "observation")
        streams = _mapping(streams_node, "model.streams")
        stream_keys = set(STREAM_KEYS)
        allowed_obs = {f.name for f in fields(cls)} - stream_keys
        unknown = set(obs) - allowed_obs - stream_keys
        if unknown:
            raise ValueError(f"observation has unknown field(s) {sorted(unknown)}; allowed: {sorted(allowed_obs)}")
        unknown = set(streams) - stream_keys
        if unknown:
            raise ValueError(f"model.streams has unknown field(s) {sorted(unknown)}; "
                             "allowed: ['camera', 'coordinates', 'hgm']")
        merged = {**obs, **streams}
        missing = allowed_obs - set(obs)
        if missing:
            raise ValueError(f"observation misses field(s) {sorted(missing)}: give the whole node "
                             "(conf/config.yaml's `observation`; config_files.observation_config fills it)")
        missing = stream_keys - set(merged)
        if missing:
            raise ValueError(f"model.streams misses field(s) {sorted(missing)}: every model names its streams "
                             "(camera, hgm, coordinates)")
        # YAML may spell "no stream" as null or false.
        for key in ("camera", "hgm"):
            if merged[key] in (None, False):
                merged[key] = "none"
        if merged["coordinates"] is None:
            merged["coordinates"] = False
        return cls(**merged)
