"""Interval estimates over seeds: stratified percentile bootstrap, IQM, probability of improvement.

The unit of replication is a seed (one training run, or one evaluation run of a non-learning host);
episodes inside a run are not independent replications of the method and never enter a CI.
Stratification follows Agarwal et al. (2021, "Deep RL at the edge of the statistical precipice"):
seeds are resampled with replacement inside each scenario, never across them, so each bootstrap
sample keeps one entry per scenario.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import trim_mean

CONFIDENCE = 0.95
N_BOOT = 2000

# A statistic sees each sample as a [n_boot, n_seeds] array (the point estimate uses n_boot = 1)
# and returns one value per bootstrap row.
Statistic = Callable[[list[np.ndarray]], np.ndarray]


@dataclass(frozen=True)
class Estimate:
    """A point estimate with a percentile-bootstrap CI; `n` is the fewest seeds in any sample."""

    point: float
    low: float
    high: float
    n: int

    @property
    def has_ci(self) -> bool:
        return bool(np.isfinite(self.low) and np.isfinite(self.high))

    def excludes_zero(self) -> int:
        """+1 if the CI lies above zero, -1 if below, 0 if it covers zero or does not exist."""
        if not self.has_ci:
            return 0
        if self.low > 0:
            return 1
        if self.high < 0:
            return -1
        return 0


def _clean(values: Sequence[float] | np.ndarray) -> np.ndarray:
    arr = np.asarray(values, dtype=float).ravel()
    return arr[np.isfinite(arr)]


def bootstrap(samples: Sequence[Sequence[float] | np.ndarray], statistic: Statistic,
              confidence: float = CONFIDENCE, n_boot: int = N_BOOT, seed: int = 0) -> Estimate:
    """Percentile bootstrap of `statistic`, resampling every sample independently (the strata).

    Any empty sample gives NaN everywhere; a sample with one seed gives a point but no CI, because
    resampling one value says nothing about the spread between seeds.
    """
    arrays = [_clean(s) for s in samples]
    if not arrays or any(a.size == 0 for a in arrays):
        return Estimate(np.nan, np.nan, np.nan, 0)
    n = min(a.size for a in arrays)
    point = float(statistic([a[None, :] for a in arrays])[0])
    if n < 2:
        return Estimate(point, np.nan, np.nan, n)
    rng = np.random.default_rng(seed)
    resampled = [a[rng.integers(0, a.size, size=(n_boot, a.size))] for a in arrays]
    boot = np.asarray(statistic(resampled), dtype=float)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(boot, [alpha, 1.0 - alpha])
    return Estimate(point, float(low), float(high), n)


def mean_ci(values: Sequence[float] | np.ndarray, **kw: float) -> Estimate:
    """Mean over seeds with its bootstrap CI."""
    return bootstrap([values], lambda s: s[0].mean(axis=1), **kw)


def iqm(values: Sequence[float] | np.ndarray) -> float:
    """Interquartile mean: the mean of the middle 50 %, robust to one outlying seed."""
    arr = _clean(values)
    return float(trim_mean(arr, 0.25)) if arr.size else np.nan


def _strata_pairs(a: Mapping[str, Sequence[float]], b: Mapping[str, Sequence[float]]) -> list[str]:
    return [k for k in a if k in b and _clean(a[k]).size and _clean(b[k]).size]


def iqm_ci(by_stratum: Mapping[str, Sequence[float]], **kw: float) -> Estimate:
    """IQM of all (scenario, seed) scores pooled, with seeds resampled inside each scenario."""
    keys = [k for k in by_stratum if _clean(by_stratum[k]).size]
    if not keys:
        return Estimate(np.nan, np.nan, np.nan, 0)
    return bootstrap([by_stratum[k] for k in keys],
                     lambda s: trim_mean(np.concatenate(s, axis=1), 0.25, axis=1), **kw)


def stratified_mean_ci(by_stratum: Mapping[str, Sequence[float]], **kw: float) -> Estimate:
    """Mean over scenarios of the mean over seeds."""
    keys = [k for k in by_stratum if _clean(by_stratum[k]).size]
    if not keys:
        return Estimate(np.nan, np.nan, np.nan, 0)
    return bootstrap([by_stratum[k] for k in keys],
                     lambda s: np.mean([x.mean(axis=1) for x in s], axis=0), **kw)


def difference_ci(a: Mapping[str, Sequence[float]], b: Mapping[str, Sequence[float]], **kw: float) -> Estimate:
    """Mean over the scenarios both hold of (mean of a - mean of b); a and b resampled independently."""
    keys = _strata_pairs(a, b)
    if not keys:
        return Estimate(np.nan, np.nan, np.nan, 0)
    k = len(keys)

    def stat(s: list[np.ndarray]) -> np.ndarray:
        return np.mean([s[i].mean(axis=1) - s[k + i].mean(axis=1) for i in range(k)], axis=0)

    return bootstrap([a[x] for x in keys] + [b[x] for x in keys], stat, **kw)


def test_noise_ci(a_episodes: Sequence[float] | np.ndarray, b_episodes: Sequence[float] | np.ndarray,
                  **kw: float) -> Estimate:
    """mean(a) - mean(b) for two hosts tested on one seed, with a bootstrap over their test episodes.

    Not a CI of a method (that is over seeds, above): it says how far a longer test of the same two
    networks in the same traffic could move the difference, i.e. whether one seed's comparison is
    decided by the hosts or by which episodes the test happened to draw."""
    return bootstrap([a_episodes, b_episodes], lambda s: s[0].mean(axis=1) - s[1].mean(axis=1), **kw)


def _prob_greater(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # Mann-Whitney style: ties count half, so two identical methods score exactly 0.5.
    gt = (x[:, :, None] > y[:, None, :]).mean(axis=(1, 2))
    eq = (x[:, :, None] == y[:, None, :]).mean(axis=(1, 2))
    return gt + 0.5 * eq


def probability_of_improvement(x: Mapping[str, Sequence[float]], y: Mapping[str, Sequence[float]],
                               **kw: float) -> Estimate:
    """P(a random seed of x scores above a random seed of y), averaged over the scenarios both hold."""
    keys = _strata_pairs(x, y)
    if not keys:
        return Estimate(np.nan, np.nan, np.nan, 0)
    k = len(keys)

    def stat(s: list[np.ndarray]) -> np.ndarray:
        return np.mean([_prob_greater(s[i], s[k + i]) for i in range(k)], axis=0)

    return bootstrap([x[c] for c in keys] + [y[c] for c in keys], stat, **kw)


def slope_ci(by_x: Mapping[float, Sequence[float]], **kw: float) -> Estimate:
    """Least-squares slope of the per-x mean over seeds against x, seeds resampled inside each x."""
    keys = [k for k in by_x if _clean(by_x[k]).size]
    if len(keys) < 2:
        return Estimate(np.nan, np.nan, np.nan, 0)
    xs = np.asarray(keys, dtype=float)
    xc = xs - xs.mean()

    def stat(s: list[np.ndarray]) -> np.ndarray:
        means = np.stack([v.mean(axis=1) for v in s], axis=1)  # [n_boot, n_x]
        return (means - means.mean(axis=1, keepdims=True)) @ xc / (xc @ xc)

    return bootstrap([by_x[k] for k in keys], stat, **kw)


def slope_difference_ci(a: Mapping[float, Sequence[float]], b: Mapping[float, Sequence[float]],
                        **kw: float) -> Estimate:
    """Slope of a minus slope of b over the x values both hold."""
    keys = [k for k in a if k in b and _clean(a[k]).size and _clean(b[k]).size]
    if len(keys) < 2:
        return Estimate(np.nan, np.nan, np.nan, 0)
    xs = np.asarray(keys, dtype=float)
    xc = xs - xs.mean()
    k = len(keys)

    def slope(parts: list[np.ndarray]) -> np.ndarray:
        means = np.stack([v.mean(axis=1) for v in parts], axis=1)
        return (means - means.mean(axis=1, keepdims=True)) @ xc / (xc @ xc)

    return bootstrap([a[x] for x in keys] + [b[x] for x in keys], lambda s: slope(s[:k]) - slope(s[k:]), **kw)
