"""What a session directory's files must hold before anything reads them (`bomi replay`, re-scoring).

A session file (``bomi.h5``, ``joystick.h5``) and its records (``trials.jsonl``) come from disk:
edited, damaged, or from two sessions mixed. Every field the readers use is checked for its type,
shape and range, every index (a tick, a frame row, a trial's go and end) against what it indexes,
and the logged model against the logged profile; each fault is one ``BomiError`` line naming the
file and the field. Unknown extra attributes or columns are ignored (a newer writer's additions).
"""
from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from bomi.classifier import Model
from bomi.errors import BomiError
from bomi.model_io import check_model_for
from bomi.profiles import Profile
from sim.joystick import BUTTONS, FUNCTIONS, LAYOUTS
from tasks.experiments.limits import MAX_SEED
from tasks.operators.assist import parse_assist
from tasks.trials.session import UNKNOWN, Controller, Phase, TrialPlan

CLOCKS = ("simulated", "wall")
MAX_DT_S = 1.0  # a control period; the arm's is 1/60 s
MAX_PLAN_SECONDS = 1e6  # what a session's countdown, time limit or readiness bound may be at most
INT16 = (-(2 ** 15), 2 ** 15 - 1)  # an IMU frame's sensor counts


@dataclass(frozen=True)
class Column:
    """A column of a group: the dtype kinds it may have ("f" float, "i" int, "b" bool, "S" text)
    and the shape of one row (None: any size on that axis)."""

    kinds: str
    row: tuple[int | None, ...] = ()


FLOAT, INT, BOOL, TEXT = Column("fi"), Column("iu"), Column("b"), Column("SOU")
XYZ = Column("fi", (3,))
GROUPS: dict[str, dict[str, Column]] = {
    "ticks": {"t": FLOAT, "trial": INT, "phase": INT, "task_t": FLOAT, "stick": Column("fi", (len(FUNCTIONS),)),
              "pressed": Column("b", (len(BUTTONS),)), "linear": XYZ, "angular": XYZ, "finger": FLOAT,
              "mode": TEXT, "hand_pos": XYZ, "arm_qpos": Column("fi", (None,)), "closure": FLOAT,
              "cube_pos": Column("fi", (None, 3)), "touching": Column("b", (None,)), "frames": INT,
              "byte_end": INT},
    "frames": {"tick": INT, "node_id": INT, "period_ms": INT, "counter": INT, "mag": Column("iu", (3,)),
               "gyro": Column("iu", (3,)), "acc": Column("iu", (3,)), "sample": INT, "intended": INT},
    "decisions": {"tick": INT, "frame_row": INT, "sample_index": INT, "label": INT, "confidence": FLOAT,
                  "rejected": BOOL, "gamma": FLOAT, "nu": FLOAT, "intended": INT},
    "trials": {"number": INT, "task_seed": INT, "go_tick": INT, "end_tick": INT, "first_command_tick": INT,
               "success": BOOL, "completion_time": FLOAT, "failure": TEXT},
}


class Fault(ValueError):
    """A field that is not what the reader needs: ``field`` and what is wrong with it."""

    def __init__(self, field: str, what: str):
        super().__init__(f"{field}: {what}")


def _attr(attrs: dict, key: str, kind: type | tuple[type, ...], ok: Callable[[Any], bool] = lambda v: True,
          expected: str = "") -> Any:
    if key not in attrs:
        raise Fault(f"attribute {key}", "missing")
    value = attrs[key]
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    numeric = kind in (int, float, (int, float))
    if isinstance(value, bool) and numeric or not isinstance(value, kind) or not ok(value):
        raise Fault(f"attribute {key}", f"{value!r:.80} is not {expected or kind}")
    return value


def _json_attr(attrs: dict, key: str) -> Any:
    text = _attr(attrs, key, str, expected="JSON text")
    try:
        return json.loads(text)
    except (json.JSONDecodeError, RecursionError):
        raise Fault(f"attribute {key}", f"{text!r:.80} is not JSON") from None


def _finite_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_plan(value: Any) -> TrialPlan:
    """The logged ``plan`` attribute as a TrialPlan: exactly its fields, each in range."""
    names = [f.name for f in fields(TrialPlan)]
    if not isinstance(value, dict) or sorted(value) != sorted(names):
        raise Fault("attribute plan", f"must be an object of {', '.join(names)}")
    counts = {"trials": (1, 10_000), "first": (1, 10_000), "seed": (0, MAX_SEED)}
    for key, (low, high) in counts.items():
        v = value[key]
        if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
            raise Fault(f"attribute plan.{key}", f"{v!r:.40} is not a whole number in [{low}, {high}]")
    for key in ("countdown_s", "time_limit_s", "ready_within_s"):
        v = value[key]
        if not _finite_number(v) or not 0 <= v <= MAX_PLAN_SECONDS:
            raise Fault(f"attribute plan.{key}", f"{v!r:.40} is not a number of seconds in [0, {MAX_PLAN_SECONDS:g}]")
    return TrialPlan(**value)


