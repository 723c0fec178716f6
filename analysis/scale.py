"""The scale a set of runs was made at, beside the paper's, read from the runs' own resolved configs.

The report's first page and results.md both open with it: a verdict means little without the
training budget, the image size and the number of test episodes behind it.
"""

from __future__ import annotations

from typing import Any

import pandas as pd
import yaml

from analysis.labels import model_label

PAPER_STEPS = 1_000_000
SMOKE_PRESET = "smoke"


def _configs(configs: dict[str, str]) -> dict[str, dict[str, Any]]:
    parsed = {}
    for model, text in configs.items():
        try:
            parsed[model] = yaml.safe_load(text) or {}
        except yaml.YAMLError:
            parsed[model] = {}
    return parsed


def presets(configs: dict[str, str]) -> list[str]:
    """The experiment presets (`experiment.name`) the runs were made with."""
    return sorted({str(c.get("experiment", {}).get("name")) for c in _configs(configs).values()
                   if c.get("experiment", {}).get("name")})


def is_smoke(configs: dict[str, str]) -> bool:
    """Runs of the `smoke` preset: they prove that the pipeline runs and learn nothing."""
    return SMOKE_PRESET in presets(configs)


def scale_text(configs: dict[str, str], evals: pd.DataFrame) -> str:
    """Preset, training steps, image size and frames, the checkpoint tested and the test episodes
    per cell, each beside the paper's; from a learned model's config (the proposed one first)."""
    parsed = _configs(configs)
    config = parsed.get("proposed") or next((c for c in parsed.values() if c.get("model", {}).get("learned")),
                                            next(iter(parsed.values()), {}))
    learner, obs = config.get("learner", {}), config.get("observation", {})
    parts = []
    if learner:
        steps = learner.get("total_steps", 0)
        # A model trained at another budget (a variant published beside the grid) says so here.
        others = "".join(f", {model_label(m, short=True)} {c['learner']['total_steps']:,}"
                         for m, c in sorted(parsed.items()) if c.get("model", {}).get("learned")
                         and c.get("learner", {}).get("total_steps", steps) != steps)
        parts.append(f"preset `{', '.join(presets(configs)) or '?'}`: {steps:,} "
                     f"training steps per seed{others} (paper {PAPER_STEPS:,}), "
                     f"images {obs.get('height')}x{obs.get('width')} with {obs.get('frame_stack')} frames "
                     "(paper 84x84, 4)")
        parts.append(f"tested with the `{config.get('eval', {}).get('checkpoint', 'final')}` checkpoint "
                     "(paper: the final network)")
    if "n_episodes" in evals and not evals.empty:
        episodes = sorted({int(n) for n in evals["n_episodes"].dropna()})
        parts.append(f"{'/'.join(map(str, episodes))} test episodes per cell (paper: 200,000 decisions, "
                     "about 834 episodes)")
    return "; ".join(parts) + "." if parts else "scale unknown: the runs logged no config."
