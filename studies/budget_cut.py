"""What a shorter training's best.pt would have been: for a study arm's trainings that kept their
validation passes, the pass with the best validation return among those at or before each budget,
tested as the study tests (training traffic, the preset's test). Nothing is trained.

    python studies/budget_cut.py --checkpoints studies/runs/checkpoints --arm r20_all_160k \
        --seeds 100 101 102 103 104 --budgets 80000 120000 --out docs/study/r20_paper160/budget_cut.csv

One 160k-step training then answers for 80k and 120k too, at the cost of a test per budget. It is close
to, not the same as, a training that stops at the budget: every schedule of the quick presets is in
absolute steps except prioritized replay's importance-sampling exponent (beta), which anneals over the
whole run, so at 80k steps of a 160k run it is half-way where an 80k run's is at its end. The rows are
named `ARM@bestNk` in the learner study's per-seed format, so that `learner_study.py report --earlier
FILE --earlier-arms ARM@best80k` puts them in its table beside the arm's own best.pt.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd
from study_arms import ARMS

RESULTS = ("episode_return", "collisions", "dangerous_actions", "avg_speed_kmh", "lane_changes", "overtakes")


def cut_name(arm: str, budget: int) -> str:
    """The per-seed row name of `arm`'s best pass at or before `budget` env steps."""
    return f"{arm}@best{budget // 1000}k" if budget % 1000 == 0 else f"{arm}@best{budget}"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoints", type=Path, required=True, help="the study store's checkpoints/ folder")
    p.add_argument("--arm", required=True, choices=sorted(ARMS))
    p.add_argument("--seeds", nargs="+", type=int, required=True)
    p.add_argument("--budgets", nargs="+", type=int, required=True, help="env steps to cut the trainings at")
    p.add_argument("--out", type=Path, required=True, help="the per-seed CSV to write")
    a = p.parse_args(argv)
    bad = [b for b in a.budgets if b <= 0]
    if bad:
        p.error(f"--budgets {bad}: a budget is a positive number of env steps")
    from hydra import compose, initialize_config_dir

    from hgm_repro.contracts.conf_dir import CONF_DIR
    from hgm_repro.contracts.errors import ConfigError
    from hgm_repro.contracts.schema import validate
    from hgm_repro.contracts.train_key import train_key
    from hgm_repro.evaluation.episodes import evaluate
    from hgm_repro.evaluation.reselection import best_pass, validation_passes

    rows, choices = [], []
    for seed in a.seeds:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            job = validate(compose("config", overrides=["experiment=quick", f"seed={seed}", "scenario=train",
                                                        *ARMS[a.arm]]))
        directory = a.checkpoints / train_key(job)
        passes = validation_passes(directory) if directory.is_dir() else []
        if not passes:
            p.error(f"seed {seed}: no kept validation passes of arm {a.arm} in {directory} "
                    "(train it with eval.keep_val_checkpoints=true)")
        stale = [q.env_steps for q in passes if not q.current]
        if stale:
            p.error(f"seed {seed}: passes {stale} were scored by the blank-frame validation of evaluation version 1; "
                    "score them again first (studies/revalidate.py)")
        tested: dict[Path, pd.Series] = {}
        for budget in a.budgets:
            try:
                chosen = best_pass(passes, budget)
            except ConfigError as error:
                p.error(f"seed {seed}: {error}")
            if chosen.path not in tested:  # budgets that choose the same pass share its (deterministic) test
                tested[chosen.path] = evaluate(job, job.scenario, chosen.path).episodes[list(RESULTS)].mean()
            means = tested[chosen.path]
            rows.append({"arm": cut_name(a.arm, budget), "seed": seed, **means.to_dict()})
            choices.append(f"seed {seed}, {budget // 1000}k: the {chosen.env_steps // 1000}k pass "
                           f"(validation {chosen.val_return:.0f}) tests at {means['episode_return']:.0f} "
                           f"with {means['collisions']:.2f} collisions")
            print(choices[-1], flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_csv(a.out, index=False, float_format="%.6g")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()
