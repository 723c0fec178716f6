"""Table 3's network shape for code that needs it without a Hydra config (the networks' default
arguments, the observation check of the smallest image), read from its one definition:
conf/model/network/table3.yaml, which the proposed, Min and Coordinate model configs include."""

from __future__ import annotations

from collections.abc import Sequence

from .conf_dir import load_yaml

_TABLE3 = load_yaml("model/network", "table3")

# [filters, kernel, stride] of each conv layer (no padding).
PAPER_CONV: list[list[int]] = [[int(v) for v in layer] for layer in _TABLE3["conv"]]
# The two dense layers of each dueling head.
PAPER_HIDDEN: list[int] = [int(h) for h in _TABLE3["hidden"]]


def conv_stack_output(side: int, conv: Sequence[Sequence[int]] = PAPER_CONV) -> int:
    """Spatial size after the conv stack (no padding), to explain a too-small image."""
    for _filters, kernel, stride in conv:
        side = (side - int(kernel)) // int(stride) + 1
    return side


def smallest_image_side(conv: Sequence[Sequence[int]] = PAPER_CONV) -> int:
    """The smallest image side the conv stack maps to at least one pixel (36 for Table 3)."""
    side = 1
    while conv_stack_output(side, conv) < 1:
        side += 1
    return side


MIN_IMAGE_SIDE = smallest_image_side()
