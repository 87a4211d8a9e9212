"""How far a person's rests scatter: the one measure of the neutral posture beyond its mean.

A person never comes back to quite the same rest between motions (P1's real days: the rests' levels
spread by 0.9-1.5 deg on the median angle, docs/runs.md); the chain
measures every motion from the one rest it calibrated on, so a later session's motions carry the
difference of two rests. ``rest_spread`` measures the scatter from a labelled recording;
``bomi.chain.rest_offsets`` turns it into training copies.
"""
from __future__ import annotations

import numpy as np

from bomi.classifier import NEUTRAL_LABEL
from bomi.features import run_edges

MIN_RESTS = 3   # rests a spread is measured from (two degrees of freedom at the least)


def hold_levels(labels: np.ndarray, angles: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """(label, mean of the (n, k) ``angles`` over the run) of each run of one label in (n,) ``labels``, in order."""
    edges = run_edges(labels)
    return [(int(labels[a]), angles[a:b].mean(axis=0)) for a, b in zip(edges[:-1], edges[1:])]


def rest_spread(labels: np.ndarray, angles: np.ndarray) -> np.ndarray | None:
    """(k,) standard deviation of the rests' levels (the mean angles of each run of the neutral
    class) on each of the (n, k) ``angles``; None with fewer than MIN_RESTS rests."""
    rests = np.array([level for label, level in hold_levels(labels, angles) if label == NEUTRAL_LABEL])
    if len(rests) < MIN_RESTS:
        return None
    return rests.std(axis=0, ddof=1)
