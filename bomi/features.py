"""Windows and the paper's feature vectors, as plain array functions shared by batch and streaming.

Every node contributes a 6-value state per sample: neutral-subtracted (pitch, roll, yaw) and gyro
(x, y, z). A feature kind selects components from those states (``component_index``):
- FV1: pitch, roll, yaw of the first node (node 1); pitch and roll of every other node;
- FV2: FV1 plus every node's gyroscope x, y, z;
- FV3: the FV2 components over two sub-windows (halves); per half, the minimum, maximum, mean and
  absolute sum of every component.
FV1 and FV2 are reduced over the window by its mean (a window of 8 smooths single-sample jumps).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FEATURE_KINDS = ("FV1", "FV2", "FV3")
# Longest window a spec may ask for: 1024 samples are 16 s at 62.5 Hz, longer than any motion held in
# calibration (5 s), so no single-label window that long exists to train on; a bound keeps a bad file
# from allocating without limit.
MAX_WINDOW = 1024
NODE_STATE = ("pitch", "roll", "yaw", "gyro_x", "gyro_y", "gyro_z")


def component_index(n_nodes: int, kind: str) -> np.ndarray:
    """Positions, in the flattened (n_nodes * 6) node states, of the components ``kind`` uses."""
    if kind not in FEATURE_KINDS:
        raise ValueError(f"unknown feature vector {kind!r}, expected one of {', '.join(FEATURE_KINDS)}")
    width = len(NODE_STATE)
    index = [0, 1, 2] + [node * width + k for node in range(1, n_nodes) for k in (0, 1)]
    if kind != "FV1":
        index += [node * width + k for node in range(n_nodes) for k in (3, 4, 5)]
    return np.array(index, dtype=np.intp)


def feature_columns(kind: str, channels: int, which: np.ndarray) -> np.ndarray:
    """The columns of the features of ``channels`` components that the components ``which`` alone
    make, in the order ``features`` of those components alone gives them (FV3: each of its 8
    statistics, [min, max, mean, absolute sum] of the first half then the second, is a block of
    ``channels`` columns)."""
    which = np.asarray(which, dtype=np.intp)
    if kind != "FV3":
        return which
    return (np.arange(8)[:, None] * channels + which[None, :]).ravel()


def sliding_windows(samples: np.ndarray, length: int = 8, stride: int = 1) -> np.ndarray:
    """(n, C) samples -> (m, length, C) read-only view of the windows, the k-th ending at sample
    ``length - 1 + k * stride``."""
    if length < 1 or stride < 1:
        raise ValueError("window length and stride must be >= 1")
    if len(samples) < length:
        return np.empty((0, length) + samples.shape[1:], dtype=samples.dtype)
    view = np.lib.stride_tricks.sliding_window_view(samples, length, axis=0)
    return np.moveaxis(view, -1, 1)[::stride]


def window_ends(n_samples: int, length: int = 8, stride: int = 1) -> np.ndarray:
    """Index of the last sample of every window ``sliding_windows`` cuts from ``n_samples`` samples."""
    return np.arange(length - 1, n_samples, stride)


def run_edges(labels: np.ndarray) -> np.ndarray:
    """(runs + 1,) the first sample of every run of equal labels, then ``len(labels)``: run k is
    samples ``edges[k]:edges[k + 1]``."""
    return np.r_[np.flatnonzero(np.diff(labels, prepend=labels[0] - 1)), len(labels)]


def single_label_windows(labels: np.ndarray, length: int = 8, stride: int = 1) -> np.ndarray:
    """Boolean mask over windows: True where all samples of the window carry the same label."""
    windows = sliding_windows(np.asarray(labels)[:, None], length, stride)[:, :, 0]
    return np.all(windows == windows[:, :1], axis=1)


def features(kind: str, windows: np.ndarray) -> np.ndarray:
    """(m, L, C) windows of the ``kind`` components -> (m, F) feature vectors."""
    if kind == "FV3":
        return fv3(windows)
    if kind in ("FV1", "FV2"):
        return windows.mean(axis=1)
    raise ValueError(f"unknown feature vector {kind!r}")


def window_features(samples: np.ndarray, kind: str, length: int = 8, stride: int = 1,
                    select: np.ndarray | None = None) -> np.ndarray:
    """``features`` of every window ``sliding_windows`` cuts from (n, C) samples (``select``: of the
    windows this boolean mask keeps), without cutting them: FV3's half-window statistics are computed
    once per run of ``length // 2`` consecutive samples (``_run_stats``), and each window takes its
    two halves' (several times less work); with ``select``, only the runs of the kept windows
    (``_half_stats``). The same operations on the same samples in the same order as ``fv3``: the
    same bits (tests/test_features.py)."""
    if kind != "FV3":
        out = features(kind, sliding_windows(samples, length, stride))
        return out if select is None else out[select]
    if length % 2:
        raise ValueError(f"FV3 needs an even window length (two equal sub-windows), got {length}")
    half = length // 2
    if select is None:
        if len(samples) < length:
            return np.empty((0, 8 * samples.shape[1]))
        stats = _run_stats(samples, half) if samples.shape[1] > 1 else _half_stats(sliding_windows(samples, half))
        first = len(samples) - length + 1                    # runs that start a window
        return np.hstack([stats[:first:stride], stats[half:half + first:stride]])
    starts = (window_ends(len(samples), length, stride) - (length - 1))[select]
    runs = sliding_windows(samples, half)
    stats = _half_stats(runs[np.concatenate([starts, starts + half])])
    return np.hstack([stats[:len(starts)], stats[len(starts):]])


def fv3(windows: np.ndarray) -> np.ndarray:
    """Min, max, mean, absolute sum of every component over each half of the window.

    Layout: [min, max, mean, abssum of half a, then the same of half b], each over all components.
    """
    m, length, channels = windows.shape
    if length % 2:
        raise ValueError(f"FV3 needs an even window length (two equal sub-windows), got {length}")
    return _half_stats(windows.reshape(2 * m, length // 2, channels)).reshape(m, 8 * channels)


def _half_stats(runs: np.ndarray) -> np.ndarray:
    """(k, h, C) runs of h consecutive samples -> (k, 4 C): min, max, mean and absolute sum over each
    run.  One implementation for the stream (a window's two halves) and the batch (every run of a
    recording): the same reductions, so both agree bit for bit (tests/test_features.py).  ufunc
    reductions rather than ndarray methods: this runs once per sample in the stream."""
    size = runs.shape[1]
    return np.concatenate((np.minimum.reduce(runs, axis=1), np.maximum.reduce(runs, axis=1),
                           np.add.reduce(runs, axis=1) / size, np.add.reduce(np.abs(runs), axis=1)), axis=1)


def _run_stats(samples: np.ndarray, size: int) -> np.ndarray:
    """(n, C) samples -> (n - size + 1, 4 C): ``_half_stats`` of every run of ``size`` consecutive
    samples, in ``size`` passes over whole columns rather than reductions over a strided view of the
    runs (10x faster on a recording). Over several channels, numpy reduces a run's axis one sample
    after the other, a sum from its identity +0.0: so do these passes (min(min(x0, x1), x2)...,
    ((0.0 + x0) + x1) + x2...), giving the same bits, signed zeros included (tests/test_features.py).
    A single channel's runs numpy reduces along its innermost axis (sums pairwise from 8 samples on):
    ``window_features`` leaves those to ``_half_stats`` (a spec has 3 components at least)."""
    n = len(samples) - size + 1
    low = high = samples[:n]
    total = 0.0 + low
    absolute = np.abs(low)
    for k in range(1, size):
        run = samples[k:k + n]
        low, high = np.minimum(low, run), np.maximum(high, run)
        total, absolute = total + run, absolute + np.abs(run)
    return np.concatenate((low, high, total / size, absolute), axis=1)


@dataclass(frozen=True)
class FeatureSpec:
    """What a model was trained on: the feature kind, its nodes, and the window."""

    kind: str
    nodes: tuple[int, ...]
    window: int = 8
    stride: int = 1

    def __post_init__(self) -> None:
        component_index(len(self.nodes), self.kind)  # validates kind
        if not (1 <= self.window <= MAX_WINDOW and 1 <= self.stride <= self.window):
            raise ValueError(f"window length must be in 1..{MAX_WINDOW} and stride in 1..window, "
                             f"got window {self.window}, stride {self.stride}")
        if self.kind == "FV3" and self.window % 2:
            raise ValueError(f"FV3 needs an even window length, got {self.window}")

    @property
    def components(self) -> np.ndarray:
        return component_index(len(self.nodes), self.kind)


class WindowBuffer:
    """Streaming window of the last ``length`` rows; ``push`` returns the full window or None.

    Rows are written twice into a buffer of 2 * length so the current window is always one
    contiguous slice (no copy, no reordering).
    """

    def __init__(self, length: int, channels: int, stride: int = 1):
        self.length = length
        self.stride = stride
        self._buffer = np.zeros((2 * length, channels))
        self._count = 0

    def push(self, row: np.ndarray) -> np.ndarray | None:
        slot = self._count % self.length
        self._buffer[slot] = row
        self._buffer[slot + self.length] = row
        self._count += 1
        if self._count < self.length or (self._count - self.length) % self.stride:
            return None
        start = slot + 1
        return self._buffer[start:start + self.length]

    def push_many(self, rows: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
        """``features(kind, window)`` of every window n ``push`` calls of (n, C) ``rows`` return, in order,
        as (w, F); and the positions in ``rows`` of the pushes that return one. The buffer ends as n
        pushes leave it. The features come by ``window_features`` from the rows the windows span (FV3's
        half-window statistics once per run of samples, not per window: the same bits)."""
        length, count, n = self.length, self._count, len(rows)
        before = min(count, length - 1)            # the rows a window ending at the first new row reaches back to
        start = (count - before) % length
        history = np.concatenate([self._buffer[start:start + before], rows])
        pushes = count + 1 + np.arange(n)          # each row's push number
        made = np.flatnonzero((pushes >= length) & ((pushes - length) % self.stride == 0))
        # the first window's first row in ``history``: from there on, every stride-th window is one made
        first = int(made[0]) + before - (length - 1) if len(made) else len(history)
        out = window_features(history[first:], kind, length, self.stride)
        for k in range(max(0, n - length), n):     # the rows still in the buffer, each in its two slots
            slot = (count + k) % length
            self._buffer[slot] = self._buffer[slot + length] = rows[k]
        self._count = count + n
        return out, made

    def reset(self) -> None:
        self._count = 0
