"""One rung of the scale ladder: the runs of one experiment preset, on their own.

It lives below both the ladder's tables (`analysis.ladder`) and its figure (`analysis.ladder_figure`), which
each read it, so that neither has to import the other to know what a rung is.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection

import pandas as pd

from analysis.claims import ClaimResult, evaluate_claims
from analysis.labels import LEARNED, NOT_RUN, UNDER_WAY


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


def absence(rung: str, going: Collection[tuple[str, str]], model: str | None = None) -> str:
    """What a rung, or one method on it, with no seed tested reads: "under way" where `going` (pairs of rung
    and method whose training has started and stopped, as `analysis.ladder.under_way` finds them) holds it,
    else "not run"."""
    started = any(name == rung and (model is None or method == model) for name, method in going)
    return UNDER_WAY if started else NOT_RUN
