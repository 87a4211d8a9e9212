"""Recordings in the published dataset's column naming (.mat and .csv), and the project's CSV writer.

Columns per IMU node i (1..6): ``Pitch{i}Raw Roll{i}Raw Yaw{i}Raw`` (fused angles, degrees),
``ACC{i}X/Y/Z``, ``GYRO{i}X/Y/Z``, ``MAG{i}X/Y/Z`` (raw LSB); ``Etiquette`` is the class label and
``Time`` (seconds) is optional. Any subset of nodes may be present, but a present node has all 12.
"""
from __future__ import annotations

import csv
import io
import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io

from bomi.errors import BomiError
from bomi.frames import SAMPLE_RATE_HZ

NODE_INDICES = range(1, 7)
TIME_COLUMN = "Time"
LABEL_COLUMN = "Etiquette"
_SIGNALS = ("angles", "acc", "gyro", "mag")  # column order of the published files


def node_columns(node: int) -> dict[str, tuple[str, str, str]]:
    """The three column names of each signal of one node, keyed by signal."""
    return {
        "angles": (f"Pitch{node}Raw", f"Roll{node}Raw", f"Yaw{node}Raw"),
        "acc": tuple(f"ACC{node}{axis}" for axis in "XYZ"),
        "gyro": tuple(f"GYRO{node}{axis}" for axis in "XYZ"),
        "mag": tuple(f"MAG{node}{axis}" for axis in "XYZ"),
    }


def _flat_columns(node: int) -> list[str]:
    return [name for names in node_columns(node).values() for name in names]


@dataclass
class NodeData:
    """One node's signals, each (n, 3): raw acc/gyro/mag and fused (pitch, roll, yaw) in degrees."""

    acc: np.ndarray
    gyro: np.ndarray
    mag: np.ndarray
    angles: np.ndarray


@dataclass
class Recording:
    """A multi-node recording; ``labels`` and ``time`` are None when the file has no such column."""

    nodes: dict[int, NodeData]
    labels: np.ndarray | None
    time: np.ndarray | None = None
    source: str = "<memory>"

    @property
    def node_indices(self) -> tuple[int, ...]:
        return tuple(sorted(self.nodes))

    def __len__(self) -> int:
        return len(next(iter(self.nodes.values())).angles)

    def require_labels(self) -> np.ndarray:
        if self.labels is None:
            raise BomiError(f"{self.source}: no {LABEL_COLUMN} column (class labels are needed here)")
        return self.labels


@dataclass(frozen=True)
class NodeSample:
    """One node's row: 3-sequences acc, gyro, mag (raw LSB) and angles (pitch, roll, yaw, degrees)."""

    acc: Sequence[float]
    gyro: Sequence[float]
    mag: Sequence[float]
    angles: Sequence[float]


def read_recording(path: str | os.PathLike) -> Recording:
    """Read a .mat (published dataset) or .csv (published naming, project format) recording."""
    path = Path(path)
    if not path.is_file():
        raise BomiError(f"{path}: no such recording file")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        columns = _read_mat_columns(path)
        # The published .mat files carry a uint8 'Time' counter that is not a clock (dataset README).
        columns.pop(TIME_COLUMN, None)
    elif suffix == ".csv":
        columns = _read_csv_columns(path)
    else:
        raise BomiError(f"{path}: unknown recording format '{suffix}' (expected .mat or .csv)")
    return _recording_from_columns(path, columns)


def _read_mat_columns(path: Path) -> dict[str, np.ndarray]:
    try:
        raw = scipy.io.loadmat(path)
    except Exception as exc:  # scipy raises several types for corrupt files
        raise BomiError(f"{path}: not a readable MATLAB file ({exc})") from None
    columns = {}
    for name, value in raw.items():
        if name.startswith("__"):
            continue
        array = np.asarray(value)
        if array.dtype.kind not in "biuf":
            raise BomiError(f"{path}: column {name} is not numeric")
        if array.ndim > 2 or (array.ndim == 2 and min(array.shape) > 1):
            raise BomiError(f"{path}: column {name} is not a single column (shape {array.shape})")
        columns[name] = array.reshape(-1).astype(float)
    return columns


