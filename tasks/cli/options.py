"""Validation of command-line options: argparse ``type=`` functions and the checks of output paths.

One place for each check, so every command rejects the same bad value with the same one-line
message (``bomi: error: argument --seeds: ...``) before any long work starts.
"""
from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Collection, Iterable
from pathlib import Path

from bomi.errors import BomiError
from bomi.files import check_output
from tasks.experiments.limits import MAX_SECONDS, MAX_SEED, MAX_SEEDS, MIN_TIME_LIMIT_S


def _number(text: str, kind: type) -> float | int:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, "
                                         f"got {text!r}") from None
    if kind is float and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def _ranged(name: str, kind: type, *checks: tuple[Callable[[float], bool], str]) -> Callable[[str], float]:
    """An argparse ``type=``: the text as ``kind`` (a float finite), refused with the message of the
    first ``(accepts, message)`` check it fails."""
    def parse(text: str) -> float:
        value = _number(text, kind)
        for accepts, message in checks:
            if not accepts(value):
                raise argparse.ArgumentTypeError(f"{message}, got {text!r}")
        return value
    parse.__name__ = name  # argparse's name for the type
    return parse


_AT_MOST_A_DAY = (lambda v: v <= MAX_SECONDS, f"at most {MAX_SECONDS:g} s (a day)")
_POSITIVE = (lambda v: v > 0, "must be above 0")
_NON_NEGATIVE = (lambda v: v >= 0, "must not be negative")

positive_int = _ranged("positive_int", int, (lambda v: v >= 1, "must be at least 1"))
non_negative_int = _ranged("non_negative_int", int, _NON_NEGATIVE)
positive_float = _ranged("positive_float", float, _POSITIVE)
non_negative_float = _ranged("non_negative_float", float, _NON_NEGATIVE)
seconds = _ranged("seconds", float, _POSITIVE, _AT_MOST_A_DAY)  # a duration in seconds
episode_seconds = _ranged("episode_seconds", float, (lambda v: v >= MIN_TIME_LIMIT_S, f"at least {MIN_TIME_LIMIT_S:g} s"),
                     _AT_MOST_A_DAY)  # of simulated time per episode
non_negative_seconds = _ranged("non_negative_seconds", float, _NON_NEGATIVE, _AT_MOST_A_DAY)
seed = _ranged("seed", int, _NON_NEGATIVE, (lambda v: v <= MAX_SEED, f"at most {MAX_SEED}"))
seed_count = _ranged("seed_count", int, (lambda v: 1 <= v <= MAX_SEEDS, f"must be in [1, {MAX_SEEDS}]"))
# a posterior threshold
open_unit_interval = _ranged("open_unit_interval", float, (lambda v: 0 < v < 1, "must be between 0 and 1 (exclusive)"))
# of dropping a frame, of altering a byte
probability = _ranged("probability", float, (lambda v: 0 <= v < 1, "must be in [0, 1)"))


def add_force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--force", action="store_true", help="replace output files that already exist")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_outputs(outputs: dict[str, tuple[Path | str | None, tuple[str, ...]]], *, inputs: Iterable[Path | str] = (),
                  force: bool = False, defaults: Collection[str] = ()) -> dict[str, Path | None]:
    """Check every output before any work: option -> (path or None, allowed suffixes).

    Refuses an existing file unless ``force``, an input file (even with ``force``), a directory, a
    missing or read-only directory, a wrong suffix, and two options naming the same file. The
    options in ``defaults`` name the command's own default output (the user named none): an
    existing regular file there is the previous run's and is replaced, as if with ``force``.
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
        checked[option] = check_output(path, overwrite=force or option in defaults, suffixes=suffixes, what=option)
    paths = [p.resolve() for p in checked.values() if p is not None]
    if len(set(paths)) != len(paths):
        raise BomiError(f"{', '.join(o for o, p in checked.items() if p is not None)}: two outputs name the same file")
    return checked
