"""tasks/statistics.py against values worked out by hand (counting subsets, closed forms)."""
import math

import numpy as np
import pytest

from tasks.statistics import (Alternative, fisher_exact_p, mann_whitney_p, mean_interval, paired_ratio_interval,
                              sign_test_p, signed_rank_p, wilson_interval)

Z95 = 1.959963984540054   # the standard normal's 97.5 % quantile


def wilson_by_hand(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return centre - half, centre + half


@pytest.mark.parametrize("k, n", [(3, 10), (7, 12), (50, 62), (10, 10)])
def test_the_wilson_interval_is_the_score_interval(k, n):
    assert wilson_interval(k, n) == pytest.approx(wilson_by_hand(k, n), rel=1e-9)


def test_no_success_in_ten_has_the_wilson_upper_bound_z2_over_n_plus_z2():
    low, high = wilson_interval(0, 10)
    assert low == 0.0 and high == pytest.approx(Z95 ** 2 / (10 + Z95 ** 2), rel=1e-12)   # 0.2775


def test_the_mean_interval_of_one_to_five_is_three_plus_minus_t4_times_the_standard_error():
    t4 = 2.7764451051977987   # Student t, 4 degrees of freedom, 97.5 % (tables: 2.776)
    low, high = mean_interval([1, 2, 3, 4, 5])
    assert (low, high) == pytest.approx((3 - t4 * math.sqrt(2.5 / 5), 3 + t4 * math.sqrt(2.5 / 5)), rel=1e-12)
    assert mean_interval([4.0]) is None and mean_interval([2.0, 2.0, 2.0]) == (2.0, 2.0)


def test_the_sign_test_counts_the_tail_of_a_fair_coin():
    assert sign_test_p(5, 0) == pytest.approx(1 / 32)           # all five: 1/2^5
    assert sign_test_p(4, 1) == pytest.approx(6 / 32)           # 4 or 5 of 5: (5 + 1) / 32
    assert sign_test_p(0, 0) == 1.0
    assert sign_test_p(1, 4, Alternative.LESS) == pytest.approx(6 / 32)


def test_the_signed_rank_test_counts_rank_sums_of_subsets():
    assert signed_rank_p([-1.0, -2.5, -3.0, -4.0, -6.0]) == pytest.approx(1 / 32)   # W+ = 0: one of 32 sign patterns
    # W+ = 5 (the largest difference positive): the subsets of ranks 1..5 summing to 5 or less are
    # {}, {1}, {2}, {3}, {4}, {5}, {1,2}, {1,3}, {1,4}, {2,3}: 10 of 32
    assert signed_rank_p([-1.0, -2.0, -3.0, -4.0, 5.0]) == pytest.approx(10 / 32)
    assert signed_rank_p([0.0, 0.0]) == 1.0


def test_fisher_exact_of_three_of_four_against_one_of_four():
    # margins 4/4 of 8: P(a) = C(4,a) C(4,4-a) / C(8,4); as or more extreme than a = 3: a in {0, 1, 3, 4}
    assert fisher_exact_p(3, 4, 1, 4) == pytest.approx((1 + 16 + 16 + 1) / 70)
    assert fisher_exact_p(2, 4, 2, 4) == pytest.approx(1.0)


def test_mann_whitney_of_two_separated_samples_of_three():
    # U = 0: one of the C(6,3) = 20 ways to split the ranks, twice for both sides
    assert mann_whitney_p([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]) == pytest.approx(2 / 20)


def test_the_paired_ratio_interval_holds_a_constant_ratio_and_brackets_the_ratio_of_means():
    before = np.array([100.0, 120.0, 90.0, 150.0, 110.0, 130.0])
    low, high = paired_ratio_interval(before, 0.5 * before, np.random.default_rng(0), resamples=2000)
    assert low == pytest.approx(0.5) and high == pytest.approx(0.5)
    after = before * np.array([0.4, 0.6, 0.5, 0.7, 0.3, 0.5])
    low, high = paired_ratio_interval(before, after, np.random.default_rng(0), resamples=2000)
    assert low < after.mean() / before.mean() < high and 0.3 < low and high < 0.7