def _read_csv_columns(path: Path) -> dict[str, np.ndarray]:
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:  # -sig: tolerate a byte-order mark
            rows = list(csv.reader(handle))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise BomiError(f"{path}: not a readable CSV file ({exc})") from None
    if not rows:
        raise BomiError(f"{path}: empty file")
    header = [name.strip() for name in rows[0]]
    if len(set(header)) != len(header):
        raise BomiError(f"{path}: duplicate column names in the header")
    body = rows[1:]
    for line, row in enumerate(body, start=2):
        if len(row) != len(header):
            raise BomiError(f"{path}: line {line} has {len(row)} cells, the header has {len(header)}")
    cells = np.array(body, dtype=str).reshape(len(body), len(header))
    columns = {}
    for j, name in enumerate(header):
        try:
            columns[name] = cells[:, j].astype(float)
        except ValueError:
            line = next(i for i, cell in enumerate(cells[:, j], start=2) if not _is_number(cell))
            raise BomiError(f"{path}: column {name}, line {line}: not a number ({str(cells[line - 2, j])!r})") from None
    return columns


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _recording_from_columns(path: Path, columns: dict[str, np.ndarray]) -> Recording:
    present = [i for i in NODE_INDICES if any(name in columns for name in _flat_columns(i))]
    if not present:
        raise BomiError(f"{path}: no IMU node columns (expected e.g. Pitch1Raw, ACC1X, ... for nodes 1..6)")
    for i in present:
        for name in _flat_columns(i):
            if name not in columns:
                raise BomiError(f"{path}: node {i} is incomplete, column {name} is missing")
    used = [name for i in present for name in _flat_columns(i)]
    used += [name for name in (TIME_COLUMN, LABEL_COLUMN) if name in columns]
    length = len(columns[used[0]])
    if length == 0:
        raise BomiError(f"{path}: no samples (empty file)")
    for name in used:
        if len(columns[name]) != length:
            raise BomiError(f"{path}: column {name} has {len(columns[name])} rows, {used[0]} has {length}")
        bad = np.flatnonzero(~np.isfinite(columns[name]))
        if bad.size:
            raise BomiError(f"{path}: column {name} has a missing/NaN/inf value at row {bad[0] + 1}")
    labels = None
    if LABEL_COLUMN in columns:
        values = columns[LABEL_COLUMN]
        if np.any(values != np.round(values)) or np.any(values < 0):
            raise BomiError(f"{path}: column {LABEL_COLUMN} must hold non-negative whole class labels")
        labels = values.astype(np.int64)
    nodes = {
        i: NodeData(**{signal: np.column_stack([columns[n] for n in names])
                       for signal, names in node_columns(i).items()})
        for i in present
    }
    return Recording(nodes=nodes, labels=labels, time=columns.get(TIME_COLUMN), source=str(path))


def _header(nodes: Sequence[int], labelled: bool) -> list[str]:
    return [TIME_COLUMN] + [name for i in nodes for name in _flat_columns(i)] + ([LABEL_COLUMN] if labelled else [])


def _format_row(time: float, samples: Sequence[NodeSample], label: int | None) -> str:
    values = [time] + [v for s in samples for signal in _SIGNALS for v in getattr(s, signal)]
    cells = [repr(float(v)) for v in values] + ([str(int(label))] if label is not None else [])
    return ",".join(cells) + "\n"


def write_recording(path: str | os.PathLike, rec: Recording, rate_hz: float = SAMPLE_RATE_HZ) -> None:
    """Write ``rec`` as CSV (Time from ``rec.time`` or sample index / rate); replaces ``path`` atomically."""
    path = Path(path)
    nodes = rec.node_indices
    time = rec.time if rec.time is not None else np.arange(len(rec)) / rate_hz
    buffer = io.StringIO()
    buffer.write(",".join(_header(nodes, rec.labels is not None)) + "\n")
    for k in range(len(rec)):
        samples = [NodeSample(**{s: getattr(rec.nodes[i], s)[k] for s in _SIGNALS}) for i in nodes]
        buffer.write(_format_row(time[k], samples, None if rec.labels is None else rec.labels[k]))
    _atomic_write_text(path, buffer.getvalue())


def _atomic_write_text(path: Path, text: str) -> None:
    """Write to a temporary file beside ``path`` then rename, so ``path`` is never half-written."""
    handle, temp = tempfile.mkstemp(dir=path.parent or ".", prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w", encoding="utf-8", newline="") as out:
            out.write(text)
        os.replace(temp, path)
    except BaseException:
        os.unlink(temp)
        raise


class RecordingWriter:
    """Incremental CSV recording: rows are buffered and written in whole segments.

    Every flush appends complete lines with a single write, so an interrupted capture leaves a
    valid file holding every flushed row. Refuses to replace an existing file unless ``overwrite``.
    """

    def __init__(self, path: str | os.PathLike, nodes: Sequence[int], *, labelled: bool = True,
                 segment_rows: int = 301, overwrite: bool = False):
        self.path = Path(path)
        self.nodes = tuple(sorted(nodes))
        if not self.nodes or any(i not in NODE_INDICES for i in self.nodes):
            raise BomiError(f"{self.path}: node indices must be within 1..6, got {list(nodes)}")
        self.labelled = labelled
        self.segment_rows = segment_rows
        self.rows_written = 0
        self._pending: list[str] = []
        try:
            self._file = open(self.path, "w" if overwrite else "x", encoding="utf-8", newline="")
        except FileExistsError:
            raise BomiError(f"{self.path}: file exists, not overwriting it") from None
        except OSError as exc:
            raise BomiError(f"{self.path}: cannot create the recording ({exc.strerror})") from None
        self._file.write(",".join(_header(self.nodes, labelled)) + "\n")
        self._file.flush()

    def append(self, time: float, samples: Mapping[int, NodeSample], label: int | None = None) -> None:
        """Add one row: ``samples`` maps every node index of the writer to its NodeSample."""
        if set(samples) != set(self.nodes):
            raise ValueError(f"row has nodes {sorted(samples)}, the recording has {list(self.nodes)}")
        if self.labelled == (label is None):
            raise ValueError("a label is required exactly when the recording is labelled")
        self._pending.append(_format_row(time, [samples[i] for i in self.nodes], label))
        if len(self._pending) >= self.segment_rows:
            self.flush()

    def flush(self) -> None:
        if self._pending:
            self._file.write("".join(self._pending))
            self.rows_written += len(self._pending)
            self._pending.clear()
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self.flush()
            self._file.close()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
