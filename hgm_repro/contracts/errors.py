"""The errors every floor raises for bad input, and the exit code a command gives for them."""

from __future__ import annotations

import math
from typing import Any

# Like argparse: the command line (a config, a store, a checkpoint) asked for something this run
# cannot use. Scripts and sweeps tell a refused input from a crash by it.
BAD_INPUT_EXIT = 2


class ConfigError(ValueError):
    """A configuration value is outside what the part that reads it accepts."""


def finite_number(where: str, value: Any) -> float:
    """`value` as a float, or a ConfigError naming `where` when it is not a finite number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where}={value!r} is not allowed: expected a finite number")
    return float(value)
