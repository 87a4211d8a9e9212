"""Recordings as they come (.mat and .csv), and the project's CSV writer.

Two published namings of a node's columns are read:
- indexed, node i in 1..6 (the 5-day dataset, and what the project writes): ``Pitch{i}Raw Roll{i}Raw
  Yaw{i}Raw`` (fused angles, degrees), ``ACC{i}X/Y/Z``, ``GYRO{i}X/Y/Z``, ``MAG{i}X/Y/Z`` (raw);
- node-less, node 1 (the original host software's logger with one node): ``PitchRaw RollRaw YawRaw``,
  ``ACCX/Y/Z``, ``GYROX/Y/Z``, ``MAGX/Y/Z``.
``Etiquette`` is the class label; a CSV's numeric ``Time`` (seconds) is kept, and a .mat's when it
is a clock: floating-point seconds, or the original logger's int32 milliseconds (bomi.passes finds
the passes of the protocol by it; the published files' uint8 ``Time`` counter is not a clock). Any subset of nodes may
be present and, per node, any subset of its four signals (angles, acc, gyro, mag), each with all
three columns. Every other variable, of any type, is ignored and listed in ``Recording.ignored``.
What a recording must hold depends on what is done with it: ``Recording.require`` says, in one
line, which columns are missing for that purpose.
"""
from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import numpy as np
import scipy.io

from bomi.errors import BomiError
from bomi.files import check_input, write_text
from bomi.frames import SAMPLE_RATE_HZ

NODE_INDICES = range(1, 7)
TIME_COLUMN = "Time"
LABEL_COLUMN = "Etiquette"
RECORDING_SUFFIXES = (".mat", ".csv")
# Raw values are 16-bit counts and angles degrees: anything beyond this is a garbled cell, and would
# overflow the filters and features downstream.
MAX_ABS_VALUE = 1e6
MAX_LABEL = 2**31 - 1  # labels are ints; a larger value is a garbled cell, not a class
LOGGER_NODE = 1  # the node the original logger's node-less column names belong to
# The most rows a recording may have: 67 minutes at 62.5 Hz, 15 times P1's recorded day (16,555 rows;
# a calibration pass lasts minutes). Reading a CSV of P1's 37 columns peaks near 10 kB a row (0.97 GB
# for 99,330 rows, measured), so this bounds a read near 2.5 GB, where a million rows ran out of memory.
MAX_RECORDING_ROWS = 250_000
# The smallest difference between two classes' postures a calibration can hold: a motion class is
# held 10 deg or more from the neutral posture (P1's smallest, head yaw: 12 deg; dataset README).
# Every angle within +-pi and the classes' postures at most pi apart, yet differing by more than
# this in radians, are angles in radians.
MIN_POSTURE_RAD = math.radians(10.0) / 2
POSTURE_ROWS = 31   # 0.5 s: fewer rows of a class do not show its posture (tasks/participants/twin.py)
LOGGER_CLOCK_DTYPE = np.dtype(np.int32)  # the original logger's Time: an int32 count of ...
LOGGER_TICKS_PER_S = 1000               # ... milliseconds


class Signal(str, Enum):
    """A node's signals, in the column order of the published files."""

    ANGLES = "angles"
    ACC = "acc"
    GYRO = "gyro"
    MAG = "mag"


RAW_SIGNALS = (Signal.ACC, Signal.GYRO, Signal.MAG)
_SIGNAL_TEXT = {Signal.ANGLES: "angles", Signal.ACC: "ACC", Signal.GYRO: "GYRO", Signal.MAG: "MAG"}


def node_columns(node: int | None) -> dict[Signal, tuple[str, str, str]]:
    """The three column names of each signal of one node, keyed by signal (``None``: the node-less names)."""
    i = "" if node is None else node
    return {
        Signal.ANGLES: (f"Pitch{i}Raw", f"Roll{i}Raw", f"Yaw{i}Raw"),
        Signal.ACC: tuple(f"ACC{i}{axis}" for axis in "XYZ"),
        Signal.GYRO: tuple(f"GYRO{i}{axis}" for axis in "XYZ"),
        Signal.MAG: tuple(f"MAG{i}{axis}" for axis in "XYZ"),
    }


def _flat_columns(node: int, signals: Iterable[Signal] = tuple(Signal)) -> list[str]:
    columns = node_columns(node)
    return [name for signal in signals for name in columns[signal]]


