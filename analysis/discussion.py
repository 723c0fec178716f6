"""A short discussion written from the claim verdicts and the data coverage, not by hand."""

from __future__ import annotations

import pandas as pd

from analysis.claims import INCONCLUSIVE, NOT_SUPPORTED, SUPPORTED, ClaimResult
from analysis.tables import PAPER_TABLE6


def ordering_agreement(evals: pd.DataFrame) -> tuple[int, int, int, int]:
    """(pairs agreeing, pairs compared, scenarios with Proposed first, scenarios compared) vs the paper.

    Only the order of the methods is compared: the paper's score has no stated unit, so its values
    cannot be matched with ours. Pairs the paper ties are skipped.
    """
    means = evals.groupby(["scenario", "model"])["episode_return"].mean() if not evals.empty else pd.Series()
    agree = pairs = first = compared = 0
    methods = list(PAPER_TABLE6.index)
    for scenario in PAPER_TABLE6.columns:
        ours = {m: means.get((scenario, m)) for m in methods}
        if any(v is None or pd.isna(v) for v in ours.values()):
            continue
        compared += 1
        first += max(ours, key=ours.get) == "proposed"
        for i, a in enumerate(methods):
            for b in methods[i + 1:]:
                paper = PAPER_TABLE6.loc[a, scenario] - PAPER_TABLE6.loc[b, scenario]
                if paper == 0:
                    continue
                pairs += 1
                agree += (paper > 0) == (ours[a] > ours[b])
    return agree, pairs, first, compared


def _tally(results: list[ClaimResult], verdict: str) -> str:
    """'one claim (7)', 'four claims (1, 2, 3 and 4)', 'none'."""
    nums = [str(r.number) for r in results if r.verdict == verdict]
    if not nums:
        return "none"
    words = ("no", "one", "two", "three", "four", "five", "six", "seven")
    count = words[len(nums)] if len(nums) < len(words) else str(len(nums))
    listed = nums[0] if len(nums) == 1 else f"{', '.join(nums[:-1])} and {nums[-1]}"
    return f"{count} claim{'s' if len(nums) > 1 else ''} ({listed})"


def discussion(results: list[ClaimResult], seed_counts: pd.DataFrame, n_train_runs: int,
               evals: pd.DataFrame) -> list[str]:
    """Paragraphs: the overall tally, then what each group of verdicts rests on, then caveats."""
    paras = [
        f"Of the paper's seven claims, our runs support {_tally(results, SUPPORTED)}, contradict "
        f"{_tally(results, NOT_SUPPORTED)} and leave {_tally(results, INCONCLUSIVE)} undecided."
    ]
    for r in results:
        if r.verdict == INCONCLUSIVE:
            open_ = [c.text() for c in r.comparisons if c.verdict != SUPPORTED]
            paras.append(f"Claim {r.number} is undecided; the comparisons that do not hold yet: "
                         f"{'; '.join(open_) or 'none were possible (no data)'}.")
        elif r.verdict == NOT_SUPPORTED:
            against = [c for c in r.comparisons if c.verdict == NOT_SUPPORTED]
            paras.append(f"Claim {r.number} fails on: " + "; ".join(c.text() for c in against) + ".")
    if not seed_counts.empty:
        learned = seed_counts.loc[[m for m in ("proposed", "min", "coordinate") if m in seed_counts.index]]
        filled = learned.to_numpy()[learned.to_numpy() > 0]
        fewest = int(filled.min()) if filled.size else 0
        missing = int((seed_counts == 0).sum().sum())
        if 0 < fewest < 3:
            paras.append(f"Caution: some cells of the test grid hold only {fewest} seed(s); a bootstrap over so "
                         "few seeds either gives no interval or one that is too narrow, so verdicts there "
                         "are left undecided.")
        if missing:
            paras.append(f"{missing} method x scenario cell(s) of the test grid have no run; claims that need "
                         "them are undecided.")
    if n_train_runs == 0:
        paras.append("The store holds no training curves, so the training claims (2, 3, 4) rest on no data.")
    agree, pairs, first, compared = ordering_agreement(evals)
    if compared:
        paras.append(f"Against the paper's Table 6, where Proposed ranks first in all five scenarios: our mean "
                     f"returns put Proposed first in {first} of the {compared} scenario(s) evaluated with all "
                     f"three learned methods, and {agree} of {pairs} pairwise orderings of the methods agree "
                     "with the paper's (point estimates, ignoring the CIs).")
    paras.append("The paper's Table 6 gives one score per cell without a unit, seed count or interval; we "
                 "compare orderings with it, not values. Our score is the mean test episode return.")
    return paras
