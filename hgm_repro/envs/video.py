"""Episode videos from top-down frames: animated GIF always, MP4 when imageio-ffmpeg is present."""

from __future__ import annotations

import importlib.util
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from PIL import Image

from ..simulator.driver import Driver, attach
from ..simulator.highway import HighwaySimulator
from .render import render_top_down

Policy = Callable[[HighwaySimulator], torch.Tensor]
# draws env `env_index` of the simulator as it is now: (sim, env_index, action, caption) -> [h, w, 3] uint8
Render = Callable[[HighwaySimulator, int, "int | None", "str | None"], np.ndarray]


def save_episode(frames: Sequence[np.ndarray], path: str | Path, fps: float = 4.0) -> Path:
    """Write `frames` ([h, w, 3] uint8 each) to `path`: GIF for .gif, MP4 for .mp4.

    Pillow's GIF writer merges consecutive identical frames into one longer frame, so a GIF of
    a still scene may hold fewer frames than given (its play time is unchanged)."""
    path = Path(path)
    if not frames:
        raise ValueError("save_episode got no frames")
    arrays = [np.ascontiguousarray(f, dtype=np.uint8) for f in frames]
    if any(a.ndim != 3 or a.shape[-1] != 3 for a in arrays):
        raise ValueError(f"frames must be [h, w, 3] RGB arrays, got shapes {sorted({a.shape for a in arrays})}")
    suffix = path.suffix.lower()
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".gif":
        images = [Image.fromarray(a) for a in arrays]
        # Milliseconds per frame; GIF stores hundredths of a second, so very high fps is capped.
        duration = max(20, int(round(1000.0 / fps)))
        images[0].save(path, save_all=True, append_images=images[1:], duration=duration, loop=0)
    elif suffix == ".mp4":
        if importlib.util.find_spec("imageio_ffmpeg") is None:
            raise RuntimeError(f"cannot write {path}: MP4 needs the imageio-ffmpeg package, which is not "
                               "installed; install it or save as .gif")
        import imageio.v2 as imageio

        # H.264 wants even sizes: pad with the last row/column instead of letting ffmpeg rescale.
        h, w = arrays[0].shape[:2]
        pad = ((0, h % 2), (0, w % 2), (0, 0))
        with imageio.get_writer(path, fps=fps, macro_block_size=1) as writer:
            for a in arrays:
                writer.append_data(np.pad(a, pad, mode="edge"))
    else:
        raise ValueError(f"unsupported video suffix {path.suffix!r} for {path}: use .gif or .mp4")
    return path


def record_episode(sim: HighwaySimulator, driver_or_policy: Driver | Policy, path: str | Path,
                   max_decisions: int | None = None, env_index: int = 0, fps: float | None = None,
                   render: Render | None = None, **render_kwargs: Any) -> dict[str, float]:
    """Reset `sim`, drive it with a driver (`.act(sim)`, its safety layer attached) or a policy
    (a callable `sim -> LongTensor[N]` of actions) until env `env_index` ends its episode or
    `max_decisions` pass, save the video of that env to `path`, and return its metrics.

    One frame per state: frame t shows the state after t decisions, the decision taken in it
    (none on the last frame) and what happened in the step into it (a collision, an overtake).
    So a video of d decisions has d + 1 frames. All envs of `sim` step together (the simulator
    is batched); only `env_index` is filmed. `fps` defaults to twice real time. `render` draws a
    frame (default: the top-down view, `render_top_down` with `render_kwargs`); it is called right
    after the policy chose, so it may show what the policy saw.
    """
    act: Policy
    if hasattr(driver_or_policy, "act"):
        act = attach(driver_or_policy, sim).act
    elif callable(driver_or_policy):
        act = driver_or_policy
    else:
        raise TypeError(f"record_episode needs a driver with .act(sim) or a callable policy, "
                        f"got {type(driver_or_policy).__name__}")
    if render is None:
        def render(sim_: HighwaySimulator, env: int, action: int | None, caption: str | None) -> np.ndarray:
            return render_top_down(sim_, env, action=action, caption=caption, **render_kwargs)

    limit = sim.config.episode_decisions if max_decisions is None else int(max_decisions)
    sim.reset()
    frames: list[np.ndarray] = []
    metrics: dict[str, float] = {}
    caption: str | None = None
    for _ in range(limit):
        action = act(sim)
        frames.append(render(sim, env_index, int(action[env_index]), caption))
        result = sim.step(action)
        # The NPC a crashed host hit is gone from the road at once (it respawns), so say so in words.
        events = [name for name, flag in (("COLLISION", result.collision), ("dangerous", result.dangerous),
                                          ("overtake", result.overtakes > 0)) if bool(flag[env_index])]
        caption = " ".join(events) or None
        metrics = {k: float(v[env_index]) for k, v in result.episode.items()}
        if bool(result.done[env_index]):
            break
    frames.append(render(sim, env_index, None, caption))
    save_episode(frames, path, fps=fps if fps is not None else 2.0 / sim.config.decision_dt)
    return metrics