# column name -> (node, signal, axis) for both namings
_COLUMN_MEANING: dict[str, tuple[int, Signal, int]] = {
    name: (LOGGER_NODE if node is None else node, signal, axis)
    for node in (None, *NODE_INDICES) for signal, names in node_columns(node).items() for axis, name in enumerate(names)
}


@dataclass
class NodeData:
    """One node's signals, each (n, 3) or None when the recording does not hold it: raw acc/gyro/mag
    and fused (pitch, roll, yaw) in degrees."""

    acc: np.ndarray | None = None
    gyro: np.ndarray | None = None
    mag: np.ndarray | None = None
    angles: np.ndarray | None = None

    @property
    def signals(self) -> tuple[Signal, ...]:
        return tuple(s for s in Signal if getattr(self, s.value) is not None)

    def __len__(self) -> int:
        return len(getattr(self, self.signals[0].value))


@dataclass
class Recording:
    """A multi-node recording; ``labels`` and ``time`` are None when the file has no such column.

    ``ignored``: the file's variables the chain does not use (``bomi train --verbose`` lists them).
    """

    nodes: dict[int, NodeData]
    labels: np.ndarray | None
    time: np.ndarray | None = None
    source: str = "<memory>"
    ignored: tuple[str, ...] = ()

    @property
    def node_indices(self) -> tuple[int, ...]:
        return tuple(sorted(self.nodes))

    def __len__(self) -> int:
        return len(next(iter(self.nodes.values())))

    def require_labels(self) -> np.ndarray:
        if self.labels is None:
            raise BomiError(f"{self.source}: no {LABEL_COLUMN} column (class labels are needed here)")
        return self.labels

    def require(self, nodes: Iterable[int], signals: Iterable[Signal], purpose: str) -> None:
        """One-line BomiError naming the missing columns unless every node in ``nodes`` has ``signals``."""
        nodes, signals = list(nodes), list(signals)
        missing = []
        for i in nodes:
            if i not in self.nodes:
                missing.append(f"node {i} (none of its columns)")
                continue
            missing += [name for s in signals if getattr(self.nodes[i], s.value) is None
                        for name in node_columns(i)[s]]
        if not missing:
            return
        what = ", ".join(_SIGNAL_TEXT[s] for s in signals)
        hint = ""
        if Signal.ANGLES in signals and all(i in self.nodes and set(RAW_SIGNALS) <= set(self.nodes[i].signals)
                                            for i in nodes):
            hint = " (it has raw ACC/GYRO/MAG: `bomi fuse` computes the angles)"
        raise BomiError(f"{self.source}: {purpose} needs {what} of node(s) {nodes}; missing "
                        f"{', '.join(missing)}{hint}")

    def describe(self) -> str:
        """One line: samples, each node's signals, labels."""
        nodes = "; ".join(f"node {i}: {', '.join(_SIGNAL_TEXT[s] for s in self.nodes[i].signals)}"
                          for i in self.node_indices)
        labels = "no labels" if self.labels is None else f"labels {sorted(set(self.labels.tolist()))}"
        return f"{self.source}: {len(self)} samples; {nodes}; {labels}"


@dataclass(frozen=True)
class NodeSample:
    """One node's row: 3-sequences acc, gyro, mag (raw LSB) and angles (pitch, roll, yaw, degrees)."""

    acc: Sequence[float]
    gyro: Sequence[float]
    mag: Sequence[float]
    angles: Sequence[float]


def read_recording(path: str | os.PathLike) -> Recording:
    """Read a .mat (MATLAB v5) or .csv recording in either naming; other variables are ignored. Its rows
    are counted before anything is loaded (at most MAX_RECORDING_ROWS); angles in radians are refused."""
    path = check_input(path, "recording")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        check_recording_rows(_mat_rows(path), str(path))
        # The published .mat files carry a uint8 'Time' counter that is not a clock (dataset README).
        rec = _recording_from_variables(path, _read_mat_variables(path), from_csv=False)
    elif suffix == ".csv":
        check_recording_rows(_csv_rows(path), str(path))
        rec = _recording_from_variables(path, _read_csv_variables(path), from_csv=True)
    else:
        raise BomiError(f"{path}: unknown recording format '{suffix}' (expected {' or '.join(RECORDING_SUFFIXES)})")
    check_degrees(rec)
    return rec


