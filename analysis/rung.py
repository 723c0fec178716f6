"""One rung of the scale ladder: the runs of one experiment preset, on their own.

It lives below both the ladder's tables (`analysis.ladder`) and its figure (`analysis.ladder_figure`), which
each read it, so that neither has to import the other to know what a rung is.
"""

from __future__ import annotations

import dataclasses

import pandas as pd

from analysis.claims import ClaimResult, evaluate_claims
from analysis.labels import LEARNED


@dataclasses.dataclass
class Rung:
    """One rung's runs: the learned methods' of its preset, the human-driven host's, and their curves."""

    name: str
    label: str
    evals: pd.DataFrame
    curves: pd.DataFrame
    episodes: pd.DataFrame
    runs: pd.DataFrame | None = None

    @property
    def ran(self) -> bool:
        return bool(self.evals["model"].isin(LEARNED).any())

    def claims(self) -> list[ClaimResult]:
        return evaluate_claims(self.evals, self.curves)
