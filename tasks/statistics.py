"""Intervals and tests over episodes and seeds, in one place, each from scipy.stats.

Intervals (95 % unless asked): ``wilson_interval`` of a success share (binomtest's Wilson score),
``mean_interval`` of a mean (Student t), ``paired_ratio_interval`` of a ratio of two paired means
(a percentile bootstrap over the pairs). Tests (p-values): ``sign_test_p`` (exact binomial sign test of
won against lost pairs), ``signed_rank_p`` (exact Wilcoxon signed-rank of paired differences),
``fisher_exact_p`` (two success shares) and ``mann_whitney_p`` (two samples of times).
"""
from __future__ import annotations

import enum
from collections.abc import Sequence

import numpy as np
import scipy.stats

CONFIDENCE = 0.95


class Alternative(str, enum.Enum):
    """The alternative hypothesis of a test, as scipy spells it."""

    TWO_SIDED = "two-sided"
    GREATER = "greater"
    LESS = "less"


def wilson_interval(successes: int, trials: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Wilson score interval of a success share (``scipy.stats.binomtest(...).proportion_ci``)."""
    ci = scipy.stats.binomtest(successes, trials).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def mean_interval(values: Sequence[float] | np.ndarray, confidence: float = CONFIDENCE) -> tuple[float, float] | None:
    """Student-t interval of the mean of ``values`` (None below two values; no spread: the mean twice)."""
    values = np.asarray(values, dtype=float)
    if values.size < 2:
        return None
    mean, sem = float(values.mean()), float(scipy.stats.sem(values))
    if sem == 0.0:
        return mean, mean
    low, high = scipy.stats.t.interval(confidence, values.size - 1, loc=mean, scale=sem)
    return float(low), float(high)


def paired_ratio_interval(before: Sequence[float], after: Sequence[float], rng: np.random.Generator,
                          resamples: int = 10_000, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Percentile bootstrap interval of mean(after) / mean(before), the pairs (a seed's two runs)
    resampled together (``scipy.stats.bootstrap``, paired)."""
    def ratio(b: np.ndarray, a: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.mean(a, axis=axis) / np.mean(b, axis=axis)

    result = scipy.stats.bootstrap((np.asarray(before, float), np.asarray(after, float)), ratio, paired=True,
                                   n_resamples=resamples, confidence_level=confidence, method="percentile",
                                   random_state=rng)
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def sign_test_p(won: int, lost: int, alternative: Alternative = Alternative.GREATER) -> float:
    """Exact sign test of the pairs only one side won: P(``won`` or more of ``won + lost`` | a fair
    coin) for GREATER (1 without such pairs)."""
    n = won + lost
    return float(scipy.stats.binomtest(won, n, 0.5, alternative=alternative.value).pvalue) if n else 1.0


def signed_rank_p(differences: Sequence[float], alternative: Alternative = Alternative.LESS) -> float:
    """Exact Wilcoxon signed-rank test of paired differences (LESS: the differences tend below 0);
    1 when every difference is 0 (nothing to rank)."""
    if not any(differences):
        return 1.0
    return float(scipy.stats.wilcoxon(differences, alternative=alternative.value, method="exact").pvalue)


def fisher_exact_p(successes_a: int, trials_a: int, successes_b: int, trials_b: int) -> float:
    """Two-sided Fisher exact test of two success shares."""
    table = [[successes_a, trials_a - successes_a], [successes_b, trials_b - successes_b]]
    return float(scipy.stats.fisher_exact(table)[1])


def mann_whitney_p(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided Mann-Whitney U test of two samples (scipy's default method: exact for small samples
    without ties)."""
    return float(scipy.stats.mannwhitneyu(a, b).pvalue)