def check_recording_rows(rows: int, what: str) -> None:
    """One-line BomiError when a recording of ``rows`` rows (``what``: the file, or what would make it)
    exceeds MAX_RECORDING_ROWS; called before the rows are allocated."""
    if rows > MAX_RECORDING_ROWS:
        raise BomiError(f"{what}: {rows} rows ({rows / SAMPLE_RATE_HZ / 3600:.1f} h at {SAMPLE_RATE_HZ:g} Hz), more "
                        f"than the {MAX_RECORDING_ROWS} ({MAX_RECORDING_ROWS / SAMPLE_RATE_HZ / 3600:.1f} h) a "
                        "recording may have: cut it into shorter recordings")


def check_recording_seconds(seconds: float, what: str) -> None:
    """``check_recording_rows`` for a recording of ``seconds`` at SAMPLE_RATE_HZ yet to be made (a
    protocol `bomi synth` would perform), before anything is allocated."""
    check_recording_rows(math.floor(seconds * SAMPLE_RATE_HZ) + 1, what)


def _mat_rows(path: Path) -> int:
    """The most rows of any variable of a .mat file, from its headers alone (nothing loaded)."""
    try:
        shapes = [shape for _, shape, _ in scipy.io.whosmat(path)]
    except Exception as exc:  # as in _read_mat_variables: several types for corrupt or v7.3 files
        raise BomiError(f"{path}: not a readable MATLAB v5 file ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    return max((max(shape) for shape in shapes if shape), default=0)


def _csv_rows(path: Path) -> int:
    """A CSV file's lines after the header, counted by reading it in blocks (nothing kept)."""
    lines, last = 0, b"\n"
    with open(path, "rb") as handle:
        while block := handle.read(1 << 20):
            lines += block.count(b"\n")
            last = block[-1:]
    return lines + (last != b"\n") - 1


def check_degrees(rec: Recording) -> None:
    """One-line BomiError when a labelled recording's angles look like radians: every angle within
    +-pi, and the median postures of two classes held POSTURE_ROWS or more more than MIN_POSTURE_RAD
    apart, yet never more than pi."""
    nodes = [i for i in rec.node_indices if rec.nodes[i].angles is not None]
    if rec.labels is None or not nodes:
        return
    angles = np.column_stack([rec.nodes[i].angles for i in nodes])
    classes, counts = np.unique(rec.labels, return_counts=True)
    classes = classes[counts >= POSTURE_ROWS]
    if len(classes) < 2 or np.max(np.abs(angles)) > math.pi:
        return
    postures = np.array([np.median(angles[rec.labels == c], axis=0) for c in classes])
    apart = float(np.max(np.ptp(postures, axis=0)))
    if apart > MIN_POSTURE_RAD:
        raise BomiError(f"{rec.source}: every angle is within +-{math.pi:.2f} and the classes' postures differ by at "
                        f"most {apart:.2f}: the angles look like radians; a recording's angles are degrees "
                        f"(multiply by {math.degrees(1.0):.2f})")


def _read_mat_variables(path: Path) -> dict[str, object]:
    try:
        raw = scipy.io.loadmat(path)
    except Exception as exc:  # scipy raises several types for corrupt or v7.3 (HDF5) files
        raise BomiError(f"{path}: not a readable MATLAB v5 file ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    return {name: value for name, value in raw.items() if not name.startswith("__")}


def _read_csv_variables(path: Path) -> dict[str, object]:
    """Column name -> (n,) array of the cells as text (converted later, only for the columns used)."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:  # -sig: tolerate a byte-order mark
            rows = list(csv.reader(handle))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise BomiError(f"{path}: not a readable CSV file ({exc})") from None
    while rows and not any(cell.strip() for cell in rows[-1]):  # trailing blank lines
        rows.pop()
    if not rows:
        raise BomiError(f"{path}: empty file")
    header = [name.strip() for name in rows[0]]
    if len(header) == 1 and any(sep in header[0] for sep in ";\t"):
        raise BomiError(f"{path}: one column named {header[0][:40]!r}...: columns must be separated by commas")
    body = rows[1:]
    for line, row in enumerate(body, start=2):
        if len(row) != len(header):
            raise BomiError(f"{path}: line {line} has {len(row)} cells, the header has {len(header)}")
    cells = np.array(body, dtype=str).reshape(len(body), len(header))
    variables: dict[str, object] = {}
    for j, name in enumerate(header):
        if name in variables:
            if name in _COLUMN_MEANING or name in (LABEL_COLUMN, TIME_COLUMN):
                raise BomiError(f"{path}: column {name} appears twice in the header")
            continue
        variables[name] = np.char.strip(cells[:, j])
    return variables


def _as_column(path: Path, name: str, value: object, text_cells: bool) -> np.ndarray:
    """A used variable (CSV: its cells as text) as an (n,) float array, or a one-line BomiError."""
    array = np.asarray(value)
    if text_cells:
        try:
            return array.astype(float)
        except ValueError:
            line = next(k for k, cell in enumerate(array, start=2) if not _is_number(cell))
            raise BomiError(f"{path}: column {name}, line {line}: not a number ({str(array[line - 2])!r})") from None
    if array.dtype.kind not in "biuf":
        raise BomiError(f"{path}: variable {name} is not numeric ({array.dtype.kind!r} data, shape {array.shape})")
    if array.ndim > 2 or (array.ndim == 2 and min(array.shape) > 1):
        raise BomiError(f"{path}: variable {name} is not a single column (shape {array.shape})")
    return array.reshape(-1).astype(float)


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _clock_ticks_per_s(time: object, from_csv: bool) -> int | None:
    """Units per second of a file's ``Time`` variable, None when it is not a clock: a CSV's is in
    seconds; a .mat's is in seconds when floating-point, in milliseconds when an integer of 32 bits
    or more (the original logger's int32 millisecond clock), and not a clock when a narrower integer
    (the published 5-day files' uint8 counter, which wraps every 256 rows)."""
    if time is None:
        return None
    if from_csv:
        return 1
    dtype = np.asarray(time).dtype
    if dtype.kind == "f":
        return 1
    if dtype.kind in "iu" and dtype.itemsize >= LOGGER_CLOCK_DTYPE.itemsize:
        return LOGGER_TICKS_PER_S
    return None


def _recording_from_variables(path: Path, variables: dict[str, object], from_csv: bool) -> Recording:
    """The node columns, labels and (CSV only) a numeric Time of ``variables``; the rest is ignored."""
    meaning = {name: _COLUMN_MEANING[name] for name in variables if name in _COLUMN_MEANING}
    if not meaning:
        raise BomiError(f"{path}: no IMU node columns (expected e.g. Pitch1Raw, ACC1X, ... for nodes 1..6, "
                        "or PitchRaw, ACCX, ... for a single node)")
    found: dict[tuple[int, Signal], dict[int, str]] = {}
    for name, (node, signal, axis) in meaning.items():
        axes = found.setdefault((node, signal), {})
        if axis in axes:
            raise BomiError(f"{path}: both {axes[axis]} and {name} are present (node {node} given twice)")
        axes[axis] = name
    for (node, signal), axes in found.items():
        if len(axes) < 3:
            naming = None if next(iter(axes.values())) in node_columns(None)[signal] else node
            absent = [n for k, n in enumerate(node_columns(naming)[signal]) if k not in axes]
            raise BomiError(f"{path}: node {node} {_SIGNAL_TEXT[signal]} is incomplete, column "
                            f"{', '.join(absent)} {'is' if len(absent) == 1 else 'are'} missing")
    used = list(meaning) + [name for name in (LABEL_COLUMN,) if name in variables]
    columns = {name: _as_column(path, name, variables[name], from_csv) for name in used}
    ignored = [name for name in variables if name not in columns]
    ticks_per_s = _clock_ticks_per_s(variables.get(TIME_COLUMN), from_csv)
    if ticks_per_s is not None:
        try:
            columns[TIME_COLUMN] = _as_column(path, TIME_COLUMN, variables[TIME_COLUMN], from_csv) / ticks_per_s
            ignored.remove(TIME_COLUMN)
            used.append(TIME_COLUMN)
        except BomiError:
            pass  # a clock the chain cannot read (e.g. text timestamps) is just another ignored variable
    length = len(columns[used[0]])
    if length == 0:
        raise BomiError(f"{path}: no samples (empty file)")
    for name in used:
        if len(columns[name]) != length:
            raise BomiError(f"{path}: column {name} has {len(columns[name])} rows, {used[0]} has {length}")
        bad = np.flatnonzero(~np.isfinite(columns[name]))
        if bad.size:
            raise BomiError(f"{path}: column {name} has a missing/NaN/inf value at row {bad[0] + 1}")
        bad = np.flatnonzero(np.abs(columns[name]) > MAX_ABS_VALUE) if name not in (TIME_COLUMN, LABEL_COLUMN) else []
        if len(bad):
            raise BomiError(f"{path}: column {name}, row {bad[0] + 1}: {columns[name][bad[0]]:g} is beyond "
                            f"+-{MAX_ABS_VALUE:g}, not a sensor value")
    labels = None
    if LABEL_COLUMN in columns:
        values = columns[LABEL_COLUMN]
        bad = np.flatnonzero((values != np.round(values)) | (values < 0) | (values > MAX_LABEL))
        if bad.size:
            raise BomiError(f"{path}: column {LABEL_COLUMN}, row {bad[0] + 1}: {values[bad[0]]:g} is not a class "
                            f"label (whole number in 0..{MAX_LABEL})")
        labels = values.astype(np.int64)
    nodes: dict[int, NodeData] = {}
    for (node, signal), axes in sorted(found.items()):
        data = nodes.setdefault(node, NodeData())
        setattr(data, signal.value, np.column_stack([columns[axes[k]] for k in range(3)]))
    return Recording(nodes=nodes, labels=labels, time=columns.get(TIME_COLUMN), source=str(path),
                     ignored=tuple(ignored))


def _header(nodes: Mapping[int, Sequence[Signal]], labelled: bool) -> list[str]:
    return ([TIME_COLUMN] + [name for i, signals in nodes.items() for name in _flat_columns(i, signals)]
            + ([LABEL_COLUMN] if labelled else []))


def _format_row(values: Sequence[float], label: int | None) -> str:
    cells = [repr(float(v)) for v in values] + ([str(int(label))] if label is not None else [])
    return ",".join(cells) + "\n"


def write_recording(path: str | os.PathLike, rec: Recording, rate_hz: float = SAMPLE_RATE_HZ, *,
                    overwrite: bool = False) -> None:
    """Write ``rec`` as CSV, indexed naming, the signals each node holds (Time from ``rec.time`` or
    sample index / rate), atomically; replaces an existing file only if ``overwrite``."""
    path = Path(path)
    signals = {i: rec.nodes[i].signals for i in rec.node_indices}
    time = rec.time if rec.time is not None else np.arange(len(rec)) / rate_hz
    table = np.column_stack([time] + [getattr(rec.nodes[i], s.value) for i, node in signals.items() for s in node])
    buffer = io.StringIO()
    buffer.write(",".join(_header(signals, rec.labels is not None)) + "\n")
    for k, values in enumerate(table.tolist()):
        buffer.write(_format_row(values, None if rec.labels is None else rec.labels[k]))
    write_text(path, buffer.getvalue(), overwrite=overwrite)


def write_logger_mat(path: str | os.PathLike, rec: Recording, *, overwrite: bool = False) -> None:
    """Write ``rec`` as the original logger's MATLAB file: its node-less column names for a single node 1
    (indexed names otherwise), ``Time`` its int32 millisecond clock (``rec.time`` rounded to the
    millisecond), ``Etiquette``; an existing file only if ``overwrite``. bomi.logger_layout gives
    the clock the logger's pauses."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise BomiError(f"{path}: file exists, not overwriting it")
    single = rec.node_indices == (LOGGER_NODE,)
    variables: dict[str, np.ndarray] = {}
    for i in rec.node_indices:
        for signal, names in node_columns(None if single else i).items():
            values = getattr(rec.nodes[i], signal.value)
            if values is not None:
                variables.update({name: values[:, k:k + 1] for k, name in enumerate(names)})
    time = rec.time if rec.time is not None else np.arange(len(rec)) / SAMPLE_RATE_HZ
    variables[TIME_COLUMN] = np.round(np.asarray(time, dtype=float) * LOGGER_TICKS_PER_S).astype(LOGGER_CLOCK_DTYPE)[:, None]
    if rec.labels is not None:
        variables[LABEL_COLUMN] = rec.labels[:, None].astype(float)
    scipy.io.savemat(path, variables)


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
        self._file.write(",".join(_header({i: tuple(Signal) for i in self.nodes}, labelled)) + "\n")
        self._file.flush()

    def append(self, time: float, samples: Mapping[int, NodeSample], label: int | None = None) -> None:
        """Add one row: ``samples`` maps every node index of the writer to its NodeSample."""
        if set(samples) != set(self.nodes):
            raise ValueError(f"row has nodes {sorted(samples)}, the recording has {list(self.nodes)}")
        if self.labelled == (label is None):
            raise ValueError("a label is required exactly when the recording is labelled")
        values = [time] + [v for i in self.nodes for s in Signal for v in getattr(samples[i], s.value)]
        self._pending.append(_format_row(values, label))
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
