"""Figures and tables of the learner study (research/studies/learner_study.py), from its MLflow store.

Each run (training or evaluation) is matched to its arm through its logged config params.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
import yaml  # noqa: E402
from hydra import compose, initialize_config_dir  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402
from mlflow import MlflowClient  # noqa: E402
from omegaconf import DictConfig, OmegaConf  # noqa: E402
from study_arms import ARMS, ROOT, STUDY_REFERENCES  # noqa: E402

from analysis.stats import iqm_ci, mean_ci  # noqa: E402
from hgm_repro.contracts.names import current_key  # noqa: E402
from hgm_repro.contracts.train_key import TRAINING_GROUPS  # noqa: E402

# Training curves (with exploration) and the greedy validation return (no exploration, seeds no
# test uses): the second shows when a host has learned, the first how it explored.
CURVES = ("train/episode_return", "train/collisions", "train/avg_speed_kmh", "val/episode_return")
# The moving average's validation (arms with learner.ema_decay), drawn dashed beside the online network's.
EMA_CURVE = "val_ema/episode_return"
RESULTS = ("episode_return", "collisions", "dangerous_actions", "avg_speed_kmh", "lane_changes", "overtakes")


def _value(text: object) -> object:
    """A logged param or an override's value as plain data ('0.99' -> 0.99, 'True' -> True)."""
    value = yaml.safe_load(str(text))
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else value


def arm_signatures() -> dict[str, dict[str, object]]:
    """arm -> the value, in that arm's own config, of every key any arm overrides.

    Runs are matched on these values rather than on their train_key, so that runs made before a
    config field existed (the field's absence means its default) still count. Each arm's config is
    composed whole, because an arm that chooses another model (model=min) also changes the keys it
    does not name (min's `model.streams.hgm` is none); a config group is read by its choice's name."""
    keys = sorted({o.split("=", 1)[0] for overrides in ARMS.values() for o in overrides})
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        configs = {arm: compose("config", overrides=["experiment=quick", *overrides])
                   for arm, overrides in ARMS.items()}
    return {arm: {k: _value(_chosen(cfg, k)) for k in keys} for arm, cfg in configs.items()}


def _chosen(cfg: DictConfig, key: str) -> object:
    node = OmegaConf.select(cfg, key)
    return node.get("name") if isinstance(node, DictConfig) else node


def _steps_axis(ax: plt.Axes) -> None:
    # Thousands of steps: six-digit tick labels run into each other on a 160k-step run.
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k"))
    ax.set_xlabel("env steps")


def _arm_of(params: dict[str, str], signatures: dict[str, dict[str, object]]) -> str | None:
    for arm, signature in signatures.items():
        if all(_value(params[k]) == v if k in params else
               (_not_recorded_by_training(k) or v == signature_default(k, signatures))
               for k, v in signature.items()):
            return arm
    return None


def _not_recorded_by_training(key: str) -> bool:
    """A training run logs only the groups it depends on (not `eval.val_envs`, say): the absence of
    another group's value says nothing about the arm."""
    return key.partition(".")[0] not in TRAINING_GROUPS


def signature_default(key: str, signatures: dict[str, dict[str, object]]) -> object:
    return signatures["base"][key]


