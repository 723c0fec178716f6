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
    colour_limit: float = 1.0  # |value| of a vehicle at v_min or v_max: the colour scale's ends
    extent: tuple[float, float, float, float] = (0.0, 1.0, -1.0, 1.0)  # metres: left, right, behind, ahead
    host: np.ndarray | None = None  # H x W bool: the host's cells
    vehicles: np.ndarray | None = None  # H x W bool: cells of any connected vehicle
    lane_edges: tuple[float, ...] = ()  # lateral positions (m) of the lines between lanes


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
    from hgm_repro.envs.render import hgm_colour_limit
    from hgm_repro.observations import ObservationBuilder, decode_hgm, hyper_grid_matrix
    from hgm_repro.simulator import Action, HighwaySimulator

    sim_cfg = simulator_config()
    traffic = scenario_config(scenario, sim_cfg)
    sim = HighwaySimulator(sim_cfg, traffic, n_envs=1, seed=seed)
    obs_cfg = observation_config("proposed", frame_stack=1)
    builder = ObservationBuilder(sim, obs_cfg)
    builder.reset(None)
    keep = torch.full((1,), int(Action.NO_ACTION), dtype=torch.long)
    for _ in range(SNAPSHOT_STEPS):
        sim.step(keep)
    frame = builder.frame()
    # The enriched channels mark which cells hold a vehicle and which the host: under the paper's formula
    # a vehicle at the mid speed writes 0, the colour of an empty cell.
    ahead = obs_cfg.hgm_ahead or obs_cfg.v2x_range
    enriched = decode_hgm(hyper_grid_matrix(sim, height=obs_cfg.height, width=obs_cfg.width,
                                            v2x_range=obs_cfg.v2x_range, variant="enriched", encoded=True,
                                            ahead=obs_cfg.hgm_ahead)[0]).cpu().numpy()
    road = sim_cfg.lanes * sim_cfg.lane_width
    return ScenarioPicture(scenario, dict(traffic.ratios).get("NCV", 0.0), _to_hwc(frame["camera"][0, -3:]),
                           _to_hwc(frame["hgm"][0, -3:]), colour_limit=hgm_colour_limit(sim_cfg),
                           extent=(0.0, road, -obs_cfg.v2x_range, ahead), host=enriched[2] > 0,
                           vehicles=enriched[1] > 0,
                           lane_edges=tuple(k * sim_cfg.lane_width for k in range(1, sim_cfg.lanes)))


def scenario_pictures(scenarios: list[str], seed: int = 0) -> tuple[list[ScenarioPicture], str | None]:
    """Pictures for each scenario, or an empty list and a note saying why there are none."""
    try:
        return [_from_interfaces(s, seed) for s in scenarios], None
    except Exception as exc:  # noqa: BLE001 - any failure of code outside analysis/ means "skip"
        failure = f"{type(exc).__name__}: {exc}"[:200]
    return [], f"Pictures skipped: the observation code could not be used ({failure})."


def pictures_figure(pictures: list[ScenarioPicture], stem: Path) -> dict[str, Path]:
    """Camera frames on the top row; below them the HGMs in metres (forward is up, as in the camera), the
    colour scale fitted to the speeds a vehicle can have, connected vehicles outlined, the host in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analysis.figures import save

    n = len(pictures)
    fig, axes = plt.subplots(2, n, figsize=(2.1 * n + 1.4, 6.4), squeeze=False,
                             gridspec_kw={"height_ratios": [1.0, 1.35]})
    limit = max(p.colour_limit for p in pictures)
    im = None
    for col, pic in enumerate(pictures):
        top, bottom = axes[0, col], axes[1, col]
        top.imshow(pic.camera, interpolation="nearest")
        top.set_title(f"Scenario {pic.scenario}\nCV ratio {pic.cv_ratio:.2f}", fontsize=10)
        top.set_xticks([])
        top.set_yticks([])
        left, right, behind, ahead = pic.extent
        value = pic.hgm[..., 0].astype(float) / 127.5 - 1.0
        im = bottom.imshow(value, cmap="RdBu_r", vmin=-limit, vmax=limit, extent=pic.extent, aspect="auto",
                           interpolation="nearest")
        h, w = value.shape
        xs = left + (np.arange(w) + 0.5) * (right - left) / w
        ys = ahead - (np.arange(h) + 0.5) * (ahead - behind) / h  # row 0 is farthest ahead
        if pic.vehicles is not None and pic.vehicles.any():
            bottom.contour(xs, ys, pic.vehicles.astype(float), levels=[0.5], colors="k", linewidths=0.6)
        if pic.host is not None and pic.host.any():
            bottom.contour(xs, ys, pic.host.astype(float), levels=[0.5], colors="red", linewidths=1.4)
        for edge in pic.lane_edges:
            bottom.axvline(edge, color="0.7", lw=0.5, ls="--")
        bottom.set_xlabel("across the road (m)", fontsize=8)
        bottom.tick_params(labelsize=7)
        if col:
            bottom.set_yticklabels([])
    axes[0, 0].set_ylabel("front camera\n(looking forward)", fontsize=9)
    axes[1, 0].set_ylabel("HGM: along the road from the host (m)\n\u2191 forward", fontsize=9)
    cbar = fig.colorbar(im, ax=axes[1, :].tolist(), fraction=0.03, pad=0.02)
    cbar.set_label("cell value (v - v_mid) / v_mid", fontsize=8)
    cbar.ax.tick_params(labelsize=7)
    fig.text(0.01, 0.005, "HGM: red faster, blue slower than the mid speed; black outline = connected vehicle, "
             "red outline = the host; dashed = lane lines.", fontsize=7.5)
    return save(fig, stem, formats=("png", "pdf"))
