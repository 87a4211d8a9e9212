"""The trial dataset: one HDF5 file per controller session (``bomi.h5``, ``joystick.h5``; a session
resumed after an interruption goes on in ``bomi.2.h5``, ...), written with h5py and readable by any
HDF5 reader (docs/trials.md describes every group and column).

Every file is written whole and replaced atomically (``replace_atomically``: a temporary file beside
it, fsync, rename, the directory fsync-ed), so a kill at any instant leaves the last complete version.

Groups: ``ticks`` (one row per control tick), ``stream`` (the bytes the source delivered, cut per
tick by ``ticks/byte_end``), ``frames`` (one row per IMU frame parsed), ``decisions`` (one row per
decision the live loop acted on), ``trials`` (one row per trial). The root's attributes say what
the file is (``format``, ``version``) and how the session ran.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path

import h5py
import numpy as np

from bomi.errors import BomiError
from sim.joystick import BUTTONS, FUNCTIONS
from tasks.trials.checks import check_session
from tasks.trials.session import Phase, Session

FORMAT = "bomi-trials"
VERSION = 1
STR = h5py.string_dtype()


@dataclass
class SessionData:
    """A session file read back: its attributes and every group's columns as arrays."""

    path: Path
    attrs: dict
    ticks: dict[str, np.ndarray]
    stream: bytes
    frames: dict[str, np.ndarray]
    decisions: dict[str, np.ndarray]
    trials: dict[str, np.ndarray]

    def tick_bytes(self) -> list[bytes]:
        """The bytes the source delivered at each tick."""
        ends = self.ticks["byte_end"]
        starts = np.r_[0, ends[:-1]]
        return [self.stream[a:b] for a, b in zip(starts.tolist(), ends.tolist())]

    def trial_row(self, number: int) -> int | None:
        rows = np.flatnonzero(self.trials["number"] == number)
        return int(rows[0]) if rows.size else None


def _columns(rows: list[dict], key: str, dtype=None) -> np.ndarray:
    return np.array([row[key] for row in rows], dtype=dtype)


