"""Per-episode metrics: pure functions over the arrays an episode logs.

Decision-stream metrics take one entry per classifier decision (one per IMU sample once the
window is full): the class the virtual participant intended and the class the chain output.
A decision made within ``allowance`` samples after the intended class changed is part of the
transition (the window still holds the previous posture): it counts towards the latency, not
as a misclassification.  Arm metrics take one entry per 60 Hz control tick.
"""
from __future__ import annotations

import numpy as np


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, length) of every run of True in a boolean array."""
    padded = np.r_[False, np.asarray(mask, dtype=bool), False].astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b - a)) for a, b in zip(edges[::2], edges[1::2])]


def in_transition(intended: np.ndarray, allowance: int) -> np.ndarray:
    """True for the first ``allowance`` decisions after each change of the intended class."""
    intended = np.asarray(intended)
    mask = np.zeros(intended.shape, dtype=bool)
    for change in np.flatnonzero(intended[1:] != intended[:-1]) + 1:
        mask[change:change + allowance] = True
    return mask


def misclassified(intended: np.ndarray, decided: np.ndarray, allowance: int) -> np.ndarray:
    """Decisions that differ from the intended class outside transitions."""
    intended, decided = np.asarray(intended), np.asarray(decided)
    return (intended != decided) & ~in_transition(intended, allowance)


def realtime_accuracy(intended: np.ndarray, decided: np.ndarray, allowance: int) -> float:
    """Fraction of settled decisions (outside transitions) equal to the intended class."""
    settled = ~in_transition(intended, allowance)
    if not settled.any():
        return float("nan")
    return float(np.mean(np.asarray(intended)[settled] == np.asarray(decided)[settled]))


def longest_error_run_ms(errors: np.ndarray, sample_period_s: float) -> float:
    """Duration of the longest run of consecutive misclassified decisions, in ms."""
    longest = max((length for _, length in runs(errors)), default=0)
    return 1000.0 * longest * sample_period_s


def error_destinations(decided: np.ndarray, errors: np.ndarray, neutral: int) -> dict[str, int]:
    """How many misclassified decisions fell to neutral and how many to another active class."""
    wrong = np.asarray(decided)[np.asarray(errors, dtype=bool)]
    return {"to_neutral": int(np.sum(wrong == neutral)), "to_other_class": int(np.sum(wrong != neutral))}


def decision_latencies(intended: np.ndarray, decided: np.ndarray, neutral: int) -> np.ndarray:
    """Samples from each motion onset (intended change to an active class) to the first decision
    of that class; onsets whose intent ended before the chain output it are left out."""
    intended, decided = np.asarray(intended), np.asarray(decided)
    latencies = []
    for onset in np.flatnonzero(np.r_[True, intended[1:] != intended[:-1]]):
        label = intended[onset]
        if label == neutral:
            continue
        end = onset
        while end < len(intended) and intended[end] == label:
            end += 1
        hits = np.flatnonzero(decided[onset:end] == label)
        if hits.size:
            latencies.append(int(hits[0]))
    return np.asarray(latencies, dtype=int)


def unintended_displacement_mm(hand_pos: np.ndarray, intended_dir: np.ndarray) -> float:
    """Hand travel (mm) not along the direction the person wanted at that tick.

    ``intended_dir[i]`` is the wanted unit direction for the step i -> i+1, or zero when the
    person wanted the hand still (then all of the step is unintended); travel backwards along
    the wanted direction is unintended too.
    """
    step = np.diff(np.asarray(hand_pos, dtype=float), axis=0)
    wanted = np.asarray(intended_dir, dtype=float)[: len(step)]
    along = np.einsum("ij,ij->i", step, wanted)
    sideways = step - np.clip(along, 0.0, None)[:, None] * wanted
    return 1000.0 * float(np.sum(np.linalg.norm(sideways, axis=1)))


def count_changes(values: list | np.ndarray) -> int:
    """Number of ticks where the value differs from the previous tick (e.g. mode switches)."""
    values = list(values)
    return sum(a != b for a, b in zip(values, values[1:]))


def cube_drops(cube_z: np.ndarray, touching: np.ndarray, fall_m: float = 0.02, horizon: int = 60) -> int:
    """Times a cube left the fingers and then fell more than ``fall_m`` within ``horizon`` ticks.

    ``cube_z`` and ``touching`` are (ticks, cubes).  A cube set down on its support falls only
    the release gap, so a placement is not a drop.
    """
    cube_z, touching = np.asarray(cube_z, dtype=float), np.asarray(touching, dtype=bool)
    drops = 0
    for k in range(cube_z.shape[1]):
        for release in np.flatnonzero(touching[:-1, k] & ~touching[1:, k]) + 1:
            after = cube_z[release:release + horizon, k]
            drops += int(cube_z[release, k] - after.min() > fall_m)
    return drops
