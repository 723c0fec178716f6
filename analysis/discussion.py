"""A short discussion written from the claim verdicts and the data coverage, not by hand: what each
verdict means and what would change it (the evidence itself is in the claims section)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats as sps

from analysis.claims import INCONCLUSIVE, NOT_SUPPORTED, SUPPORTED, TIE, ClaimResult, Comparison
from analysis.labels import listed
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
    return f"{count} claim{'s' if len(nums) > 1 else ''} ({listed(nums)})"


def seeds_to_decide(comparison: Comparison, most: int = 1000) -> int | None:
    """About how many seeds would put this tie's interval clear of 0 if its point estimate and the spread
    of its seeds stayed as they are; None when the point is 0 or more than `most` would be needed."""
    e = comparison.estimate
    if not e.has_ci or e.n < 2 or e.point == 0:
        return None
    spread = (e.high - e.low) / 2 * np.sqrt(e.n) / sps.t.ppf(0.975, e.n - 1)  # the seeds' standard deviation
    for n in range(e.n + 1, most + 1):
        if sps.t.ppf(0.975, n - 1) * spread / np.sqrt(n) < abs(e.point):
            return n
    return None


def _what_would_change(result: ClaimResult) -> str:
    """One paragraph per claim: what its verdict means, and what would move it."""
    comps = result.comparisons
    head = f"Claim {result.number} ({result.statement.rstrip('.')})"
    if result.verdict == SUPPORTED:
        return (f"{head} holds at this scale: every difference it needs lies clear of 0. More seeds would narrow "
                "the intervals; only a different training or test (the paper's budget and image size) could "
                "turn it.")
    if result.verdict == NOT_SUPPORTED:
        against = [c for c in comps if c.verdict == NOT_SUPPORTED]
        shown = "; ".join(f"{c.label}, {c.number()}" for c in against[:2]) + ("; ..." if len(against) > 2 else "")
        return (f"{head} goes the other way in {len(against)} of {len(comps)} differences ({shown}). More seeds "
                "would not turn these: their intervals already exclude 0 on the wrong side. Only a different "
                "training (longer, or at the paper's image size) could.")
    if result.verdict == TIE:
        ties = [c for c in comps if c.verdict == TIE]
        need = [seeds_to_decide(c) for c in ties]
        if all(n is not None for n in need):
            hardest = ties[int(np.argmax(need))]
            more = (f"if the point estimates held, about {max(need)} seeds per method would decide it (the hardest "
                    f"is {hardest.label}, {hardest.number()}, from {hardest.estimate.n} seeds)")
        else:
            more = "some of them are so close to 0 that no practical number of seeds would decide them"
        return (f"{head} is a tie: {len(ties)} of its {len(comps)} differences cannot be told from 0 with these "
                f"seeds, and none goes the other way; {more}.")
    missing = [c for c in comps if c.verdict == INCONCLUSIVE]
    reasons = sorted({c.reason for c in missing})
    return (f"{head} is undecided for want of data ({listed(reasons) if reasons else 'no comparison possible'}): "
            "runs for the missing cells, with at least three seeds each, would decide it.")


def discussion(results: list[ClaimResult], seed_counts: pd.DataFrame, n_train_runs: int,
               evals: pd.DataFrame) -> list[str]:
    """Paragraphs: the overall tally, what each verdict means and what would change it, then caveats."""
    paras = [
        f"Of the paper's seven claims, our runs support {_tally(results, SUPPORTED)}, contradict "
        f"{_tally(results, NOT_SUPPORTED)}, find a tie in {_tally(results, TIE)} and leave "
        f"{_tally(results, INCONCLUSIVE)} undecided. A tie is not a contradiction: it says that with this "
        "many seeds the difference the paper reports cannot be told from none."
    ]
    paras += [_what_would_change(r) for r in results]
    if not seed_counts.empty:
        learned = seed_counts.loc[[m for m in ("proposed", "min", "coordinate") if m in seed_counts.index]]
        filled = learned.to_numpy()[learned.to_numpy() > 0]
        fewest = int(filled.min()) if filled.size else 0
        missing = int((seed_counts == 0).sum().sum())
        if 0 < fewest < 3:
            paras.append(f"Caution: some cells of the test grid hold only {fewest} seed(s); with so few seeds an "
                         "interval is missing or too wide to decide on, so verdicts there are left undecided.")
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
                     "with the paper's (point estimates, ignoring the intervals). The paper's Table 6 gives one "
                     "score per cell without a unit, seed count or interval, so we compare orderings with it, not "
                     "values; our score is the mean test episode return.")
    return paras