def check_neutral(value: Any) -> dict[int, tuple[float, float, float]] | None:
    """The logged ``neutral`` attribute: null, or node id -> three finite angles (degrees)."""
    if value is None:
        return None
    if not isinstance(value, dict) or not value:
        raise Fault("attribute neutral", "must be null or an object of node id -> [pitch, roll, yaw]")
    out = {}
    for node, angles in value.items():
        if not node.isdigit() or not isinstance(angles, list) or len(angles) != 3 \
                or not all(_finite_number(a) and abs(a) <= 360 for a in angles):
            raise Fault(f"attribute neutral.{node:.20}", "must be three angles in [-360, 360] deg")
        out[int(node)] = tuple(float(a) for a in angles)
    return out


def check_attrs(attrs: dict) -> None:
    """The root attributes a reader uses, each typed and in range."""
    controller = _attr(attrs, "controller", str, lambda v: v in [c.value for c in Controller],
                       f"one of {', '.join(c.value for c in Controller)}")
    _attr(attrs, "clock", str, lambda v: v in CLOCKS, f"one of {', '.join(CLOCKS)}")
    _attr(attrs, "dt", (int, float), lambda v: math.isfinite(v) and 0 < v <= MAX_DT_S, f"a period in (0, {MAX_DT_S}] s")
    _attr(attrs, "layout", str, lambda v: v in LAYOUTS, f"one of {', '.join(LAYOUTS)}")
    _attr(attrs, "participant", str)
    _attr(attrs, "seed", int, lambda v: 0 <= v <= MAX_SEED, f"a seed in [0, {MAX_SEED}]")
    for key, expected in (("stick_columns", list(FUNCTIONS)), ("pressed_columns", list(BUTTONS))):
        if _json_attr(attrs, key) != expected:
            raise Fault(f"attribute {key}", f"must be {json.dumps(expected)} (the columns this bomi replays)")
    check_plan(_json_attr(attrs, "plan"))
    check_neutral(_json_attr(attrs, "neutral"))
    if "assist" in attrs:   # a file from before the assistance was logged ran without
        assist = _attr(attrs, "assist", str)
        try:
            parse_assist(assist, "")
        except BomiError as exc:
            raise Fault("attribute assist", str(exc)) from None
    if controller == Controller.BOMI.value:
        _attr(attrs, "profile", str, lambda v: bool(v), "a profile name")
        _attr(attrs, "allowance", int, lambda v: 0 <= v <= 10_000, "a number of decisions in [0, 10000]")
        classes = _json_attr(attrs, "classes")
        if not isinstance(classes, dict) or not classes or not all(
                k.isdigit() and isinstance(v, str) for k, v in classes.items()):
            raise Fault("attribute classes", "must be an object of class label -> its function and name")


