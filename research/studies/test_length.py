"""How much of one seed's comparison with the human-driven host the test decides: trained networks and
the human-driven host re-tested with a longer test than their preset's, in the same scenario and test
traffic, no training.

    python research/studies/test_length.py --runs research/studies/runs/variants/proposed_enriched \
        --model proposed_enriched \
        --overrides experiment=quick160 --scenario 3 --seeds 0 1 2 3 4 --steps 38400 --out research/study/test_length

`--runs` is the folder a publish script trained in (its `checkpoints/<train_key>/`). Each seed's network
(the checkpoint the preset tests, `eval.checkpoint`) and the human-driven host drive `--steps` test
decisions; the first episodes of each env are the preset's own test (episode k of an env always starts
from the same traffic, whatever the test's length), so the table sets each seed's margin, with its
95% bootstrap interval over test episodes, from the preset's test beside the one from the longer test.
It writes `episodes.csv` (every episode, with `test` = preset or long) and `margins.csv` to --out.
The seeds are result seeds only when the networks are the published ones: this re-tests, never trains
or chooses anything, so it cannot tune on them.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = "human"


def _job(model: str, seed: int, scenario: str, overrides: list[str], steps: int | None):  # -> JobConfig
    from hydra import compose, initialize_config_dir

    from hgm_repro.contracts.conf_dir import CONF_DIR
    from hgm_repro.contracts.schema import check_config

    extra = [f"eval.test_steps={steps}"] if steps else []
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[f"model={model}", f"seed={seed}", f"scenario='{scenario}'", *overrides,
                                           *extra])
    return check_config(cfg)


def _checkpoint(runs: Path, job) -> Path | None:  # noqa: ANN001 - a JobConfig
    from hgm_repro.contracts.checkpoint import BEST_CHECKPOINT, EMA_CHECKPOINT, FINAL_CHECKPOINT
    from hgm_repro.contracts.train_key import train_key

    if not job.model.learned:
        return None
    name = {"best": BEST_CHECKPOINT, "ema": EMA_CHECKPOINT, "final": FINAL_CHECKPOINT}[job.eval.checkpoint]
    path = runs / "checkpoints" / train_key(job) / name
    if not path.is_file():
        raise SystemExit(f"test_length.py: no {name} for {job.model.name} seed {job.seed} at {path}: train it first "
                         "(the publish script that made --runs), or name the folder it trained in")
    return path


def _test(args: tuple[Path, str, int, str, list[str], int]) -> pd.DataFrame:
    runs, model, seed, scenario, overrides, steps = args
    from hgm_repro.evaluation.episodes import episodes_per_env, evaluate

    preset = _job(model, seed, scenario, overrides, None)
    job = _job(model, seed, scenario, overrides, steps)
    result = evaluate(job, job.scenario, _checkpoint(runs, job))
    first = episodes_per_env(preset.eval.test_steps, preset.eval.test_envs, job.simulator.episode_decisions)
    episodes = result.episodes.assign(model=model, scenario=scenario, seed=seed)
    episodes["test"] = ["preset" if k < first else "long" for k in episodes["episode"]]
    print(f"tested {model} seed {seed}: {len(episodes)} episodes ({first} per env are the preset's test)", flush=True)
    return episodes


def margins(episodes: pd.DataFrame) -> pd.DataFrame:
    """Each seed's margin over the human-driven host with its test-noise interval, for the preset's test
    (its episodes alone) and the whole longer test."""
    from analysis.tables import seed_margins

    parts = []
    for test, chosen in (("preset", episodes[episodes["test"] == "preset"]), ("long", episodes)):
        cells = chosen.groupby(["model", "scenario", "seed"], as_index=False)[["episode_return", "collisions"]].mean()
        table = seed_margins(cells, chosen, reference=REFERENCE)
        counts = chosen.groupby(["model", "seed"]).size().rename("episodes").reset_index()
        parts.append(table.merge(counts, on=["model", "seed"]).assign(test=test))
    return pd.concat(parts, ignore_index=True)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=Path, required=True, help="the folder the networks trained in (checkpoints/)")
    p.add_argument("--model", required=True, help="the learned model to re-test (a conf/model name)")
    p.add_argument("--overrides", nargs="*", default=[], help="the Hydra overrides it trained with")
    p.add_argument("--scenario", default="3")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    p.add_argument("--steps", type=int, default=38400, help="test decisions (the quick presets test 9,600)")
    p.add_argument("--jobs", type=int, default=2, help="tests at once (one core each)")
    p.add_argument("--out", type=Path, default=ROOT / "research" / "study" / "test_length")
    a = p.parse_args(argv)
    if a.steps <= 0:
        p.error(f"--steps {a.steps}: a test needs at least one decision")
    if not (a.runs / "checkpoints").is_dir():
        p.error(f"--runs {a.runs}: no checkpoints/ folder there; name the folder a publish script trained in")
    tasks = [(a.runs.resolve(), m, s, a.scenario, a.overrides, a.steps) for s in a.seeds for m in (a.model, REFERENCE)]
    with ProcessPoolExecutor(max_workers=a.jobs) as pool:
        episodes = pd.concat(list(pool.map(_test, tasks)), ignore_index=True)
    a.out.mkdir(parents=True, exist_ok=True)
    episodes.to_csv(a.out / "episodes.csv", index=False, float_format="%.6g")
    table = margins(episodes)
    table.to_csv(a.out / "margins.csv", index=False, float_format="%.6g")
    shown = table[table["model"] == a.model][["test", "seed", "episodes", "episode_return", "ref_return", "margin",
                                              "margin_low", "margin_high", "collisions", "beating", "close"]]
    print(shown.round(2).to_string(index=False))
    for test, part in shown.groupby("test", sort=False):
        print(f"{test}: the bar on {int(part['beating'].sum())} of {len(part)} seeds, {int(part['close'].sum())} close")


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    main()
