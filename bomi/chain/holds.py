"""Cues and movement told apart: where a recording keeps its moves, what the person holds at each row.

A recording's labels are the cues on the screen; a person moves a fraction of a second after each
(``bomi.onsets`` finds each move's onset and offset in the angles). Where the recording keeps its
moves (continuous, neutral between motions), the rows between a cue and the measured onset of its
move still show the posture held before the cue: training reads them as that posture
(``held_labels``), and evaluation scores the holds apart from the transitions, each transition the
measured time from its cue to its move's offset (``MoveAllowances``). A recording that keeps only the
holds (stitched, as P1's five published days) has nothing to tell apart: it is used as it is.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from bomi.frames import SAMPLE_RATE_HZ
from bomi.onsets import Move, MoveKind, find_moves, keeps_moves, row_rate
from bomi.recording import Recording

# A move measured later than this after its cue is not trusted as far as that: the latest plausible
# cue-to-movement time (1 s) and the longest voluntary move of the protocol (2 s), the bounds the
# twin holds a measured timing to (tasks/participants/twin.py, REACTION_BOUNDS_S and ONSET_BOUNDS_S).
MAX_MOVE_END_S = 3.0


def recording_moves(rec: Recording, nodes: Sequence[int]) -> list[Move] | None:
    """The move after every cue of ``rec`` in the angles of ``nodes``; None when the recording keeps
    only the holds (``bomi.onsets.keeps_moves``), has no labels or no angles of those nodes."""
    if rec.labels is None or not all(i in rec.nodes and rec.nodes[i].angles is not None for i in nodes):
        return None
    angles = np.stack([rec.nodes[i].angles for i in nodes], axis=1)
    time = rec.time if rec.time is not None else np.arange(len(rec)) / SAMPLE_RATE_HZ
    moves = find_moves(angles, time, rec.labels)
    return moves if keeps_moves(moves) else None


def held_labels(labels: np.ndarray, moves: Sequence[Move]) -> np.ndarray:
    """The posture held at each row: a cue's label from its move's measured onset on; before it (at
    most MAX_MOVE_END_S after the cue) the label before the cue. A cue whose move was not timed keeps
    its label (nothing measured to tell)."""
    held = np.array(labels, copy=True)
    for move in moves:
        if move.kind is not MoveKind.TIMED or move.onset_s > MAX_MOVE_END_S:
            continue
        held[move.cue_row:move.onset_row] = labels[move.cue_row - 1]
    return held


def as_held(rec: Recording, nodes: Sequence[int]) -> Recording:
    """``rec`` labelled by the posture held (``held_labels``) where it keeps its moves; else ``rec`` itself."""
    moves = recording_moves(rec, nodes)
    return rec if moves is None else replace(rec, labels=held_labels(rec.labels, moves))


@dataclass(frozen=True)
class MoveAllowances:
    """The transition after each cue of a recording that keeps its moves: from the cue to its move's
    measured offset (bounded by MAX_MOVE_END_S); a cue whose move was not timed takes the median of
    the timed ones."""

    cue_rows: np.ndarray    # (k,) the row of each cue
    rows: np.ndarray        # (k,) rows from each cue to the end of its transition
    seconds: np.ndarray     # (k,) the same in seconds
    timed: int              # cues whose move was timed

    @classmethod
    def of(cls, rec: Recording, nodes: Sequence[int]) -> MoveAllowances | None:
        """None when ``rec`` keeps only its holds (or has no timed move)."""
        moves = recording_moves(rec, nodes)
        timed = [m for m in (moves or ()) if m.kind is MoveKind.TIMED]
        if not timed:
            return None
        seconds = np.array([min(m.offset_s, MAX_MOVE_END_S) if m.kind is MoveKind.TIMED else np.nan for m in moves])
        seconds[np.isnan(seconds)] = float(np.median(seconds[~np.isnan(seconds)]))
        rows = np.array([m.offset_row - m.cue_row if m.kind is MoveKind.TIMED and m.offset_s <= MAX_MOVE_END_S
                         else int(np.ceil(s * _rate(rec))) for m, s in zip(moves, seconds)])
        return cls(np.array([m.cue_row for m in moves]), rows, seconds, len(timed))

    def on_hold(self, n: int) -> np.ndarray:
        """(n,) True at the rows of the holds: every row but those from a cue to its transition's end."""
        hold = np.ones(n, dtype=bool)
        for cue, rows in zip(self.cue_rows, self.rows):
            hold[cue:cue + rows] = False
        return hold

    def text(self) -> str:
        """The allowance in words, for the output."""
        others = "" if self.timed == len(self.rows) else ", the others the median"
        return (f"each cue to its move's offset found in the signals ({self.timed} of {len(self.rows)} moves timed"
                f"{others}; median {np.median(self.seconds):.2f} s, {self.seconds.min():.2f}-{self.seconds.max():.2f} s, "
                f"at most {MAX_MOVE_END_S:g} s)")


def _rate(rec: Recording) -> float:
    return row_rate(rec.time) if rec.time is not None else SAMPLE_RATE_HZ
