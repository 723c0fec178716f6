"""Hook for the report's pictures: one front-camera frame and one HGM per test scenario.

The pictures come from the project's own observation code, never from the tracking store. Two
routes are tried, in order, and any failure is turned into a note for the report instead of an
error, because the report must still build while that code is being written or is broken:

1. `hgm_repro.show.scenario_snapshot(scenario: str, seed: int) -> {"camera": img, "hgm": img}`
   (img: HxWx3 uint8 array, or [3, H, W], or a PIL image);
2. the documented interfaces: `HighwaySimulator` + `ObservationBuilder(sim, ObservationConfig(...))`,
   reading `camera` and `hgm` from `.frame()` (uint8 [N, 3, H, W]).
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


def _from_show(scenario: str, seed: int) -> ScenarioPicture:
    from hgm_repro import show  # type: ignore[attr-defined]

    shot = show.scenario_snapshot(scenario, seed=seed)
    return ScenarioPicture(scenario, _to_hwc(shot["camera"]), _to_hwc(shot["hgm"]))


def _observation_settings() -> dict[str, Any]:
    import yaml

    from hgm_repro import CONF_DIR

    return dict(yaml.safe_load((Path(CONF_DIR) / "config.yaml").read_text()).get("observation", {}))


def _from_interfaces(scenario: str, seed: int) -> ScenarioPicture:
    import torch

    from hgm_repro.observations import ObservationBuilder, ObservationConfig  # type: ignore[attr-defined]
    from hgm_repro.simulator import Action, HighwaySimulator
    from hgm_repro.simulator.loading import scenario_config, simulator_config

    sim_cfg = simulator_config()
    sim = HighwaySimulator(sim_cfg, scenario_config(scenario, sim_cfg), n_envs=1, seed=seed)
    settings = _observation_settings()
    settings.update(camera="front", hgm="paper", coordinates=False, frame_stack=1)
    builder = ObservationBuilder(sim, ObservationConfig(**settings))
    builder.reset(None)
    keep = torch.full((1,), int(Action.NO_ACTION), dtype=torch.long)
    for _ in range(SNAPSHOT_STEPS):
        sim.step(keep)
    frame = builder.frame()
    return ScenarioPicture(scenario, _to_hwc(frame["camera"][0, -3:]), _to_hwc(frame["hgm"][0, -3:]))


def scenario_pictures(scenarios: list[str], seed: int = 0) -> tuple[list[ScenarioPicture], str | None]:
    """Pictures for each scenario, or an empty list and a note saying why there are none."""
    failures = []
    for route in (_from_show, _from_interfaces):
        try:
            return [route(s, seed) for s in scenarios], None
        except Exception as exc:  # noqa: BLE001 - any failure of code outside analysis/ means "skip"
            failures.append(f"{route.__name__.strip('_')}: {type(exc).__name__}: {exc}"[:200])
    return [], "Pictures skipped: the observation code could not be used (" + "; ".join(failures) + ")."


def pictures_figure(pictures: list[ScenarioPicture], stem: Path) -> dict[str, Path]:
    """Camera frames on the top row, HGMs (decoded to [-1, 1], diverging colours) below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analysis.figures import save
    from analysis.labels import CV_RATIO

    n = len(pictures)
    fig, axes = plt.subplots(2, n, figsize=(2.0 * n + 1.0, 4.6), squeeze=False)
    for col, pic in enumerate(pictures):
        axes[0, col].imshow(pic.camera, interpolation="nearest")
        ratio = CV_RATIO.get(pic.scenario)
        axes[0, col].set_title(f"Scenario {pic.scenario}" + (f"\nCV {ratio:.2f}" if ratio is not None else ""),
                               fontsize=10)
        value = pic.hgm[..., 0].astype(float) / 127.5 - 1.0
        im = axes[1, col].imshow(value, cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
        for row in (0, 1):
            axes[row, col].set_xticks([])
            axes[row, col].set_yticks([])
    axes[0, 0].set_ylabel("front camera", fontsize=10)
    axes[1, 0].set_ylabel("HGM value", fontsize=10)
    fig.colorbar(im, ax=axes[1, :].tolist(), fraction=0.025, pad=0.02)
    return save(fig, stem, formats=("png", "pdf"))
