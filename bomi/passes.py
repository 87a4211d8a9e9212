"""Passes of the calibration protocol found in a recording, not assumed.

A logger left running between two passes of the protocol (or two sessions pasted into one file)
writes one file whose ``Time`` clock pauses, or restarts, between them (the original logger's int32
millisecond clock pauses between passes, and at the start after its first row: bomi.logger_layout). Every command that reads a
labelled recording splits it here, so that each pass is calibrated on its own neutral posture and
counted as one pass (a day, or a session) by training, evaluation and the twin.

A pass boundary is a step of the clock that goes backwards (a restarted clock), or forwards by
more than PASS_GAP_S *and* more than GAP_RATIO times the file's typical pause (the median of its
steps longer than MIN_PAUSE_S, shorter ones being a few samples lost, when there are at least
MIN_MOVE_PAUSES of them): a file that keeps only the holds (the published 5-day set, `bomi synth`)
pauses 1-3 s at every move, which is not a new pass; a file that keeps its moves has no such pauses.
Either side of a boundary holds at least MIN_PASS_S of rows. A file without a clock (the
published .mat files' ``Time`` is a uint8 counter, not read) is one pass: the class sequence alone
cannot tell, since one pass already repeats it (three repetitions of every motion).

The model file keeps a digest of every run (of equal labels) it was trained on, so that `bomi
evaluate` can say when it tests on rows it trained on (``in_sample_share``).
"""
from __future__ import annotations

import hashlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from bomi.errors import BomiError
from bomi.features import run_edges
from bomi.frames import SAMPLE_RATE_HZ
from bomi.recording import TIME_COLUMN, NodeData, Recording, Signal

PASS_GAP_S = 2.0     # a pause of the clock shorter than this is never a new pass
GAP_RATIO = 2.0      # ... nor one shorter than this many times the file's typical pause (a holds-only file's moves)
MIN_PAUSE_S = 0.25   # a step of the clock up to this long is samples lost, not a pause (a move takes 0.5 s or more)
MIN_MOVE_PAUSES = 5  # fewer pauses are passes, not a holds-only file's moves (a pass has 2 per motion held, 3+ motions)
# A pass of the protocol (bomi.protocol) holds the neutral posture 5 s and at least one motion 5 s
# followed by 5 s of neutral: fewer rows beside a pause are not a pass (the original logger writes a
# row, then pauses at the start) and stay with the pass beside them; a restart of the clock is only
# ever between passes.
MIN_PASS_S = 15.0
# A recording shorter than this cannot hold a posture and the neutral around it (a class's posture
# needs 0.5 s of holding to be measured, tasks/participants/twin.py): nothing can be judged from it.
MIN_JUDGED_S = 1.0   # one second (said so in words)
DIGEST_HEX = 16      # characters kept of each run's sha256 (64 bits: no two runs of real data collide)


@dataclass(frozen=True)
class PassBounds:
    """Rows [start, stop) of one pass, and what ended the previous one (None for the first)."""

    start: int
    stop: int
    cause: str | None = None


def pass_bounds(rec: Recording) -> list[PassBounds]:
    """The passes of ``rec`` by its clock (module docstring); one pass without a clock. A one-line
    BomiError when ``rec`` is too short to judge, or its clock runs backwards within a pass."""
    check_long_enough(rec)
    if rec.time is None:
        return [PassBounds(0, len(rec))]
    steps = np.diff(rec.time)
    pauses = steps[steps > MIN_PAUSE_S]
    typical = float(np.median(pauses)) if len(pauses) >= MIN_MOVE_PAUSES else 0.0
    threshold = max(PASS_GAP_S, GAP_RATIO * typical)
    min_rows = round(MIN_PASS_S * SAMPLE_RATE_HZ)
    bounds, start, cause = [], 0, None
    for edge in np.flatnonzero((steps < 0) | (steps > threshold)) + 1:
        if edge - start < min_rows or len(rec) - edge < min_rows:
            continue   # the rows before the logger's start pause, say: too few to be a pass
        bounds.append(PassBounds(start, int(edge), cause))
        step = steps[edge - 1]
        cause = (f"the clock restarts at row {edge}" if step < 0 else
                 f"a {step:.1f} s gap in {TIME_COLUMN} at row {edge}")
        start = int(edge)
    bounds.append(PassBounds(start, len(rec), cause))
    _check_clock_forwards(rec, steps, bounds)
    return bounds


def check_long_enough(rec: Recording) -> None:
    """One-line BomiError when ``rec`` has fewer rows than MIN_JUDGED_S of samples."""
    least = round(MIN_JUDGED_S * SAMPLE_RATE_HZ)
    if len(rec) < least:
        raise BomiError(f"{rec.source}: {len(rec)} rows, too short to judge: shorter than one second ({least} "
                        f"rows at {SAMPLE_RATE_HZ:g} Hz), the least that holds a posture and its neutral")


