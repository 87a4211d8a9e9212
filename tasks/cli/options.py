"""Validation of command-line options: argparse ``type=`` functions and the checks of output paths.

One place for each check, so every command rejects the same bad value with the same one-line
message (``bomi: error: argument --seeds: ...``) before any long work starts.
"""
from __future__ import annotations

import argparse
import math
import os
from collections.abc import Iterable
from pathlib import Path

from bomi.errors import BomiError
from bomi.files import check_output


def _number(text: str, kind: type) -> float | int:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, "
                                         f"got {text!r}") from None
    if kind is float and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def positive_int(text: str) -> int:
    value = _number(text, int)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text!r}")
    return value


def non_negative_int(text: str) -> int:
    value = _number(text, int)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must not be negative, got {text!r}")
    return value


def positive_float(text: str) -> float:
    value = _number(text, float)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be above 0, got {text!r}")
    return value


def non_negative_float(text: str) -> float:
    value = _number(text, float)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must not be negative, got {text!r}")
    return value


# Longest time any option may ask for: a day, longer than any session, capture or episode; it keeps
# arithmetic on times (sample counts, schedules) finite.
MAX_SECONDS = 86_400.0


def seconds(text: str) -> float:
    """A duration in seconds: above 0, at most MAX_SECONDS."""
    value = positive_float(text)
    if value > MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"at most {MAX_SECONDS:g} s (a day), got {text!r}")
    return value


def non_negative_seconds(text: str) -> float:
    value = non_negative_float(text)
    if value > MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"at most {MAX_SECONDS:g} s (a day), got {text!r}")
    return value


def open_unit_interval(text: str) -> float:
    """A number strictly between 0 and 1 (a posterior threshold)."""
    value = _number(text, float)
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1 (exclusive), got {text!r}")
    return value


def probability(text: str) -> float:
    """A probability in [0, 1) (of dropping a frame, of altering a byte)."""
    value = _number(text, float)
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text!r}")
    return value


def add_force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--force", action="store_true", help="replace output files that already exist")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_outputs(outputs: dict[str, tuple[Path | str | None, tuple[str, ...]]], *, inputs: Iterable[Path | str] = (),
                  force: bool = False) -> dict[str, Path | None]:
    """Check every output before any work: option -> (path or None, allowed suffixes).

    Refuses an existing file unless ``force``, an input file (even with ``force``), a directory, a
    missing or read-only directory, a wrong suffix, and two options naming the same file.
    """
    checked: dict[str, Path | None] = {}
    for option, (path, suffixes) in outputs.items():
        if path is None:
            checked[option] = None
            continue
        path = Path(path)
        for source in inputs:
            if _same_file(path, Path(source)) or path.resolve() == Path(source).resolve():
                raise BomiError(f"{path}: {option} names an input file; not overwriting it")
        checked[option] = check_output(path, overwrite=force, suffixes=suffixes, what=option)
    paths = [p.resolve() for p in checked.values() if p is not None]
    if len(set(paths)) != len(paths):
        raise BomiError(f"{', '.join(o for o, p in checked.items() if p is not None)}: two outputs name the same file")
    return checked
