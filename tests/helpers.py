"""Small helpers shared by test modules."""
from __future__ import annotations

import importlib.util
import math
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from bomi.errors import BomiError


def benchmark_script(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` imported as a module (the scripts are not a package)."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parent.parent / "benchmarks"
                                                  / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def edited_copy(source: Path, target: Path, old: str, new: str) -> Path:
    """``source`` written to ``target`` with the first ``old`` replaced by ``new`` (which must occur)."""
    text = source.read_text()
    assert old in text
    target.write_text(text.replace(old, new, 1))
    return target


def assert_one_line_error(load: Callable[[Path], object], path: Path, content: str, fault: str) -> None:
    """``content`` written to ``path`` makes ``load`` raise one BomiError line naming the file and ``fault``."""
    path.write_text(content)
    with pytest.raises(BomiError) as err:
        load(path)
    message = str(err.value)
    assert str(path) in message and fault in message and "\n" not in message


def numpy_clamp(workspace, point: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """``Workspace.clamp`` as it was written on arrays (before it went to Python floats, then compiled)."""
    offset = point - workspace.shoulder
    distance = np.sqrt(offset @ offset)
    if distance > workspace.reach_max:
        point = workspace.shoulder + offset * (workspace.reach_max / distance)
    elif 0 < distance < workspace.reach_min:
        point = workspace.shoulder + offset * (workspace.reach_min / distance)
    lower = workspace.lower.copy()
    lower[2] = max(lower[2], workspace.lowest_tool_height(rotation))
    return np.minimum(np.maximum(point, lower), np.maximum(lower, workspace.upper))


def disagreement(actual, expected, ulps: float = 4.0, scale: float | None = None) -> str | None:
    """None when two forms of one computation (compiled and interpreted, Python floats and numpy
    arrays, a written-out formula and the library's) agree to ``ulps`` units in the last place of
    ``scale`` (default: the largest magnitude among the expected values), NaNs and infinities in the
    same places; else what differs.

    Bits cannot be asked of them: glibc's libm, numpy and OpenBLAS pick FMA, AVX2 or AVX-512 code
    paths at run time, so the last bit of a sin, a dot product or a sum depends on the CPU (and on
    which form runs). Measuring against the largest magnitude, not each element's, lets a component
    that is the difference of large terms carry their rounding; a chained computation (a solve, a
    rotation composed of several) passes ``ulps`` grown by its condition or length, said where used.

    Two finite floats (most calls: a test of a float form compares sample by sample) take the same
    test without numpy's per-call overhead: ``math.ulp`` of a positive float is ``np.spacing`` of it."""
    if isinstance(actual, float) and isinstance(expected, float) and math.isfinite(actual) and math.isfinite(expected):
        scale = abs(expected) if scale is None else scale
        tolerance = ulps * math.ulp(max(scale, sys.float_info.min))
        worst = abs(actual - expected)
        return None if worst <= tolerance else f"differ by {worst:.3g} > {tolerance:.3g} ({ulps:g} ulps of {scale:.3g})"
    a, b = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    if a.shape != b.shape:
        return f"shapes {a.shape} and {b.shape}"
    finite = np.isfinite(b)
    if not (np.array_equal(np.isnan(a), np.isnan(b)) and np.array_equal(a[~finite & ~np.isnan(b)],
                                                                      b[~finite & ~np.isnan(b)])
            and np.array_equal(np.isfinite(a), finite)):
        return f"NaNs or infinities differ: {a} and {b}"
    if scale is None:
        scale = float(np.max(np.abs(b[finite]), initial=0.0))
    tolerance = ulps * float(np.spacing(max(scale, np.finfo(float).tiny)))
    worst = float(np.max(np.abs(a[finite] - b[finite]), initial=0.0))
    return None if worst <= tolerance else f"differ by {worst:.3g} > {tolerance:.3g} ({ulps:g} ulps of {scale:.3g})"


def assert_agree(actual, expected, ulps: float = 4.0, scale: float | None = None) -> None:
    """``disagreement`` is None (see there)."""
    found = disagreement(actual, expected, ulps, scale)
    assert found is None, found


# A fusion filter's angles (deg) from two forms of its kernel (compiled and interpreted): the filter is
# stable, so the roundings of the two forms (a few ulps a sample, wherever libm's paths differ) stay
# far below 1e-9 deg over a day's samples; compared across the +-180 deg cut, where one form may read
# 179.99... and the other -179.99....
FILTER_FORMS_DEG = 1e-9


def assert_same_angles(actual, expected, tolerance_deg: float = FILTER_FORMS_DEG) -> None:
    gap = (np.asarray(actual, dtype=float) - np.asarray(expected, dtype=float) + 180.0) % 360.0 - 180.0
    assert np.all(np.abs(gap) <= tolerance_deg), float(np.max(np.abs(gap)))
