"""Small helpers shared by test modules."""
from __future__ import annotations

import importlib.util
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
