"""The assistance's parameters (``assist.toml``: [auto_mode], [path], [grasp_help])."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

from bomi.config_files import load_toml

DEFAULT_ASSIST_FILE = Path(__file__).resolve().parents[1] / "assist.toml"


@dataclass(frozen=True)
class AutoModeParams:
    rest_time: float
    mask_time: float
    pause_after_press: float
    press_grace: float
    response_samples: float
    press_time: float
    min_gain: float
    memory: float
    sharpness: float
    proximity: float
    off_target_prior: float
    refusal_share: float
    rest_refusal: float


@dataclass(frozen=True)
class PathParams:
    clearance: float
    release_gap: float
    grasp_near: float
    grasp_height: float
    place_near: float
    place_height: float
    yaw_tol_deg: float
    softness: float
    yaw_softness_deg: float
    open_closure: float
    squeeze: float
    revisit: float


@dataclass(frozen=True)
class GraspHelpParams:
    hold_still: float
    xy_tol: float
    z_tol: float
    yaw_tol_deg: float


@dataclass(frozen=True)
class AssistParams:
    auto_mode: AutoModeParams
    path: PathParams
    grasp_help: GraspHelpParams


_TABLES = {"auto_mode": AutoModeParams, "path": PathParams, "grasp_help": GraspHelpParams}
_MAY_BE_NEGATIVE = {"off_target_prior"}


def load_assist(path: Path | str = DEFAULT_ASSIST_FILE) -> AssistParams:
    """Read and validate an assistance TOML file; BomiError names the file and the fault."""
    return load_toml(path, DEFAULT_ASSIST_FILE.parent, "assist", _parse_assist)


def _parse_assist(data: dict, source: str) -> AssistParams:
    unknown = set(data) - set(_TABLES)
    if unknown:
        raise ValueError(f"unknown table(s): {', '.join(sorted(unknown))}")
    tables = {}
    for name, cls in _TABLES.items():
        table = data.get(name)
        if not isinstance(table, dict):
            raise ValueError(f"missing table [{name}]")
        keys = [f.name for f in fields(cls)]
        extra = set(table) - set(keys)
        if extra:
            raise ValueError(f"unknown key(s) in [{name}]: {', '.join(sorted(extra))}")
        values = {}
        for key in keys:
            value = table.get(key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"[{name}] {key} must be a finite number, got {value!r}")
            if value <= 0 and key not in _MAY_BE_NEGATIVE:
                raise ValueError(f"[{name}] {key} must be positive, got {value}")
            values[key] = float(value)
        tables[name] = cls(**values)
    if not tables["path"].open_closure < 1:
        raise ValueError("[path] open_closure must be below 1")
    if not tables["auto_mode"].refusal_share < 1:
        raise ValueError("[auto_mode] refusal_share must be below 1")
    return AssistParams(**tables)
