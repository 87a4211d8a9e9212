"""The assistance's parameters (``assist.toml``: [auto_mode], [path], [grasp_help])."""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

from bomi.config_files import from_table, load_toml, positive

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

    def __post_init__(self) -> None:
        positive(self, *(f.name for f in fields(self) if f.name != "off_target_prior"))   # a log-odds: any sign
        if not self.refusal_share < 1:
            raise ValueError(f"refusal_share: must be below 1, got {self.refusal_share!r}")


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

    def __post_init__(self) -> None:
        positive(self, *(f.name for f in fields(self)))
        if not self.open_closure < 1:
            raise ValueError(f"open_closure: must be below 1, got {self.open_closure!r}")


@dataclass(frozen=True)
class GraspHelpParams:
    hold_still: float
    xy_tol: float
    z_tol: float
    yaw_tol_deg: float

    def __post_init__(self) -> None:
        positive(self, *(f.name for f in fields(self)))


@dataclass(frozen=True)
class AssistParams:
    auto_mode: AutoModeParams
    path: PathParams
    grasp_help: GraspHelpParams


def load_assist(path: Path | str = DEFAULT_ASSIST_FILE) -> AssistParams:
    """Read and validate an assistance TOML file; a one-line BomiError names the file and the fault."""
    return load_toml(path, DEFAULT_ASSIST_FILE.parent, "assist", _parse_assist)


def _parse_assist(data: dict, source: str) -> AssistParams:
    return from_table(AssistParams, data)
