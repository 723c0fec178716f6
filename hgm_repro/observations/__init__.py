"""The paper's observations (front camera, Hyper-Grid Matrix, raw V2X coordinates) as pure,
batched functions of the simulator state, plus frame stacking."""

from .birdseye_camera import birdseye_camera
from .builder import ObservationBuilder
from .config import CAMERAS, HGM_VARIANTS, ObservationConfig
from .coordinates import coordinates
from .frame_stack import FrameStack
from .front_camera import front_camera
from .hyper_grid_matrix import decode_hgm, encode_hgm, hyper_grid_matrix, normalised_speed, v2x_senders

__all__ = [
    "CAMERAS", "FrameStack", "HGM_VARIANTS", "ObservationBuilder", "ObservationConfig", "birdseye_camera",
    "coordinates", "decode_hgm", "encode_hgm", "front_camera", "hyper_grid_matrix", "normalised_speed",
    "v2x_senders",
]