def load(stores: list[Path]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per-seed test results (learned arms and reference hosts) and learning curves of the stores."""
    signatures = arm_signatures()
    results, curves = [], []
    for store in stores:
        client = MlflowClient(tracking_uri=f"sqlite:///{store.resolve()}")
        experiment = client.get_experiment_by_name("hgm_repro")
        for r in client.search_runs([experiment.experiment_id], max_results=5000):
            tags = r.data.tags
            if r.info.status != "FINISHED" or "seed" not in tags:
                continue
            model = tags.get("model")
            params = {current_key(k): v for k, v in r.data.params.items()}  # stores of before issue 21 too
            params["model"] = model  # the model is a tag, not a param; arms that choose one are matched on it
            arm = model if model in STUDY_REFERENCES else _arm_of(params, signatures)
            if arm is None:
                continue
            seed = int(tags["seed"])
            if tags.get("stage") == "eval":
                # A test of another checkpoint (learner_study.py --also-best, --reselected) is its own row;
                # a reference host has no checkpoint, whatever the preset names.
                checkpoint = params.get("eval.checkpoint")
                if arm not in STUDY_REFERENCES and checkpoint in ("best", "ema", "reselected"):
                    arm = f"{arm}@{checkpoint}"
                results.append({"arm": arm, "seed": seed, **{m: r.data.metrics.get(f"eval/{m}") for m in RESULTS},
                                "evaluation_version": int(tags.get("evaluation_version", 1))})
            elif tags.get("stage") == "train":
                for m in (*CURVES, EMA_CURVE):
                    for point in client.get_metric_history(r.info.run_id, m):
                        curves.append({"arm": arm, "seed": seed, "metric": m, "step": point.step,
                                       "value": point.value})
    # A test made again after the evaluation fix (version 2: no blank frames) replaces the one before it;
    # the version stays with the row, so that a learned arm tested only before the fix is marked.
    tests = pd.DataFrame(results, columns=["arm", "seed", *RESULTS, "evaluation_version"])
    tests = tests.sort_values("evaluation_version", ascending=False, kind="stable")
    return (tests.drop_duplicates(["arm", "seed"]),
            pd.DataFrame(curves, columns=["arm", "seed", "metric", "step", "value"]))


def _colour(arm: str, curves: pd.DataFrame) -> str:
    """One colour per arm drawn in this report (arms that share a figure never share a colour)."""
    drawn = [a for a in ARMS if a in set(curves["arm"])]
    return f"C{drawn.index(arm) % 10}" if arm in drawn else "grey"


def _bar_count(grp: pd.DataFrame, results: pd.DataFrame) -> int:
    """Seeds on which the arm beats that seed's human-driven host on return with under 0.2 collisions
    per episode (issue 20's bar); 0 for the reference hosts."""
    human = results[results["arm"] == "human"].set_index("seed")["episode_return"]
    if grp["arm"].iloc[0] in STUDY_REFERENCES:
        return 0
    wins = [(r.seed in human.index) and r.episode_return > human[r.seed] and r.collisions < 0.2
            for r in grp.itertuples()]
    return int(sum(wins))


def earlier_results(per_seed_csv: Path | list[Path], arms: list[str]) -> pd.DataFrame:
    """The rows of `arms` from earlier reports' learner_study_per_seed.csv (or research/studies/budget_cut.py's CSV):
    an arm measured in another session (whose store is gone) stands beside the new ones in the table, from
    its committed numbers. Of several files, the first that has an (arm, seed) gives it."""
    paths = [per_seed_csv] if isinstance(per_seed_csv, Path | str) else list(per_seed_csv)
    earlier = pd.concat([pd.read_csv(path) for path in paths], ignore_index=True).drop_duplicates(["arm", "seed"])
    missing = sorted(set(arms) - set(earlier["arm"]))
    if missing:
        names = ", ".join(map(str, paths))
        raise SystemExit(f"{names} has no rows for {missing}; it has {sorted(set(earlier['arm']))}")
    kept = ["arm", "seed", *RESULTS, *(["evaluation_version"] if "evaluation_version" in earlier else [])]
    return earlier[earlier["arm"].isin(arms)][kept]


def _checkpoint_overrides(checkpoint: str) -> list[str]:
    """What an arm's `@checkpoint` suffix tested: `best80k` is best.pt among the passes up to 80k env steps
    (research/studies/budget_cut.py), the others are eval.checkpoint's own choices."""
    if not checkpoint:
        return []
    if checkpoint.startswith("best") and checkpoint != "best":
        return ["eval.checkpoint=best", f"(passes up to {checkpoint[4:]} env steps: research/studies/budget_cut.py)"]
    return [f"eval.checkpoint={checkpoint}"]


# The mark of a learned arm whose table row holds a test of evaluation version 1 (docs/interfaces.md).
BLANK_FRAME_MARK = " (blank-frame test)"


def _blank_frame_tested(arm: str, rows: pd.DataFrame) -> bool:
    """A learned arm with a seed tested only by the evaluation of before commit ff718f2, which handed its
    hosts blank frames (reference hosts read the simulator: their tests of any version are the same)."""
    return (arm not in STUDY_REFERENCES and "evaluation_version" in rows
            and bool((rows["evaluation_version"] == 1).any()))


def markdown_table(results: pd.DataFrame, summary: pd.DataFrame) -> str:
    """The study's table as research/study.md shows it: per seed `return, collisions`, the mean over seeds
    with its 95% CI and the IQM, the collisions with their CI, and the seeds that meet issue 20's bar.
    A learned arm with a blank-frame test (evaluation version 1) says so after its name."""
    seeds = sorted(results["seed"].unique())
    head = ["host", *map(str, seeds), "return: mean [95% CI], IQM", "collisions [95% CI]", "bar"]
    lines = ["| " + " | ".join(head) + " |", "| " + " | ".join(["---"] * (len(head) - 1) + ["---:"]) + " |"]
    per_seed = results.set_index(["arm", "seed"])
    for arm, row in summary.iterrows():
        cells = [f"`{arm}`" + (BLANK_FRAME_MARK if row["blank_frame_test"] else "")]
        for seed in seeds:
            hit = per_seed.loc[(arm, seed)] if (arm, seed) in per_seed.index else None
            cells.append("" if hit is None else f"{hit['episode_return']:.0f}, {hit['collisions']:.2f}")
        cells.append(f"{row['episode_return']:.0f} [{row['episode_return_lo']:.0f}, {row['episode_return_hi']:.0f}], "
                     f"{row['episode_return_iqm']:.0f}")
        cells.append(f"{row['collisions']:.2f} [{row['collisions_lo']:.2f}, {row['collisions_hi']:.2f}]")
        cells.append("" if arm in STUDY_REFERENCES else f"{row['seeds_beating_human_under_0.2']} of {row['seeds']}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def report(stores: list[Path], out: Path, earlier: pd.DataFrame | None = None) -> None:
    """Curves, the per-seed and summary CSVs and the Markdown table of `stores` into `out`; `earlier`
    (from `earlier_results`) adds (arm, seed) results measured before that the stores lack, for the table
    and CSVs only (no curves)."""
    out.mkdir(parents=True, exist_ok=True)
    results, curves = load(stores)
    if earlier is not None:  # an (arm, seed) in the store keeps the store's numbers (the first of duplicates)
        results = pd.concat([results, earlier], ignore_index=True)
    results = results.drop_duplicates(["arm", "seed"], keep="first").sort_values(["arm", "seed"])
    results.to_csv(out / "learner_study_per_seed.csv", index=False)
    rows = []
    for arm, grp in results.groupby("arm", sort=False):
        name, _, checkpoint = arm.partition("@")
        overrides = f"model={arm}" if arm in STUDY_REFERENCES else \
            " ".join(ARMS[name] + _checkpoint_overrides(checkpoint))
        row = {"arm": arm, "overrides": overrides, "seeds": len(grp), "blank_frame_test": _blank_frame_tested(arm, grp)}
        for m in RESULTS:
            est = mean_ci(grp[m].to_numpy(dtype=float))
            row[m] = est.point
            row[f"{m}_lo"], row[f"{m}_hi"] = est.low, est.high
        for m in ("episode_return", "collisions"):  # the interquartile mean: robust to one wild seed
            est = iqm_ci({"seeds": grp[m].to_numpy(dtype=float)})
            row[f"{m}_iqm"], row[f"{m}_iqm_lo"], row[f"{m}_iqm_hi"] = est.point, est.low, est.high
        row["seeds_beating_human_under_0.2"] = _bar_count(grp, results)
        rows.append(row)
    # Each arm's rows together: its own tests, then other tests of it (research/studies/budget_cut.py's ARM@best80k
    # before ARM@best120k: shorter names first); the reference hosts last.
    present = set(results["arm"])
    own = {arm: [arm, f"{arm}@best", f"{arm}@ema", f"{arm}@reselected"] for arm in ARMS}
    others = {arm: sorted((x for x in present - set(own[arm]) if x.partition("@")[0] == arm), key=lambda x: (len(x), x))
              for arm in ARMS}
    order = [a for arm in ARMS for a in (*own[arm], *others[arm]) if a in present] \
        + [a for a in STUDY_REFERENCES if a in present]
    summary = pd.DataFrame(rows).set_index("arm").reindex(order)
    summary.reset_index().to_csv(out / "learner_study_summary.csv", index=False)
    (out / "learner_study_table.md").write_text(markdown_table(results, summary))

    fig, axes = plt.subplots(1, len(CURVES), figsize=(4.6 * len(CURVES), 3.8))
    for ax, metric in zip(axes, CURVES, strict=True):
        sel = curves[curves["metric"] == metric]
        for arm in [a for a in ARMS if a in set(sel["arm"])]:
            by_step = sel[sel["arm"] == arm].groupby("step")["value"]
            mean = by_step.mean().rolling(1 if metric.startswith("val/") else 3, min_periods=1).mean()
            seeds = sel[sel["arm"] == arm]["seed"].nunique()
            # One colour per arm in every panel, whichever arms a panel has.
            ax.plot(mean.index, mean.values, color=_colour(arm, curves),
                    label=f"{arm} ({seeds} seed{'s' if seeds > 1 else ''})")
        _steps_axis(ax)
        ax.set_title(metric + (" (greedy)" if metric.startswith("val/") else " (epsilon-greedy)"))
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "learner_study_curves.png", dpi=110)
    validation_per_seed(results, curves, out / "learner_study_validation_per_seed.png")
    print(summary[["seeds", *RESULTS]].round(2).to_string())


def validation_per_seed(results: pd.DataFrame, curves: pd.DataFrame, path: Path) -> None:
    """One panel per seed: each arm's greedy validation return against env steps, beside the
    human-driven host's test return on that seed (the bar), so that one can read at what budget a
    training reaches it. Validation and test draw different traffic (seeds + 200000 and + 100000),
    so the line is a reference level, not the same episodes."""
    val = curves[curves["metric"] == "val/episode_return"]
    ema = curves[curves["metric"] == EMA_CURVE]
    seeds = sorted(val["seed"].unique())
    if not seeds:
        return
    fig, axes = plt.subplots(1, len(seeds), figsize=(4.2 * len(seeds), 3.6), sharey=True, squeeze=False)
    for ax, seed in zip(axes[0], seeds, strict=True):
        on_seed = val[val["seed"] == seed]
        for arm in [a for a in ARMS if a in set(on_seed["arm"])]:
            points = on_seed[on_seed["arm"] == arm].sort_values("step")
            ax.plot(points["step"], points["value"], marker=".", color=_colour(arm, curves), label=arm)
            averaged = ema[(ema["seed"] == seed) & (ema["arm"] == arm)].sort_values("step")
            if len(averaged):
                ax.plot(averaged["step"], averaged["value"], marker=".", linestyle="--",
                        color=_colour(arm, curves), label=f"{arm}, moving average")
        human = results[(results["arm"] == "human") & (results["seed"] == seed)]["episode_return"]
        if len(human):
            ax.axhline(float(human.iloc[0]), color="black", linestyle="--", linewidth=1,
                       label="human-driven host (test)")
        ax.set_title(f"seed {seed}")
        _steps_axis(ax)
    axes[0][0].set_ylabel("greedy validation return")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
