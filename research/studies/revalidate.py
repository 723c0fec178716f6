"""Choose best.pt again, with the fixed validation, for a study arm's trainings that kept their passes.

    python research/studies/revalidate.py --checkpoints research/studies/runs/checkpoints --arm r20_enriched_160k \
        --seeds 100 101 102 103

Before evaluation version 2 a validation pass handed hosts a blank frame whenever another env restarted
(docs/interfaces.md), so the best.pt of such a training was chosen on disturbed scores. For a training
that kept every pass's network (eval.keep_val_checkpoints), this scores each pass again as training's
validation would now and rewrites best.pt and the passes' scores (hgm_repro.evaluation.reselection.
revalidate); `learner_study.py run --also-best` then tests the new best.pt. Nothing is trained.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from study_arms import ARMS, arm_job


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoints", type=Path, required=True, help="the store's checkpoints/ folder")
    p.add_argument("--arm", required=True, choices=sorted(ARMS))
    p.add_argument("--seeds", nargs="+", type=int, required=True)
    a = p.parse_args(argv)
    from hgm_repro.contracts.train_key import train_key
    from hgm_repro.evaluation.reselection import best_pass, revalidate

    for seed in a.seeds:
        job = arm_job(a.arm, seed)
        directory = a.checkpoints / train_key(job)
        if not directory.is_dir():
            p.error(f"seed {seed}: no training of arm {a.arm} in {directory}")
        scored = revalidate(job, directory)
        best = best_pass(scored)
        print(f"seed {seed}: " + ", ".join(f"{s.env_steps // 1000}k {s.val_return:.0f}" for s in scored)
              + f"; best.pt: {best.env_steps // 1000}k", flush=True)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()
