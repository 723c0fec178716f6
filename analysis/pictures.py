"""Hook for the report's pictures: one front-camera frame and one HGM per test scenario.

The pictures come from the project's own observation code (`HighwaySimulator` +
`ObservationBuilder`, reading `camera` and `hgm` from `.frame()`), never from the tracking store.
A failure is turned into a note for the report instead of an error, because the report must
still build when that code is broken.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

SNAPSHOT_STEPS = 20  # decisions driven before the picture, so traffic has spread around the host


@dataclass
class ScenarioPicture:
    scenario: str
    cv_ratio: float  # the connected-vehicle share of the scenario config it was drawn from
    camera: np.ndarray  # H x W x 3 uint8
    hgm: np.ndarray  # H x W x 3 uint8, as the network sees it (v in [-1, 1] stored as (v + 1) * 127.5)


def _to_hwc(img: Any) -> np.ndarray:
    arr = np.asarray(img.detach().cpu() if hasattr(img, "detach") else img)
    arr = arr.squeeze()
    if arr.ndim == 3 and arr.shape[0] in (1, 3) and arr.shape[-1] not in (1, 3):
        arr = np.moveaxis(arr[-3:] if arr.shape[0] >= 3 else arr, 0, -1)
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=-1)
    return arr.astype(np.uint8)


def _from_interfaces(scenario: str, seed: int) -> ScenarioPicture:
    import torch

    from hgm_repro.contracts.config_files import observation_config, scenario_config, simulator_config
    from hgm_repro.observations import ObservationBuilder
    from hgm_repro.simulator import Action, HighwaySimulator

    sim_cfg = simulator_config()
    traffic = scenario_config(scenario, sim_cfg)
    sim = HighwaySimulator(sim_cfg, traffic, n_envs=1, seed=seed)
    builder = ObservationBuilder(sim, observation_config("proposed", frame_stack=1))
    builder.reset(None)
    keep = torch.full((1,), int(Action.NO_ACTION), dtype=torch.long)
    for _ in range(SNAPSHOT_STEPS):
        sim.step(keep)
    frame = builder.frame()
    return ScenarioPicture(scenario, dict(traffic.ratios).get("NCV", 0.0), _to_hwc(frame["camera"][0, -3:]),
                           _to_hwc(frame["hgm"][0, -3:]))


def scenario_pictures(scenarios: list[str], seed: int = 0) -> tuple[list[ScenarioPicture], str | None]:
    """Pictures for each scenario, or an empty list and a note saying why there are none."""
    try:
        return [_from_interfaces(s, seed) for s in scenarios], None
    except Exception as exc:  # noqa: BLE001 - any failure of code outside analysis/ means "skip"
        failure = f"{type(exc).__name__}: {exc}"[:200]
    return [], f"Pictures skipped: the observation code could not be used ({failure})."


def pictures_figure(pictures: list[ScenarioPicture], stem: Path) -> dict[str, Path]:
    """Camera frames on the top row, HGMs (decoded to [-1, 1], diverging colours) below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analysis.figures import save

    n = len(pictures)
    fig, axes = plt.subplots(2, n, figsize=(2.0 * n + 1.0, 4.6), squeeze=False)
    for col, pic in enumerate(pictures):
        axes[0, col].imshow(pic.camera, interpolation="nearest")
        axes[0, col].set_title(f"Scenario {pic.scenario}\nCV {pic.cv_ratio:.2f}", fontsize=10)
        value = pic.hgm[..., 0].astype(float) / 127.5 - 1.0
        im = axes[1, col].imshow(value, cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
        for row in (0, 1):
            axes[row, col].set_xticks([])
            axes[row, col].set_yticks([])
    axes[0, 0].set_ylabel("front camera", fontsize=10)
    axes[1, 0].set_ylabel("HGM value", fontsize=10)
    fig.colorbar(im, ax=axes[1, :].tolist(), fraction=0.025, pad=0.02)
    return save(fig, stem, formats=("png", "pdf"))
