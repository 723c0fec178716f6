"""The crash anatomy of a learned host over several seeds: `research/studies/plateau.py`'s outputs, one folder
per seed, read together into one table and one figure.

    python research/studies/plateau.py --checkpoint CKPT_OF_SEED --overrides experiment=quick seed=S \
        --out DIR/S   # each seed
    python research/studies/crash_anatomy.py DIR/100 DIR/101 ... --out research/study/r20

Writes `crash_anatomy.csv` (per seed: collisions per episode by kind, tailgating per episode, the
greedy return over the episodes that ended, and how many crash partners each sensor showed a decision
before) and `crash_anatomy.png` (the crashes of every seed by kind and by what showed the partner).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

SEEN_BY = ("HGM and camera", "camera only", "HGM only", "neither")


def _seen_by(row: pd.Series) -> str:
    """What showed the partner a decision before the crash (the HGM: connected vehicles; the front
    camera: vehicles wholly ahead of the host)."""
    hgm, camera = bool(row["partner_connected"]), bool(row["partner_in_camera"])
    return SEEN_BY[0] if hgm and camera else SEEN_BY[1] if camera else SEEN_BY[2] if hgm else SEEN_BY[3]


def anatomy(folders: list[Path]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per-seed rates (one row per folder) and every learned host's crash (one row each)."""
    rates, crashes = [], []
    for folder in folders:
        summary = json.loads((folder / "plateau_summary.json").read_text())["learned"]
        table = pd.read_csv(folder / "plateau_collisions.csv")
        table = table[table["host"] == "learned"].copy()
        table["seed"] = folder.name
        table["seen_by"] = table.apply(_seen_by, axis=1) if len(table) else []
        crashes.append(table)
        row = {"seed": folder.name, "collisions_per_episode": summary["collisions"],
               **{k.replace("collision/", "collisions_"): v for k, v in summary.items() if k.startswith("collision/")},
               "tailgating_per_episode": summary["dangerous/tailgating"],
               "avg_speed_kmh": summary["avg_speed_kmh"], "episode_return": summary["episode_return"],
               **{f"partner_seen_by_{s.replace(' ', '_')}": int((table["seen_by"] == s).sum()) for s in SEEN_BY}}
        rates.append(row)
    return pd.DataFrame(rates), pd.concat(crashes, ignore_index=True)


def figure(crashes: pd.DataFrame, path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    for ax, column, title in ((axes[0], "kind", "host crashes by kind"),
                              (axes[1], "seen_by", "what showed the crash partner a decision before")):
        counts = crashes.groupby(["seed", column]).size().unstack(fill_value=0)
        counts.plot.bar(stacked=True, ax=ax, rot=0)
        ax.set(title=title, xlabel="tuning seed", ylabel="crashes in 16 envs x 960 decisions")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folders", nargs="+", type=Path, help="plateau.py --out folders, one per seed (named by the seed)")
    p.add_argument("--out", type=Path, default=Path("research/study"))
    args = p.parse_args(argv)
    missing = [str(f) for f in args.folders if not (f / "plateau_summary.json").is_file()]
    if missing:
        p.error(f"no plateau.py output (plateau_summary.json) in {missing}: "
                "run research/studies/plateau.py --out there first")
    rates, crashes = anatomy(args.folders)
    args.out.mkdir(parents=True, exist_ok=True)
    rates.to_csv(args.out / "crash_anatomy.csv", index=False, float_format="%.4g")
    figure(crashes, args.out / "crash_anatomy.png")
    print(rates.to_string(index=False))


if __name__ == "__main__":
    main()
