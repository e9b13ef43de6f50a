"""Ratios between methods, with bootstrap intervals, and the seeds a difference would need.

One convention for every ratio of a report: the ratio of the two methods' means over their
seeds (never a mean of per-seed ratios), with a 95 % percentile bootstrap interval that
resamples each method's seeds independently (``scipy.stats.bootstrap``). With three seeds a
bootstrap interval is crude and too narrow; the report says how many seeds it rests on.
Every interval resamples from one fixed random state, :data:`BOOTSTRAP_SEED`, which the
report states beside them, so that a report made again from the same records gives the
same digits.
Where the denominator's mean may be zero (its own interval holds 0, as for QD-Scores that
sum returns of either sign), the ratio has no bounded interval (Fieller) and says so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

RESAMPLES = 10_000
"""Bootstrap resamples per interval."""

BOOTSTRAP_SEED = 0
"""The random state every bootstrap interval starts from (stated in the report's text)."""


@dataclass(frozen=True)
class Ratio:
    """mean(numerator) / mean(denominator) with its bootstrap interval.

    Attributes:
        value: the ratio of means (NaN when undefined: no seeds, or a mean of 0 below).
        low: lower end of the interval (NaN with fewer than 2 seeds on either side; -inf
            where the interval is unbounded).
        high: upper end of the interval (+inf where unbounded).
        n_numerator: seeds of the numerator.
        n_denominator: seeds of the denominator.
        bounded: whether the denominator's mean is away from zero: its own interval (at the
            same level) excludes 0, or, with one seed, it is not 0.
    """

    value: float
    low: float
    high: float
    n_numerator: int
    n_denominator: int
    bounded: bool = True


def ratio_of_means(
    numerator: Sequence[float] | np.ndarray,
    denominator: Sequence[float] | np.ndarray,
    confidence: float = 0.95,
    seed: int = BOOTSTRAP_SEED,
) -> Ratio:
    """The ratio of two methods' means over seeds, with a percentile bootstrap interval.

    Args:
        numerator: one value per seed of the first method, shape ``(n1,)``.
        denominator: one value per seed of the second method, shape ``(n2,)``.
        confidence: the interval's level.
        seed: the resampling's random state; the default, :data:`BOOTSTRAP_SEED`, is the
            one reports use and state.

    Returns:
        The ratio; its interval is NaN where either method has fewer than two seeds, and
        (-inf, inf) where the denominator's mean may be zero.
    """
    a = np.asarray(numerator, dtype=np.float64).reshape(-1)
    b = np.asarray(denominator, dtype=np.float64).reshape(-1)
    value = math.nan
    if len(a) and len(b) and np.mean(b) != 0:
        value = float(np.mean(a) / np.mean(b))
    low = high = math.nan
    bounded = bool(len(b)) and bool(np.mean(b) != 0)
    finite = np.all(np.isfinite(a)) and np.all(np.isfinite(b))
    # random_state, not scipy's newer rng keyword (1.15+): the project supports scipy 1.11.
    if len(b) >= 2 and finite:
        mean_b = stats.bootstrap(
            (b,),
            np.mean,
            n_resamples=RESAMPLES,
            confidence_level=confidence,
            method="percentile",
            random_state=np.random.default_rng(seed),
        ).confidence_interval
        bounded = bool(mean_b.low > 0 or mean_b.high < 0)
    if len(a) >= 2 and len(b) >= 2 and finite:
        with np.errstate(divide="ignore", invalid="ignore"):  # resamples whose mean is 0
            result = stats.bootstrap(
                (a, b),
                lambda x, y, axis: np.mean(x, axis=axis) / np.mean(y, axis=axis),
                n_resamples=RESAMPLES,
                confidence_level=confidence,
                method="percentile",
                random_state=np.random.default_rng(seed),
            )
        low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
        if not bounded:
            low, high = -math.inf, math.inf
    return Ratio(value, low, high, len(a), len(b), bounded)


def seeds_to_resolve(
    first: Sequence[float] | np.ndarray,
    second: Sequence[float] | np.ndarray,
    alpha: float = 0.05,
    power: float = 0.8,
    most: int = 1000,
) -> int | None:
    """Seeds per method a two-sided two-sample t-test needs to find the observed gap.

    The gap is the difference of the means, the spread the pooled sample standard deviation
    of both methods; the power comes from the noncentral t distribution.

    Args:
        first: one value per seed, shape ``(n1,)``, at least 2.
        second: one value per seed, shape ``(n2,)``, at least 2.
        alpha: the test's significance level.
        power: the probability of finding the gap.
        most: the largest answer searched.

    Returns:
        The smallest n per method, or ``None`` when the gap is zero, the spread undefined,
        or more than ``most`` seeds would be needed.
    """
    a = np.asarray(first, dtype=np.float64).reshape(-1)
    b = np.asarray(second, dtype=np.float64).reshape(-1)
    if len(a) < 2 or len(b) < 2:
        return None
    pooled = math.sqrt(
        ((len(a) - 1) * np.var(a, ddof=1) + (len(b) - 1) * np.var(b, ddof=1))
        / (len(a) + len(b) - 2)
    )
    gap = abs(float(np.mean(a) - np.mean(b)))
    if pooled == 0 or gap == 0 or not math.isfinite(pooled / gap):
        return None
    effect = gap / pooled
    for n in range(2, most + 1):
        df = 2 * n - 2
        critical = stats.t.ppf(1 - alpha / 2, df)
        shift = effect * math.sqrt(n / 2)
        reached = stats.nct.sf(critical, df, shift) + stats.nct.cdf(-critical, df, shift)
        if reached >= power:
            return n
    return None
