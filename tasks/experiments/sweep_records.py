"""A sweep's results file (DIR/episodes.jsonl): one JSON line per finished episode (its key, the
settings the key hashes, its metrics), read, checked and appended to.

A file edited by hand (or by anything but a sweep) is checked before any episode runs: every
record against the schema of the fields the summaries read (``RECORD_SCHEMA``, JSON Schema), and
each record of the grid against its key (its settings are the ones the key stands for, its
participant, operator and seed are its settings', a success within its time limit).  A fault is
one line naming the file and the record; nothing is run, written or lost.
"""
from __future__ import annotations

import errno
import json
import os
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from jsonschema import Draft202012Validator
from jsonschema.exceptions import best_match

from bomi.errors import BomiError
from tasks.experiments.engine import report

RESULTS_FILE = "episodes.jsonl"

_COUNT = {"type": "integer", "minimum": 0}
_SHARE = {"type": "number", "minimum": 0, "maximum": 1}
_NONNEGATIVE = {"type": "number", "minimum": 0}
_NAME = {"type": "string", "minLength": 1}
# What the summaries, tables and figures read of a record; other fields are free (a later version's).
RECORD_SCHEMA = {
    "type": "object",
    "required": ["key", "settings", "participant", "operator", "seed", "layout", "success", "completion_time",
                 "failure", "mode_switches", "unintended_displacement_mm", "cube_drops", "realtime_factor"],
    "properties": {
        "key": _NAME,
        "settings": {"type": "object", "required": ["participant", "operator", "seed", "time_limit"],
                     "properties": {"participant": _NAME, "operator": _NAME, "seed": _COUNT,
                                    "time_limit": {"type": "number", "exclusiveMinimum": 0}}},
        "participant": _NAME, "operator": _NAME, "seed": _COUNT, "layout": {"type": "string"},
        "assist": {"type": "string"}, "recovery": {"type": "string"},
        "success": {"type": "boolean"},
        "completion_time": {"type": ["number", "null"], "minimum": 0},
        "failure": {"type": ["string", "null"]},
        "mode_switches": _COUNT, "cube_drops": _COUNT, "unintended_displacement_mm": _NONNEGATIVE,
        "realtime_factor": {"type": "number", "exclusiveMinimum": 0},
        "automatic_switches": _COUNT, "wrong_goal_switches": _COUNT, "refused_switches": _COUNT,
        "undone_switches": _COUNT, "grasp_helps": _COUNT,
        "stuck": {"type": ["object", "null"], "properties": {"mechanism": {"type": "string"}}},
        "decisions": _COUNT,
        "accuracy_all_decisions": _SHARE, "accuracy_excused_transitions": _SHARE, "excused_share": _SHARE,
        "excused_allowance_ms": _NONNEGATIVE, "excused_allowance_samples": _COUNT,
        "irrelevant_decisions": _COUNT, "irrelevant_runs": _COUNT,
        "irrelevant_longest_run_ms": _NONNEGATIVE, "longest_error_run_ms": _NONNEGATIVE,
        "latency_onsets_ms": {"type": "array", "items": _NONNEGATIVE},
        "onsets": _COUNT, "onsets_unrecognised": _COUNT,
        "accuracy_vs_allowance": {"type": "object", "required": ["allowance_s", "accuracy"],
                                  "properties": {"allowance_s": {"type": "array", "items": _NONNEGATIVE},
                                                 "accuracy": {"type": "array",
                                                              "items": {"type": ["number", "null"]}}}},
    },
    "allOf": [
        # a success has its completion time; a failure has none, and its reason
        {"if": {"properties": {"success": {"const": True}}},
         "then": {"properties": {"completion_time": {"type": "number"}}},
         "else": {"properties": {"completion_time": {"type": "null"}, "failure": {"type": "string"}}}},
        # a record with decisions has what the decision metrics pool
        {"if": {"required": ["decisions"], "properties": {"decisions": {"exclusiveMinimum": 0}}},
         "then": {"required": ["accuracy_all_decisions", "accuracy_excused_transitions", "excused_allowance_ms",
                               "excused_allowance_samples", "irrelevant_decisions", "irrelevant_runs",
                               "irrelevant_longest_run_ms", "longest_error_run_ms", "latency_onsets_ms",
                               "accuracy_vs_allowance"]}},
    ],
}
_VALIDATOR = Draft202012Validator(RECORD_SCHEMA)
IDENTITY = ("participant", "operator", "seed")  # a record's own fields that its settings name too


