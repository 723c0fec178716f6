"""The paper's observations (front camera, Hyper-Grid Matrix, raw V2X coordinates) as pure,
batched functions of the simulator state, plus frame stacking.

The config is imported at once; the torch parts when first used, so that validating a job's
config (`hgm_repro.contracts.schema`) answers without loading torch.
"""

from importlib import import_module
from typing import Any

from ..contracts.observation_config import CAMERAS, HGM_VARIANTS, ObservationConfig

_LAZY = {
    "ObservationBuilder": ".builder", "coordinates": ".coordinates", "FrameStack": ".frame_stack",
    "birdseye_camera": ".birdseye_camera", "front_camera": ".front_camera",
    "decode_hgm": ".hyper_grid_matrix", "encode_hgm": ".hyper_grid_matrix",
    "hyper_grid_matrix": ".hyper_grid_matrix", "normalised_speed": ".hyper_grid_matrix",
    "v2x_senders": ".hyper_grid_matrix",
}

__all__ = [
    "CAMERAS", "FrameStack", "HGM_VARIANTS", "ObservationBuilder", "ObservationConfig", "birdseye_camera",
    "coordinates", "decode_hgm", "encode_hgm", "front_camera", "hyper_grid_matrix", "normalised_speed",
    "v2x_senders",
]


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    # All at once: importing a submodule binds its name here (`birdseye_camera`, `coordinates`,
    # `front_camera`, `hyper_grid_matrix` are both), and the functions of those names must win.
    modules = {module: import_module(module, __name__) for module in set(_LAZY.values())}
    for attr, module in _LAZY.items():
        globals()[attr] = getattr(modules[module], attr)
    return globals()[name]
