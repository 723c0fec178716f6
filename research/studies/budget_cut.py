"""What a shorter training's best.pt would have been: for study arms whose trainings kept their
validation passes, the pass with the best validation return among those at or before each budget,
tested as the study tests (training traffic, the preset's test). Nothing is trained.

    python research/studies/budget_cut.py --checkpoints research/studies/runs/checkpoints OTHER/checkpoints \
        --arms r20_all_160k r20_enriched_160k --seeds 100 101 102 103 104 --budgets 80000 120000 160000 \
        --out research/study/r20_budget/budget_cut.csv --figure research/study/r20_budget/validation_passes.png \
        --references research/study/r20_reselect/learner_study_per_seed.csv

One 160k-step training then answers for 80k and 120k too, at the cost of a test per distinct pass. It
is close to, not the same as, a training that stops at the budget: every schedule of the quick presets
is in absolute steps except prioritized replay's importance-sampling exponent (beta), which anneals
over the whole run, so at 80k steps of a 160k run it is half-way where an 80k run's is at its end.
The rows are named `ARM@bestNk` in the learner study's per-seed format, so that `learner_study.py
report --earlier FILE --earlier-arms ARM@best80k` puts them in its table beside the arm's own best.pt.
`--figure` draws every kept pass's validation return (as this code's validation scores it: passes of
an older validation must be scored again first, research/studies/revalidate.py) per seed, with the human-driven
host's test return on that seed from `--references` (a learner-study per-seed CSV) as the bar.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd
from study_arms import ARMS, arm_job
from study_report import RESULTS, validation_per_seed


def cut_name(arm: str, budget: int) -> str:
    """The per-seed row name of `arm`'s best pass at or before `budget` env steps."""
    return f"{arm}@best{budget // 1000}k" if budget % 1000 == 0 else f"{arm}@best{budget}"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoints", type=Path, nargs="+", required=True,
                   help="study stores' checkpoints/ folders, searched in order for each training")
    p.add_argument("--arms", nargs="+", required=True, choices=sorted(ARMS))
    p.add_argument("--seeds", nargs="+", type=int, required=True)
    p.add_argument("--budgets", nargs="+", type=int, required=True, help="env steps to cut the trainings at")
    p.add_argument("--out", type=Path, required=True, help="the per-seed CSV to write")
    p.add_argument("--figure", type=Path, help="also draw the kept passes' validation returns per seed here")
    p.add_argument("--references", type=Path, help="a learner-study per-seed CSV with the human-driven host's rows")
    a = p.parse_args(argv)
    bad = [b for b in a.budgets if b <= 0]
    if bad:
        p.error(f"--budgets {bad}: a budget is a positive number of env steps")
    if a.references is not None and not a.references.is_file():
        p.error(f"--references {a.references}: no such file")
    from hgm_repro.contracts.errors import ConfigError
    from hgm_repro.contracts.train_key import EVALUATION_VERSION, train_key
    from hgm_repro.evaluation.episodes import evaluate
    from hgm_repro.evaluation.reselection import best_pass, validation_passes

    # Every training's passes first, so that a missing or stale one stops the run before any test.
    trainings = {}
    for arm in a.arms:
        for seed in a.seeds:
            job = arm_job(arm, seed)
            key = train_key(job)
            found = [d / key for d in a.checkpoints if validation_passes(d / key)]
            if not found:
                p.error(f"{arm} seed {seed}: no kept validation passes of training {key} in any of "
                        f"{[str(d) for d in a.checkpoints]} (train it with eval.keep_val_checkpoints=true)")
            passes = validation_passes(found[0])
            stale = [q.env_steps for q in passes if not q.current]
            if stale:
                p.error(f"{arm} seed {seed}: passes {stale} in {found[0]} were scored by the blank-frame validation "
                        "of evaluation version 1; score them again first (research/studies/revalidate.py)")
            trainings[arm, seed] = (job, passes)

    rows, curve = [], []
    for (arm, seed), (job, passes) in trainings.items():
        curve += [{"arm": arm, "seed": seed, "metric": "val/episode_return", "step": q.env_steps, "value": q.val_return}
                  for q in passes]
        tested: dict[Path, pd.Series] = {}
        for budget in a.budgets:
            try:
                chosen = best_pass(passes, budget)
            except ConfigError as error:
                p.error(f"{arm} seed {seed}: {error}")
            if chosen.path not in tested:  # budgets that choose the same pass share its (deterministic) test
                tested[chosen.path] = evaluate(job, job.scenario, chosen.path).episodes[list(RESULTS)].mean()
            means = tested[chosen.path]
            rows.append({"arm": cut_name(arm, budget), "seed": seed, "chosen_env_steps": chosen.env_steps,
                         "val_return": chosen.val_return, **means.to_dict(),
                         "evaluation_version": EVALUATION_VERSION})
            print(f"{arm} seed {seed}, {budget // 1000}k: the {chosen.env_steps // 1000}k pass (validation "
                  f"{chosen.val_return:.0f}) tests at {means['episode_return']:.0f} with {means['collisions']:.2f} "
                  "collisions", flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_csv(a.out, index=False, float_format="%.6g")
    print(f"wrote {a.out}")
    if a.figure is not None:
        # The learner study's figure, drawn from the kept passes' scores instead of a store's logged curves.
        references = pd.read_csv(a.references) if a.references else pd.DataFrame(columns=["arm", "seed", *RESULTS])
        a.figure.parent.mkdir(parents=True, exist_ok=True)
        validation_per_seed(references, pd.DataFrame(curve), a.figure)
        print(f"wrote {a.figure}")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()
