"""Where a recording keeps its moves, when each move begins and ends, from the signals.

The labels of a continuous recording (``bomi record``: every row kept, neutral between two motions)
are the cues on the screen: a person moves some time after each cue. Each cue's move is found in
the angles, not in the label: the angles are projected on the way from the level held before the cue
to the level held late in the cued run, low-passed, and differentiated; the move's onset is the last
time before the peak speed at which the speed was below ``SPEED_SHARE`` of that peak, its offset
the first time after the peak at which it falls below it again (the usual kinematic criterion of a
share of the peak velocity). A file that keeps only the holds (stitched) jumps at each cue: its moves
are ``MoveKind.JUMP``, not timed.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np
import scipy.signal

from bomi.frames import SAMPLE_RATE_HZ

SPEED_SHARE = 0.1           # a move runs while its speed is above this share of its peak speed
SMOOTHING_HZ = 4.0          # low-pass of the projected angle before differentiating (moves are below 2 Hz)
BASELINE_S = 0.5            # the level before a cue: the median of this long before it
MIN_MOVE_DEG = 3.0          # a change of level smaller than this (all angles) is no move to time
JUMP_SHARE = 0.5            # a run whose first two rows are already this far along the way was stitched on


class MoveKind(Enum):
    """What a cue's run shows."""

    TIMED = "timed"              # a move with an onset and an offset after the cue
    JUMP = "jump"                # the signal jumps at the cue: the recording kept only the holds
    TOO_SMALL = "too small"      # the level hardly changes (fewer than MIN_MOVE_DEG)
    ANTICIPATED = "anticipated"  # already moving at the cue: no onset after it
    UNFINISHED = "unfinished"    # still moving when the run ends


@dataclass(frozen=True)
class Move:
    """The move after the cue at ``cue_row`` (to class ``label``): onset and offset in seconds after
    the cue (None unless ``kind`` is TIMED), and the rows where they fall."""

    cue_row: int
    label: int
    kind: MoveKind
    onset_s: float | None = None
    offset_s: float | None = None
    onset_row: int | None = None
    offset_row: int | None = None

    @property
    def duration_s(self) -> float | None:
        return None if self.onset_s is None or self.offset_s is None else self.offset_s - self.onset_s


def cue_rows(labels: np.ndarray) -> np.ndarray:
    """The rows where the label changes (each a cue), the first row excluded."""
    return np.flatnonzero(np.diff(np.asarray(labels).astype(int))) + 1


def smoothed(x: np.ndarray, rate_hz: float = SAMPLE_RATE_HZ) -> np.ndarray:
    """(n, ...) signals low-passed at SMOOTHING_HZ, zero phase (no shift of the onsets)."""
    b, a = scipy.signal.butter(2, SMOOTHING_HZ, "low", fs=rate_hz)
    return scipy.signal.filtfilt(b, a, x, axis=0) if len(x) > 3 * max(len(a), len(b)) else x


def row_rate(time: np.ndarray) -> float:
    """Rows per second: the median step of a recording's clock (steps of 0, a row repeated, and the
    pauses of a logger's clock left aside by the median), else the sample rate."""
    steps = np.diff(np.asarray(time, dtype=float))
    steps = steps[steps > 0]
    return 1.0 / float(np.median(steps)) if len(steps) else SAMPLE_RATE_HZ


def find_moves(angles: np.ndarray, time: np.ndarray, labels: np.ndarray) -> list[Move]:
    """The move after every cue of a recording: ``angles`` (n, ...) degrees, ``time`` (n,) s, ``labels``
    (n,) the cue in force at each row."""
    flat = np.asarray(angles, dtype=float).reshape(len(angles), -1)
    rate = row_rate(time)
    smooth = smoothed(flat, rate)
    edges = np.r_[0, cue_rows(labels), len(labels)]
    baseline = int(round(BASELINE_S * rate))
    return [cue_move(flat, smooth, time, int(labels[cue]), max(int(cue) - baseline, int(edges[k - 1])), int(cue),
                     int(edges[k + 1]))
            for k, cue in enumerate(edges[1:-1], start=1)]


def cue_move(raw: np.ndarray, smooth: np.ndarray, time: np.ndarray, label: int, baseline: int, cue: int,
             stop: int) -> Move:
    """The move of the run ``[cue, stop)``, its level before the cue held in rows ``[baseline, cue)``, in
    (n, k) ``raw`` angles and their ``smooth`` copy."""
    old = np.median(raw[baseline:cue], axis=0)
    new = np.median(raw[(cue + stop) // 2:stop], axis=0)
    way = new - old
    size = float(np.linalg.norm(way))
    if size < MIN_MOVE_DEG or stop - cue < 4:
        return Move(cue, label, MoveKind.TOO_SMALL)
    if float(np.mean((raw[cue:cue + 2] - old) @ way)) / size ** 2 > JUMP_SHARE:
        return Move(cue, label, MoveKind.JUMP)
    # the way along the move, before the cue (back to the baseline) and up to the run's middle
    start, end = baseline, (cue + stop) // 2
    along = (smooth[start:end] - old) @ way / size
    speed = np.gradient(along)   # per row: only its share of the peak counts (a row's Time may repeat, or pause)
    peak = cue - start + int(np.argmax(speed[cue - start:]))
    threshold = SPEED_SHARE * speed[peak]
    slow_before = np.flatnonzero(speed[:peak] < threshold)
    slow_after = np.flatnonzero(speed[peak:] < threshold)
    if not len(slow_before) or slow_before[-1] + 1 < cue - start:
        return Move(cue, label, MoveKind.ANTICIPATED)
    if not len(slow_after):
        return Move(cue, label, MoveKind.UNFINISHED)
    onset, offset = start + int(slow_before[-1]) + 1, start + peak + int(slow_after[0])
    return Move(cue, label, MoveKind.TIMED, float(time[onset] - time[cue]), float(time[offset] - time[cue]),
                onset, offset)


def keeps_moves(moves: list[Move]) -> bool:
    """A recording keeps its moves (continuous) when its timed moves outnumber its jumps."""
    timed = sum(m.kind is MoveKind.TIMED for m in moves)
    return timed > sum(m.kind is MoveKind.JUMP for m in moves)
