"""The scale a set of runs was made at, beside the paper's, read from the runs' own resolved configs.

The report's first page and results.md both state it, once: a verdict means little without the
training budget, the image size and the number of test episodes behind it.
"""

from __future__ import annotations

from typing import Any

import pandas as pd
import yaml

from analysis.labels import GUARDED, LAYER_AT_TEST, SAFEST, listed, model_label, ordered_models

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


def scale_lines(configs: dict[str, str], evals: pd.DataFrame) -> list[str]:
    """One line per experiment preset of the learned models: which models, training steps, image size and
    frames, the checkpoint tested and the test episodes per cell, each beside the paper's."""
    parsed = _configs(configs)
    learned = {m: c for m, c in parsed.items() if c.get("model", {}).get("learned") and c.get("learner")}
    groups: dict[str, list[str]] = {}
    for model in ordered_models(learned):
        groups.setdefault(str(learned[model].get("experiment", {}).get("name", "unnamed preset")), []).append(model)
    lines = []
    for preset, models in groups.items():
        config = learned[models[0]]
        learner, obs = config.get("learner", {}), config.get("observation", {})
        part = [f"{preset} ({models_phrase(models)}): "
                f"{learner.get('total_steps', 0):,} training steps per seed (paper {PAPER_STEPS:,})",
                f"images {obs.get('height')}x{obs.get('width')}, {obs.get('frame_stack')} frames (paper 84x84, 4)",
                f"tested with the {config.get('eval', {}).get('checkpoint', 'final')} checkpoint (paper: the final "
                "network)"]
        episodes = _episodes(evals, models)
        if episodes:
            part.append(f"{episodes} test episodes per cell (paper: about 834)")
        lines.append("; ".join(part) + ".")
    if not lines and parsed:
        episodes = _episodes(evals, list(parsed))
        lines.append(f"{', '.join(presets(configs)) or 'unnamed preset'}: no learned model"
                     + (f"; {episodes} test episodes per cell." if episodes else "."))
    return lines or ["Scale unknown: the runs logged no config."]


# The forms of a method a preset may also run, in the words the first page lists them with.
FORMS = (("guarded", GUARDED), ("layer-at-test", LAYER_AT_TEST), ("safest", SAFEST))


def _method(model: str) -> str:
    """The method a form is of: 'proposed' for 'proposed_guarded_safest'."""
    for _, table in FORMS:
        if model in table:
            return _method(table[model])
    return model


def models_phrase(models: list[str]) -> str:
    """The models of a preset in few words: the methods by name and the forms of them it also ran by kind
    ('Proposed, Min, Coordinate and their guarded and safest forms') rather than one label each; a form whose
    method the preset did not run keeps its own label."""
    grouped = [m for m in models if _method(m) != m and _method(m) in models]
    named = [model_label(m, short=True) for m in models if m not in grouped]
    kinds = [kind for kind, table in FORMS if any(m in table for m in grouped)]
    if not kinds:
        return ", ".join(named)
    owners = list(dict.fromkeys(_method(m) for m in grouped))
    whose = "their" if len(owners) > 1 else "its" if len(named) == 1 else f"{model_label(owners[0], short=True)}'s"
    return f"{', '.join(named)} and {whose} {listed(kinds)} form{'' if len(grouped) == 1 else 's'}"


def _episodes(evals: pd.DataFrame, models: list[str]) -> str:
    """'48' or '4/8': the test episodes per cell of `models`."""
    if "n_episodes" not in evals or evals.empty:
        return ""
    rows = evals[evals["model"].isin(models)] if "model" in evals else evals
    return "/".join(str(n) for n in sorted({int(n) for n in rows["n_episodes"].dropna()}))