def check_columns(groups: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
    """Every column the readers use: present, of its kind and row shape, as long as its group's
    others, finite where it is a number; returns each group's row count."""
    rows = {}
    for group, columns in GROUPS.items():
        found = groups.get(group, {})
        lengths = Counter(len(found[name]) for name in columns if name in found and np.ndim(found[name]))
        n = lengths.most_common(1)[0][0] if lengths else 0
        for name, column in columns.items():
            field = f"{group}/{name}"
            if name not in found:
                raise Fault(field, "missing")
            values = np.asarray(found[name])
            if values.dtype.kind not in column.kinds or values.ndim != 1 + len(column.row) or any(
                    want is not None and have != want for have, want in zip(values.shape[1:], column.row)):
                shape = "x".join(["n", *("any" if w is None else str(w) for w in column.row)])
                raise Fault(field, f"a {values.dtype} array of shape {values.shape}, expected {shape} "
                                   f"({'numbers' if 'f' in column.kinds else 'booleans' if column.kinds == 'b' else 'integers' if 'i' in column.kinds else 'text'})")
            if len(values) != n:
                raise Fault(field, f"{len(values)} rows, the other columns of {group} have {n}")
            if values.dtype.kind == "f" and name not in ("completion_time",) and not np.isfinite(values).all():
                raise Fault(field, "holds a value that is not a finite number")
        rows[group] = n
    return rows


def _within(values: np.ndarray, low: float, high: float, field: str) -> None:
    bad = np.flatnonzero((values < low) | (values > high))
    if bad.size:
        raise Fault(field, f"row {bad[0]} is {values[bad[0]]!r}, outside [{low:g}, {high:g}]")


def _rising(values: np.ndarray, field: str) -> None:
    bad = np.flatnonzero(np.diff(values) < 0)
    if bad.size:
        raise Fault(field, f"goes back at row {bad[0] + 1} ({values[bad[0]]!r} then {values[bad[0] + 1]!r})")


def check_indices(attrs: dict, groups: dict[str, dict[str, np.ndarray]], stream_bytes: int) -> None:
    """Every index against what it indexes, every value against its range."""
    rows = check_columns(groups)
    n, m = rows["ticks"], rows["frames"]
    ticks, frames, decisions, trials = (groups[g] for g in ("ticks", "frames", "decisions", "trials"))
    _rising(ticks["t"], "ticks/t")
    _within(ticks["t"], 0, 1e7, "ticks/t")
    _within(ticks["stick"], 0.0, 1.0, "ticks/stick")
    _within(ticks["phase"], min(Phase), max(Phase), "ticks/phase")
    _within(ticks["hand_pos"], -10.0, 10.0, "ticks/hand_pos")
    _rising(ticks["byte_end"], "ticks/byte_end")
    _within(ticks["byte_end"], 0, stream_bytes, "ticks/byte_end")
    if n and ticks["byte_end"][-1] != stream_bytes:
        raise Fault("ticks/byte_end", f"ends at byte {ticks['byte_end'][-1]}, stream/bytes holds {stream_bytes}")
    _within(frames["tick"], 0, n - 1, "frames/tick")
    _rising(frames["tick"], "frames/tick")
    _within(frames["node_id"], 0, 255, "frames/node_id")
    for name in ("mag", "gyro", "acc"):
        _within(frames[name], *INT16, f"frames/{name}")
    _within(frames["intended"], UNKNOWN, 1_000, "frames/intended")
    _within(decisions["tick"], 0, n - 1, "decisions/tick")
    _within(decisions["frame_row"], -1, m - 1, "decisions/frame_row")
    _within(decisions["label"], 0, 1_000, "decisions/label")
    _within(decisions["intended"], UNKNOWN, 1_000, "decisions/intended")
    plan = check_plan(json.loads(attrs["plan"]))
    number = trials["number"]
    if len(set(number.tolist())) != len(number):
        raise Fault("trials/number", "a trial number is listed twice")
    _within(number, plan.first, plan.last, "trials/number")
    expected_seeds = np.array([plan.task_seed(int(k)) for k in number], dtype=np.int64)
    if not np.array_equal(trials["task_seed"], expected_seeds):
        raise Fault("trials/task_seed", f"{trials['task_seed'].tolist()} is not the plan's seeds {expected_seeds.tolist()}")
    _within(trials["go_tick"], 0, max(n - 1, 0), "trials/go_tick")
    for k, (go, end, first) in enumerate(zip(*(trials[c].tolist() for c in ("go_tick", "end_tick",
                                                                           "first_command_tick")))):
        if not go < end <= n:
            raise Fault("trials/end_tick", f"row {k} is {end}, outside ({go}, {n}] (after its go_tick, within the ticks)")
        if first != -1 and not go <= first < end:
            raise Fault("trials/first_command_tick", f"row {k} is {first}, neither -1 nor in [{go}, {end})")


def check_session(path: Path, attrs: dict, groups: dict[str, dict[str, np.ndarray]], stream_bytes: int) -> None:
    """A session file's attributes and groups, as ``tasks.trials.dataset.read_session`` read them."""
    try:
        check_attrs(attrs)
        check_indices(attrs, groups, stream_bytes)
    except Fault as fault:
        raise BomiError(f"{path}: {fault}") from None


# ---------------------------------------------------------------------------------- trials.jsonl
RECORDS_FILE = "trials.jsonl"


@dataclass(frozen=True)
class TrialRecord:
    """What a reader takes from a trial's line of trials.jsonl. A BoMI trial's record keeps the SHA-256
    of the session's model.json and profile.toml as they were when it ran (None: a session written
    before this bomi logged them)."""

    number: int
    controller: Controller
    success: bool
    seed: int
    model_sha256: str | None = None
    profile_sha256: str | None = None


def read_records(directory: Path) -> dict[int, TrialRecord]:
    """The trial records of a session directory by number; each line a JSON object with a trial
    number (once), an operator that names a controller (and so a file of the directory), its
    success and seed."""
    path = inside(directory, RECORDS_FILE)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) else "not UTF-8 text"
        raise BomiError(f"{path}: cannot read it ({why}); is {directory} a `bomi trial` directory?") from None
    records: dict[int, TrialRecord] = {}
    for k, line in enumerate(lines, start=1):
        try:
            record = json.loads(line)
        except (json.JSONDecodeError, RecursionError):
            raise BomiError(f"{path}: line {k} is not JSON") from None
        try:
            parsed = _record(record, records)
        except Fault as fault:
            raise BomiError(f"{path}: line {k}: {fault}") from None
        records[parsed.number] = parsed
    return records


