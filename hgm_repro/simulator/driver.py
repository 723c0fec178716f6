"""What drives a non-learning host, and the one rule for attaching it to a simulator.

A driver (`baselines.drivers`, reached through Hydra) has `.safety_layer` and `.act(sim)`;
whether the simulator's NPC safety layer and gap acceptance also guard the host is the
driver's choice, so attaching a driver sets it on the simulator.
"""

from __future__ import annotations

from typing import Protocol

import torch

from .highway import HighwaySimulator


class Driver(Protocol):
    safety_layer: bool

    def act(self, sim: HighwaySimulator) -> torch.Tensor: ...


def attach(driver: Driver, sim: HighwaySimulator) -> Driver:
    """Make the simulator guard the host exactly when the driver expects it to."""
    sim.host_safety_layer = bool(driver.safety_layer)
    return driver
