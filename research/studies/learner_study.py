"""The learner study: which options make the quick preset's host learn to drive.

    python research/studies/learner_study.py run --arms base nstep --seeds 100 101 [--parallel 2] [--references]
    python research/studies/learner_study.py report [--store A.db B.db] [--out docs/study] \
        [--earlier research/study/r20/learner_study_per_seed.csv [MORE.csv] --earlier-arms r20_all@best]

`run` trains and evaluates each (arm, seed) with `python -m hgm_repro` in the training traffic,
into one SQLite store (`research/studies/runs/study.db` by default; the runs resume if interrupted);
`report` reads that store and writes the learning curves and a table of final test results
(mean and 95% CI over seeds) to --out. Tuning seeds are 100-104: the published results use
seeds 0-4, which no study arm ever trains on.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from study_arms import ARMS, ROOT, STUDY_REFERENCES

RUNS = ROOT / "research" / "studies" / "runs"


def _command(arm: str, seed: int, uri: str, extra: list[str]) -> list[str]:
    # The study's first test of an arm drives its final network whatever the preset tests (the quick
    # preset now tests best.pt), so that an arm's numbers keep their meaning; --also-best adds the other.
    common = [sys.executable, "-m", "hgm_repro", f"seed={seed}", "scenario=train", "experiment=quick",
              f"tracking.uri={uri}"]
    if arm in STUDY_REFERENCES:
        return [*common, f"model={arm}"]
    return [*common, "eval.checkpoint=final", *ARMS[arm], *extra]


# The second test of an (arm, seed): its best validation checkpoint instead of the final one. It
# reuses the training (the checkpoint choice is not part of the train_key), so it costs a test only.
BEST = ["eval.checkpoint=best"]
# An arm that keeps a moving average of its weights is also tested from ema.pt (reported as ARM@ema).
EMA = ["eval.checkpoint=ema"]
# --reselected: the training keeps every validation pass's network (not part of the train_key, so the
# arm trains exactly as without it), and the test of the one reselection chooses is ARM@reselected.
KEEP_PASSES = ["eval.keep_val_checkpoints=true"]
RESELECTED = [*KEEP_PASSES, "eval.checkpoint=reselected"]


def run(arms: list[str], seeds: list[int], parallel: int, store: Path, also_best: bool = False,
        references: bool = False, reselected: bool = False) -> None:
    store.parent.mkdir(parents=True, exist_ok=True)
    uri = f"sqlite:///{store.resolve()}"
    first = KEEP_PASSES if reselected else []
    queue: list[tuple[str, int, list[str]]] = [(a, s, first) for s in seeds for a in arms]
    if references:
        queue += [(host, s, []) for s in seeds for host in STUDY_REFERENCES]
    running: list[tuple[subprocess.Popen, str, int, list[str]]] = []
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    while queue or running:
        while queue and len(running) < parallel:
            arm, seed, extra = queue.pop(0)
            log = open(store.parent / f"{arm}_seed{seed}.log", "a")  # noqa: SIM115 - closed with the process
            proc = subprocess.Popen(_command(arm, seed, uri, extra), cwd=store.parent, stdout=log, stderr=log, env=env)
            running.append((proc, arm, seed, extra))
            print(f"started {arm} seed {seed} {' '.join(extra)}", flush=True)
        for item in list(running):
            proc, arm, seed, extra = item
            if proc.poll() is not None:
                running.remove(item)
                print(f"finished {arm} seed {seed} {' '.join(extra)}: exit {proc.returncode}", flush=True)
                if extra == first and proc.returncode == 0 and arm in ARMS:  # the training ran: other tests of it
                    if also_best:
                        queue.insert(0, (arm, seed, BEST))
                        if any(o.startswith("learner.ema_decay=") for o in ARMS[arm]):
                            queue.insert(0, (arm, seed, EMA))
                    if reselected:
                        queue.insert(0, (arm, seed, RESELECTED))
        time.sleep(5)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="train and evaluate arms x seeds")
    r.add_argument("--arms", nargs="*", choices=sorted(ARMS), default=[])
    r.add_argument("--seeds", nargs="+", type=int, default=[100, 101])
    r.add_argument("--parallel", type=int, default=2, help="jobs at once (one torch thread each)")
    r.add_argument("--store", type=Path, default=RUNS / "study.db")
    r.add_argument("--also-best", action="store_true",
                   help="test each training's best validation checkpoint too (reported as ARM@best), and "
                        "ema.pt of arms that keep one (ARM@ema)")
    r.add_argument("--reselected", action="store_true",
                   help="keep every validation pass's network and test the one reselection chooses among the "
                        "best of them on fresh validation traffic (reported as ARM@reselected; conf/eval)")
    r.add_argument("--references", action="store_true",
                   help=f"test the reference hosts ({', '.join(STUDY_REFERENCES)}) on the same seeds")
    rep = sub.add_parser("report", help="curves and final results from the store")
    rep.add_argument("--store", type=Path, nargs="+", default=[RUNS / "study.db"],
                     help="one or more study stores (e.g. one per session)")
    rep.add_argument("--out", type=Path, default=ROOT / "research" / "study")
    rep.add_argument("--earlier", type=Path, nargs="+", metavar="PER_SEED_CSV",
                     help="earlier reports' learner_study_per_seed.csv (or research/studies/budget_cut.py's CSV), "
                          "whose "
                          "--earlier-arms rows join the table (arms measured in a session whose store is gone)")
    rep.add_argument("--earlier-arms", nargs="+", default=[], metavar="ARM",
                     help="the rows of --earlier to show, e.g. r20_all r20_all@best")
    a = p.parse_args(argv)
    if a.cmd == "run":
        bad = [s for s in a.seeds if 0 <= s <= 4]
        if bad:
            p.error(f"seeds {bad} are the published results' seeds; tune on others (for example 100-104)")
        if not a.arms and not a.references:
            p.error("nothing to run: name --arms, or --references, or both")
        run(a.arms, a.seeds, a.parallel, a.store, a.also_best, a.references, a.reselected)
    else:
        from study_report import earlier_results, report

        if bool(a.earlier) != bool(a.earlier_arms):
            p.error("--earlier and --earlier-arms go together: the CSV and the arms to take from it")
        report(a.store, a.out, earlier_results(a.earlier, a.earlier_arms) if a.earlier else None)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()