def _check_clock_forwards(rec: Recording, steps: np.ndarray, bounds: Sequence[PassBounds]) -> None:
    """One-line BomiError when the clock steps back anywhere but between two passes (a restart)."""
    between = {b.start - 1 for b in bounds[1:]}
    back = [k for k in np.flatnonzero(steps < 0) if k not in between]
    if back:
        k = back[0]
        raise BomiError(f"{rec.source}: {TIME_COLUMN} runs backwards at {np.count_nonzero(steps < 0)} row(s) (at row {k + 1}: "
                        f"{rec.time[k + 1]:.3f} s after {rec.time[k]:.3f} s): a clock restarts only between passes "
                        f"of at least {MIN_PASS_S:g} s; fix or drop the {TIME_COLUMN} column")


def _rows(data: NodeData, rows: slice) -> NodeData:
    return NodeData(**{s.value: getattr(data, s.value)[rows] for s in data.signals})


def cut(rec: Recording, bounds: PassBounds, source: str) -> Recording:
    """Rows ``bounds`` of ``rec`` as a recording named ``source``."""
    rows = slice(bounds.start, bounds.stop)
    return replace(rec, nodes={i: _rows(d, rows) for i, d in rec.nodes.items()},
                   labels=None if rec.labels is None else rec.labels[rows],
                   time=None if rec.time is None else rec.time[rows], source=source)


def pass_name(source: str, k: int, bounds: PassBounds) -> str:
    """How a pass is named in messages: the file, the pass (from 1) and its rows (from 0, inclusive)."""
    return f"{source} pass {k} (rows {bounds.start}-{bounds.stop - 1})"


def class_sequence(labels: np.ndarray) -> tuple[int, ...]:
    """The labels of the runs of equal labels, in order."""
    return tuple(int(v) for v in labels[run_edges(labels)[:-1]])


def passes_text(rec: Recording, bounds: Sequence[PassBounds]) -> str:
    """One line: "FILE: 2 passes: rows 0-8253, 8254-16507 (a 6.2 s gap in Time at row 8254; ...)"."""
    rows = ", ".join(f"{b.start}-{b.stop - 1}" for b in bounds)
    causes = "; ".join(b.cause for b in bounds if b.cause)
    if rec.labels is not None:
        sequences = {class_sequence(rec.labels[b.start:b.stop]) for b in bounds}
        causes += ("; the same class sequence in each" if len(sequences) == 1
                   else "; their class sequences differ")
    return f"{rec.source}: {len(bounds)} passes: rows {rows} ({causes}): each is calibrated and counted as one pass"


def check_class_sets(passes: Sequence[Recording]) -> None:
    """One-line BomiError when the labelled passes of one file hold different classes."""
    sets = [sorted(set(p.labels.tolist())) for p in passes if p.labels is not None]
    if len({tuple(s) for s in sets}) > 1:
        listed = "; ".join(f"{p.source}: {', '.join(f'c{c}' for c in s)}" for p, s in zip(passes, sets))
        raise BomiError(f"passes of different class sets in one file ({listed}): record the missing classes, or "
                        "split it (bomi split) and give the passes you mean to use")


def split_passes(rec: Recording, bounds: Sequence[PassBounds]) -> list[Recording]:
    """The passes ``bounds`` (``pass_bounds``) of ``rec`` as recordings (``rec`` itself when it holds one)."""
    if len(bounds) == 1:
        return [rec]
    return [cut(rec, b, pass_name(rec.source, k, b)) for k, b in enumerate(bounds, start=1)]


def join(passes: Sequence[Recording], source: str) -> Recording:
    """The passes, in order, as one recording named ``source`` (the inverse of ``split_passes``)."""
    first = passes[0]
    nodes = {i: NodeData(**{s.value: np.concatenate([getattr(p.nodes[i], s.value) for p in passes])
                            for s in first.nodes[i].signals}) for i in first.nodes}
    stack = lambda arrays: None if arrays[0] is None else np.concatenate(arrays)  # noqa: E731
    return replace(first, nodes=nodes, labels=stack([p.labels for p in passes]), time=stack([p.time for p in passes]),
                   source=source)


# ------------------------------------------------------------------------------ in-sample checks
def run_digests(rec: Recording) -> list[tuple[int, int, str]]:
    """(start, stop, digest) of every run of equal labels: a hash of its labels and every node's angles."""
    labels = rec.require_labels()
    edges = run_edges(labels)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        h = hashlib.sha256(np.ascontiguousarray(labels[a:b], dtype=np.int64).tobytes())
        for i in rec.node_indices:
            if Signal.ANGLES in rec.nodes[i].signals:
                h.update(np.ascontiguousarray(rec.nodes[i].angles[a:b], dtype=np.float64).tobytes())
        out.append((int(a), int(b), h.hexdigest()[:DIGEST_HEX]))
    return out


def training_digests(recordings: Iterable[Recording]) -> tuple[str, ...]:
    """The digests of every run of the training recordings (stored in the model file), sorted."""
    return tuple(sorted({d for rec in recordings for _, _, d in run_digests(rec)}))


def in_sample_share(rec: Recording, digests: Iterable[str]) -> float:
    """Share of ``rec``'s rows that lie in runs a model with these training digests was trained on."""
    known = set(digests)
    inside = sum(b - a for a, b, d in run_digests(rec) if d in known)
    return inside / len(rec) if len(rec) else 0.0