def session_columns(session: Session, intents: tuple[np.ndarray, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
    """The session's records as the file's groups of columns."""
    recorder, arm = session.recorder, session.arm
    ticks, rows = recorder.ticks, arm.rows
    n = len(ticks)
    rows = rows[:n]
    frames = np.array(recorder.frames, dtype=np.int64).reshape(-1, 14)
    decisions = recorder.decisions
    frame_intents, decision_intents = intents
    tick_cols = {
        "t": _columns(ticks, "t", float), "trial": _columns(rows, "trial", np.int16),
        "phase": _columns(rows, "phase", np.int8), "task_t": _columns(rows, "task_t", float),
        "stick": np.array([t["stick"] for t in ticks], dtype=float).reshape(n, -1),
        "pressed": np.array([t["pressed"] for t in ticks], dtype=bool).reshape(n, -1),
        "linear": np.array([t["linear"] for t in ticks], dtype=float).reshape(n, 3),
        "angular": np.array([t["angular"] for t in ticks], dtype=float).reshape(n, 3),
        "finger": _columns(ticks, "finger", float), "mode": np.array([r["mode"] for r in rows], dtype=object),
        "hand_pos": np.array([r["hand_pos"] for r in rows], dtype=float).reshape(n, 3),
        "arm_qpos": np.array([r["arm_qpos"] for r in rows], dtype=float).reshape(n, -1),
        "closure": _columns(rows, "closure", float),
        "cube_pos": np.array([r["cube_pos"] for r in rows], dtype=float),
        "touching": np.array([r["touching"] for r in rows], dtype=bool),
        "frames": _columns(ticks, "frames", np.int32),
        "byte_end": np.cumsum([len(c) for c in recorder.chunks[:n]], dtype=np.int64),
        "intended_dir": np.array([t.get("intended_dir", (0.0, 0.0, 0.0)) for t in ticks], dtype=float).reshape(n, 3),
        "pushing": np.array([t.get("pushing", False) for t in ticks], dtype=bool),
        "goal": np.array([t.get("goal", "") for t in ticks], dtype=object),
        "stage": np.array([t.get("stage", "") for t in ticks], dtype=object),
    }
    for flag, dtype in (("stale", bool), ("standby", bool), ("calibrating", bool), ("reconnected", bool),
                        ("recalibrating", bool),
                        ("lost", np.int64),
                        ("dropped", np.int32), ("skipped", np.int32), ("loop_hz", float), ("overruns", np.int64)):
        tick_cols[flag] = np.array([t.get(flag, 0) for t in ticks], dtype=dtype)
    for text in ("hold", "recalibrated"):
        tick_cols[text] = np.array([t.get(text, "") for t in ticks], dtype=object)
    frame_cols = {"tick": frames[:, 0], "node_id": frames[:, 1], "period_ms": frames[:, 2], "counter": frames[:, 3],
                  "mag": frames[:, 4:7], "gyro": frames[:, 7:10], "acc": frames[:, 10:13], "sample": frames[:, 13],
                  "intended": np.asarray(frame_intents, dtype=np.int64).reshape(-1)}
    dec = np.array([d[:4] for d in decisions], dtype=np.int64).reshape(-1, 4)
    decision_cols = {"tick": dec[:, 0], "frame_row": dec[:, 1], "sample_index": dec[:, 2], "label": dec[:, 3],
                     "confidence": np.array([d[4] for d in decisions], dtype=float),
                     "rejected": np.array([d[5] for d in decisions], dtype=bool),
                     "gamma": np.array([d[6] for d in decisions], dtype=float),
                     "nu": np.array([d[7] for d in decisions], dtype=float),
                     "intended": np.asarray(decision_intents, dtype=np.int64).reshape(-1)}
    results = session.finished
    trial_cols = {
        "number": np.array([r.number for r in results], dtype=np.int32),
        "task_seed": np.array([r.task_seed for r in results], dtype=np.int64),
        "go_tick": np.array([r.go_tick for r in results], dtype=np.int64),
        "end_tick": np.array([r.end_tick for r in results], dtype=np.int64),
        "first_command_tick": np.array([r.first_command_tick for r in results], dtype=np.int64),
        "success": np.array([r.success for r in results], dtype=bool),
        "completion_time": np.array([np.nan if r.completion_time is None else r.completion_time for r in results]),
        "failure": np.array([r.failure or "" for r in results], dtype=object),
    }
    return {"ticks": tick_cols, "frames": frame_cols, "decisions": decision_cols, "trials": trial_cols}


def sync_directory(directory: Path) -> None:
    """Make the renames in ``directory`` durable."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def replace_atomically(path: Path, write: Callable[[Path], None]) -> None:
    """``write`` a temporary file beside ``path``, fsync it and rename it over ``path``: readers see the old
    file or the new one, never a part (the temporary file is removed if anything fails)."""
    partial = path.with_name(f".{path.stem}.partial{path.suffix}")
    try:
        partial.unlink(missing_ok=True)
        write(partial)
        fd = os.open(partial, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(partial, path)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    sync_directory(path.parent)


def file_sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex): what a trial record keeps of the model and profile it ran with."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_session(path: Path, session: Session, attrs: dict) -> None:
    """Write ``session`` (and the JSON-able ``attrs``) to the HDF5 file ``path``, replacing it atomically."""
    try:
        replace_atomically(path, lambda partial: _write_h5(partial, session, attrs))
    except (OSError, ValueError) as exc:
        raise BomiError(f"{path}: cannot write the trial data ({' '.join(str(exc).split())})") from None


def session_files(directory: Path, controller: str) -> list[Path]:
    """A controller's session files in ``directory``, in session order (``bomi.h5``, ``bomi.2.h5``, ...)."""
    files, part = [], 1
    while (path := directory / part_name(controller, part)).exists():
        files.append(path)
        part += 1
    return files


def part_name(controller: str, part: int) -> str:
    return f"{controller}.h5" if part == 1 else f"{controller}.{part}.h5"


def trial_file(directory: Path, controller: str, number: int) -> Path:
    """The session file of ``directory`` that holds trial ``number`` of ``controller``."""
    for path in session_files(directory, controller):
        try:
            with h5py.File(path, "r") as f:
                if "trials/number" in f and number in f["trials/number"][()].tolist():
                    return path
        except OSError as exc:
            raise BomiError(f"{path}: cannot read the trial data ({' '.join(str(exc).split())})") from None
    raise BomiError(f"{directory}: no {controller} session file holds trial {number}")


def _write_h5(path: Path, session: Session, attrs: dict) -> None:
    """The file made in memory, then written by Python: a full disk or a file-size limit is then an
    OSError (ENOSPC, EFBIG) here, not a failure inside HDF5's own writes (which crashed the process)."""
    recorder = session.recorder
    groups = session_columns(session, (recorder.frame_intents(), recorder.decision_intents()))
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs.update({"format": FORMAT, "version": VERSION, "written_by": f"bomi-jaco {version('bomi-jaco')}",
                        "controller": session.controller.value, "clock": session.clock_kind,
                        "stick_columns": json.dumps(FUNCTIONS), "pressed_columns": json.dumps(BUTTONS),
                        "phases": json.dumps({int(phase): phase.name.lower() for phase in Phase}),
                        "dt": session.arm.dt, "neutral": json.dumps(recorder.neutral and
                                                                  {str(k): v for k, v in recorder.neutral.items()}),
                        **{k: json.dumps(v) if isinstance(v, (dict, list, tuple)) or v is None else v
                           for k, v in attrs.items()}})
        for name, columns in groups.items():
            group = f.create_group(name)
            for key, values in columns.items():
                if values.dtype == object:
                    group.create_dataset(key, data=values.astype(str).astype(object), dtype=STR)
                else:
                    group.create_dataset(key, data=values, compression="gzip" if values.size > 4096 else None)
        f.create_dataset("stream/bytes", data=np.frombuffer(b"".join(recorder.chunks), dtype=np.uint8),
                         compression="gzip")
    with open(path, "xb") as out:
        out.write(buffer.getbuffer())


def read_session(path: Path) -> SessionData:
    """A session file, checked to be one of ours at a version this code reads."""
    try:
        with h5py.File(path, "r") as f:
            attrs = {k: (v.item() if np.size(v) == 1 and hasattr(v, "item") else v) for k, v in f.attrs.items()}
            if attrs.get("format") != FORMAT:
                raise BomiError(f"{path}: not a bomi trial file (format {attrs.get('format')!r})")
            if attrs.get("version") != VERSION:
                raise BomiError(f"{path}: trial file version {attrs.get('version')}, this bomi reads version {VERSION}")
            groups = {name: {key: _read(dataset) for key, dataset in _group(f, name, path).items()
                             if isinstance(dataset, h5py.Dataset)}
                      for name in ("ticks", "frames", "decisions", "trials")}
            stream = f.get("stream/bytes")
            if not isinstance(stream, h5py.Dataset) or stream.dtype != np.uint8 or stream.ndim != 1:
                raise BomiError(f"{path}: stream/bytes: missing, or not a column of bytes")
            stream = stream[()].tobytes()
    except OSError as exc:
        raise BomiError(f"{path}: cannot read the trial data ({' '.join(str(exc).split())})") from None
    check_session(Path(path), attrs, groups, len(stream))
    return SessionData(Path(path), attrs, groups["ticks"], stream, groups["frames"], groups["decisions"],
                       groups["trials"])


def _group(f: h5py.File, name: str, path: Path) -> h5py.Group:
    group = f.get(name)
    if not isinstance(group, h5py.Group):
        raise BomiError(f"{path}: {name}: missing, or not a group of columns")
    return group


def _read(dataset: h5py.Dataset) -> np.ndarray:
    if h5py.check_string_dtype(dataset.dtype) is not None:
        return dataset.asstr()[()]
    return dataset[()]