@dataclass
class Results:
    """What a results file holds: its complete records by key, its size, and how many bytes at
    its end are an unfinished last line (an interrupted write)."""
    records: dict[str, dict]
    lines: dict[str, int]  # each record's line number (its last, if a key is written twice)
    size: int
    torn: int
    unterminated: bool  # the last record is complete but has no line end


def read_results(path: Path) -> Results:
    """The records in the results file (not following a symbolic link); a last line without its
    line end is kept when it is a whole record and set aside when it is not; any other bad line is
    an error."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except FileNotFoundError:
        return Results({}, {}, 0, 0, False)
    except OSError as exc:
        raise BomiError(f"{path}: cannot be read ({exc.strerror})") from None
    with os.fdopen(fd, "rb") as handle:
        data = handle.read()
    records: dict[str, dict] = {}
    numbers: dict[str, int] = {}
    lines = data.split(b"\n")
    torn = 0
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            if not isinstance(record.get("settings"), dict):
                raise TypeError
            records[record["key"]] = record
            numbers[record["key"]] = number
        except (ValueError, KeyError, TypeError, AttributeError):
            if number == len(lines):  # the unfinished last line of an interrupted write
                torn = len(line)
                continue
            raise BomiError(f"{path}: line {number} is not an episode record; move the file away to start "
                            f"afresh") from None
    return Results(records, numbers, len(data), torn, bool(data) and not torn and not data.endswith(b"\n"))


class ResultsFile:
    """The results file opened for appending (never through a symbolic link), one whole line per
    record: a write that fails (a full disk) is cut back to the last whole line."""

    def __init__(self, path: Path, results: Results):
        self.path, self.saved = path, len(results.records)
        try:
            self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise BomiError(f"{path}: cannot be written ({exc.strerror})") from None
        if os.fstat(self.fd).st_size != results.size:
            os.close(self.fd)
            raise BomiError(f"{path}: changed while it was being read; rerun")
        if results.torn:
            os.ftruncate(self.fd, results.size - results.torn)
            report(f"bomi: {path}: set aside an unfinished last line ({results.torn} bytes, an interrupted write); "
                   f"kept its {len(results.records)} complete records")
        elif results.unterminated:
            self._write(b"\n")
            report(f"bomi: {path}: its last record had no line end; kept it ({len(results.records)} records)")

    def _write(self, data: bytes) -> None:
        size = os.fstat(self.fd).st_size
        try:
            if os.write(self.fd, data) != len(data):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        except OSError as exc:
            with suppress(OSError):
                os.ftruncate(self.fd, size)
            raise BomiError(f"{self.path}: cannot append an episode ({exc.strerror}); the {self.saved} episodes "
                            f"before it are saved, rerun to go on") from None

    def append(self, record: dict) -> None:
        self._write((json.dumps(record) + "\n").encode())
        self.saved += 1

    def close(self) -> None:
        os.close(self.fd)



def record_fault(record: dict, expected: dict[str, Any] | None) -> str | None:
    """What is wrong with ``record``: against the schema, then against its key (``expected``: the
    settings its key stands for in the grid, None for a record of another grid); None if nothing."""
    error = best_match(_VALIDATOR.iter_errors(record))
    if error is not None:
        where = ".".join(str(p) for p in error.absolute_path)
        return f"{where}: {error.message}" if where else error.message
    settings = record["settings"]
    for name in IDENTITY:
        if record[name] != settings[name]:
            return f"{name} {json.dumps(record[name])} is not its settings' {json.dumps(settings[name])}"
    if record["success"] and record["completion_time"] > settings["time_limit"]:
        return (f"completion_time {record['completion_time']:g} s is beyond its time limit "
                f"({settings['time_limit']:g} s)")
    if expected is not None and _canonical(settings) != _canonical(expected):
        differ = sorted(k for k in settings.keys() | expected.keys() if settings.get(k) != expected.get(k))
        return f"its settings are not the ones its key {record['key']} stands for (differing: {', '.join(differ)})"
    return None


def _canonical(settings: dict) -> str:
    return json.dumps(settings, sort_keys=True)


def check_records(path: Path, results: Results, grid: dict[str, dict[str, Any]]) -> None:
    """Every record of the file against the schema, and each of the grid's (``grid``: key -> the
    settings it stands for) against its key: a one-line BomiError for the first fault."""
    for key in sorted(results.records, key=results.lines.__getitem__):
        fault = record_fault(results.records[key], grid.get(key))
        if fault is not None:
            raise BomiError(f"{path}: record {results.lines[key]}: {fault}; correct or delete that line (its "
                            f"episode then runs again) and rerun: nothing was run or changed")