def _record(record: Any, seen: dict[int, TrialRecord]) -> TrialRecord:
    if not isinstance(record, dict):
        raise Fault("record", f"a JSON {type(record).__name__}, not an object")
    number = record.get("trial")
    if isinstance(number, bool) or not isinstance(number, int) or not 1 <= number <= 1_000_000:
        raise Fault("trial", f"{number!r:.40} is not a trial number")
    if number in seen:
        raise Fault("trial", f"trial {number} is recorded twice")
    operator = record.get("operator")
    if operator not in [c.value for c in Controller]:
        raise Fault("operator", f"{operator!r:.60} is not one of {', '.join(c.value for c in Controller)}")
    if not isinstance(record.get("success"), bool):
        raise Fault("success", f"{record.get('success')!r:.40} is not true or false")
    seed = record.get("seed")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise Fault("seed", f"{seed!r:.40} is not a seed in [0, {MAX_SEED}]")
    digests = {key: _digest(record, key) for key in ("model_sha256", "profile_sha256")}
    return TrialRecord(number, Controller(operator), record["success"], seed, **digests)


def _digest(record: dict, key: str) -> str | None:
    """A SHA-256 digest field (64 lowercase hexadecimal digits), or None when the record has none."""
    value = record.get(key)
    if value is not None and not (isinstance(value, str) and len(value) == 64
                                  and all(c in "0123456789abcdef" for c in value)):
        raise Fault(key, f"{value!r:.80} is not a SHA-256 digest (64 hexadecimal digits)")
    return value


def inside(directory: Path, name: str) -> Path:
    """``directory/name``, refused when it leads outside the directory (a symbolic link out, a name with ..)."""
    path = directory / name
    try:
        real, home = path.resolve(), directory.resolve()
    except (OSError, RuntimeError) as exc:
        raise BomiError(f"{path}: cannot be resolved ({exc})") from None
    if not real.is_relative_to(home) or real.parent != home:
        raise BomiError(f"{path}: leads outside the session directory {directory} (to {real}); not read")
    return path


def check_against_record(path: Path, record: TrialRecord, trials: dict[str, np.ndarray], row: int) -> None:
    """A trial's line of trials.jsonl and its row of the session file are of the same session."""
    logged = (bool(trials["success"][row]), int(trials["task_seed"][row]))
    if (record.success, record.seed) != logged:
        raise BomiError(f"{path}: trial {record.number}: success {logged[0]}, seed {logged[1]}; trials.jsonl says "
                        f"success {record.success}, seed {record.seed}: the files are of different sessions")


def check_logged_digest(path: Path, what: str, logged: str | None, now: str) -> None:
    """The session's file ``path`` is the one its trials ran with: its SHA-256 ``now`` is the ``logged``
    one (None: not logged, nothing to check)."""
    if logged is not None and logged != now:
        raise BomiError(f"{path}: not the {what} the trials were run with (sha256 {logged} logged, {now} now)")


def check_logged_model(path: Path, attrs: dict, profile: Profile, model: Model, model_path: Path) -> None:
    """The session's logged profile is the one it ran with (name, classes and functions, layout),
    and the logged model was trained for it."""
    from tasks.operators.stick import profile_layout
    logged = json.loads(attrs["classes"])
    found = {str(c.label): f"{c.function} ({c.name})" for c in profile.classes}
    if profile.name != attrs["profile"] or found != logged:
        raise BomiError(f"{profile.source}: profile {profile.name} with classes {found}, the session ran profile "
                        f"{attrs['profile']} with {logged} ({path}); not the session's profile")
    if profile_layout(profile).name != attrs["layout"]:
        raise BomiError(f"{profile.source}: layout {profile_layout(profile).name}, the session ran {attrs['layout']} "
                        f"({path})")
    check_model_for(model, profile, model_path)
    neutral = check_neutral(json.loads(attrs["neutral"]))
    if neutral is not None and sorted(neutral) != sorted(profile.node_indices):
        raise BomiError(f"{path}: attribute neutral: nodes {sorted(neutral)}, profile {profile.name}'s are "
                        f"{sorted(profile.node_indices)}")
