"""Ratios of means with bootstrap intervals, and the seeds a gap would need (power analysis)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from qdil.evaluation.ratios import BOOTSTRAP_SEED, RESAMPLES, ratio_of_means, seeds_to_resolve


def spread(mean: float, sd: float) -> np.ndarray:
    """Two values with this mean and sample standard deviation."""
    return np.array([mean - sd / math.sqrt(2), mean + sd / math.sqrt(2)])


@pytest.mark.parametrize(("effect", "n"), [(1.0, 17), (0.5, 64), (0.8, 26)])
def test_seeds_match_the_textbook_two_sample_t_test(effect: float, n: int) -> None:
    # Cohen's table (alpha 0.05 two-sided, power 0.8): d = 1 -> 17, 0.8 -> 26, 0.5 -> 64
    assert seeds_to_resolve(spread(0.0, 1.0), spread(effect, 1.0)) == n


def test_no_answer_without_a_gap_or_a_spread() -> None:
    assert seeds_to_resolve([1.0, 1.0], [1.0, 1.0]) is None
    assert seeds_to_resolve([1.0], [2.0, 3.0]) is None
    assert seeds_to_resolve(spread(0.0, 1.0), spread(0.01, 1.0), most=100) is None


def test_the_ratio_is_of_means_and_its_interval_holds_it() -> None:
    wqdil, gail = [1.10e6, 1.16e6, 1.23e6], [0.90e6, 1.02e6, 1.26e6]
    ratio = ratio_of_means(wqdil, gail)
    assert ratio.value == pytest.approx(np.mean(wqdil) / np.mean(gail))
    assert ratio.low < ratio.value < ratio.high
    assert (ratio.n_numerator, ratio.n_denominator) == (3, 3)
    assert ratio_of_means(wqdil, gail) == ratio  # the resampling is seeded
    wider = ratio_of_means(wqdil, [0.6e6, 1.02e6, 1.56e6])
    assert wider.high - wider.low > ratio.high - ratio.low


def test_intervals_repeat_from_the_stated_random_state() -> None:
    # eight spread values a side, so nearly every resample's ratio is distinct and an
    # unseeded bootstrap would move the interval's ends from one call to the next
    values = np.random.default_rng(7)
    wqdil, gail = values.normal(1.1e6, 1e5, 8), values.normal(1.0e6, 1.5e5, 8)
    first, second = ratio_of_means(wqdil, gail), ratio_of_means(wqdil, gail)
    assert (first.low, first.high) == (second.low, second.high)
    # the state is the one the report states: scipy's bootstrap from BOOTSTRAP_SEED agrees
    direct = stats.bootstrap(
        (wqdil, gail),
        lambda x, y, axis: np.mean(x, axis=axis) / np.mean(y, axis=axis),
        n_resamples=RESAMPLES,
        method="percentile",
        random_state=np.random.default_rng(BOOTSTRAP_SEED),
    ).confidence_interval
    assert (first.low, first.high) == (direct.low, direct.high)
    # and the state matters: another one gives other ends
    other = ratio_of_means(wqdil, gail, seed=BOOTSTRAP_SEED + 1)
    assert (other.low, other.high) != (first.low, first.high)


def test_one_seed_gives_a_ratio_without_an_interval() -> None:
    ratio = ratio_of_means([2.0], [1.0, 1.0])
    assert ratio.value == 2.0 and math.isnan(ratio.low) and math.isnan(ratio.high)


def test_a_denominator_whose_mean_may_be_zero_gives_no_bounded_interval() -> None:
    # raw QD-Scores near zero and of either sign (HalfCheetah at 50 iterations)
    ratio = ratio_of_means([4.7e4, -6.0e4, 1.5e5], [3.0e5, -1.4e5])
    assert not ratio.bounded
    assert (ratio.low, ratio.high) == (-math.inf, math.inf)
    assert ratio.value == pytest.approx(np.mean([4.7e4, -6.0e4, 1.5e5]) / 8.0e4)
    # the same spread, far from zero: bounded
    assert ratio_of_means([4.7e4, -6.0e4, 1.5e5], [3.0e6, 2.6e6]).bounded
    # one seed: bounded unless it is zero
    assert ratio_of_means([1.0, 2.0], [3.0]).bounded
    zero = ratio_of_means([1.0, 2.0], [0.0])
    assert not zero.bounded and math.isnan(zero.value)
