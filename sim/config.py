"""Simulation configuration: a TOML file (default ``models/sim.toml``) validated into dataclasses.

Every value is checked on load; a bad file raises :class:`SimError` naming the file, the key and
what is wrong, so the CLI can print one line.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
import typing
from dataclasses import dataclass
from pathlib import Path

from sim.errors import SimError

MODELS_DIR = Path(__file__).resolve().parents[1] / "models"
DEFAULT_CONFIG = MODELS_DIR / "sim.toml"

# Upper bounds for anyone: the JACO's own control loop runs at 100 Hz, so 1 kHz is ample; 100
# substeps at 1 kHz is already a 10 us physics step. Beyond them an episode would only crawl.
MAX_CONTROL_HZ = 1000.0
MAX_SUBSTEPS = 100
GAINS = ("finger_gain", "position_gain", "orientation_gain")  # 1/s: at most one control tick's worth

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]


@dataclass(frozen=True)
class PhysicsConfig:
    control_hz: float
    substeps: int

    @property
    def timestep(self) -> float:
        return 1.0 / (self.control_hz * self.substeps)

    def validate(self) -> None:
        _positive(self, "control_hz", "substeps")
        _at_most(self, MAX_CONTROL_HZ, "control_hz")
        _at_most(self, MAX_SUBSTEPS, "substeps")


@dataclass(frozen=True)
class ArmConfig:
    base_pos: Vec3
    armature_large: float
    armature_small: float
    gravity_compensation: bool
    home_tool_pos: Vec3
    home_seed: Vec6

    def validate(self) -> None:
        _positive(self, "armature_large", "armature_small")


@dataclass(frozen=True)
class ControlConfig:
    full_speed: float
    wrist_speed: float
    finger_speed: float
    finger_gain: float
    dls_damping: float
    position_gain: float
    orientation_gain: float
    max_tracking_error: float
    joint_limit_margin: float

    def validate(self) -> None:
        _positive(self, *(f.name for f in dataclasses.fields(self)))


@dataclass(frozen=True)
class WorkspaceConfig:
    x: Vec2
    y: Vec2
    z: Vec2
    reach_max: float
    reach_min: float
    table_clearance: float

    def validate(self) -> None:
        for name in ("x", "y", "z"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"{name}: lower bound {lo} must be below upper bound {hi}")
        _positive(self, "reach_max")
        if not 0 <= self.reach_min < self.reach_max:
            raise ValueError("reach_min must be in [0, reach_max)")
        if self.table_clearance < 0:
            raise ValueError("table_clearance must be >= 0")


@dataclass(frozen=True)
class SceneConfig:
    location_a: Vec2
    location_b: Vec2
    cube_offsets: tuple[Vec2, ...]

    def validate(self) -> None:
        if not self.cube_offsets:
            raise ValueError("cube_offsets: at least one cube is needed")


@dataclass(frozen=True)
class RenderConfig:
    camera: str
    width: int
    height: int
    fps: float

    def validate(self) -> None:
        _positive(self, "width", "height", "fps")


@dataclass(frozen=True)
class SimConfig:
    physics: PhysicsConfig
    arm: ArmConfig
    control: ControlConfig
    workspace: WorkspaceConfig
    scene: SceneConfig
    render: RenderConfig
    source: Path = DEFAULT_CONFIG


def load_config(path: Path | str | None = None) -> SimConfig:
    """Read and validate a simulation config; raises SimError naming the file on any problem."""
    path = Path(path) if path is not None else DEFAULT_CONFIG
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SimError(f"{path}: cannot read config: {exc.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SimError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise SimError(f"{path}: not a simulation config (nested too deeply)") from None
    hints = typing.get_type_hints(SimConfig)
    sections = {}
    for field in dataclasses.fields(SimConfig):
        if field.name == "source":
            continue
        try:
            sections[field.name] = _parse_section(data, field.name, hints[field.name])
        except ValueError as exc:
            raise SimError(f"{path}: [{field.name}] {exc}") from None
    unknown = set(data) - set(sections)
    if unknown:
        raise SimError(f"{path}: unknown section(s) {sorted(unknown)}")
    for gain in GAINS:  # a pull of g per second applied once per tick overshoots beyond g = control_hz
        value = getattr(sections["control"], gain)
        if value > sections["physics"].control_hz:
            raise SimError(f"{path}: [control] {gain}: {value!r} per s exceeds [physics] control_hz "
                           f"({sections['physics'].control_hz!r}): each tick would overshoot its target")
    return SimConfig(**sections, source=path)


def _parse_section(data: dict, name: str, cls: type):
    table = data.get(name)
    if not isinstance(table, dict):
        raise ValueError("section missing")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = set(table) - set(names)
    if unknown:
        raise ValueError(f"unknown key(s) {sorted(unknown)}")
    values = {}
    for key in names:
        if key not in table:
            raise ValueError(f"{key}: missing")
        try:
            values[key] = _coerce(table[key], hints[key])
        except ValueError as exc:
            raise ValueError(f"{key}: {exc}") from None
    section = cls(**values)
    section.validate()
    return section


def _coerce(value, kind):
    """Check a TOML value against a type annotation (float, int, bool, str, fixed/variable tuples)."""
    if kind is bool:
        if not isinstance(value, bool):
            raise ValueError(f"expected true/false, got {value!r}")
        return value
    if kind is str:
        if not isinstance(value, str) or not value:
            raise ValueError(f"expected a non-empty string, got {value!r}")
        return value
    if kind in (int, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"expected a number, got {value!r}")
        if kind is int and not isinstance(value, int):
            raise ValueError(f"expected an integer, got {value!r}")
        if not math.isfinite(value):
            raise ValueError(f"expected a finite number, got {value!r}")
        return kind(value)
    args = typing.get_args(kind)
    if not isinstance(value, list):
        raise ValueError(f"expected a list, got {value!r}")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(_coerce(item, args[0]) for item in value)
    if len(value) != len(args):
        raise ValueError(f"expected {len(args)} values, got {len(value)}")
    return tuple(_coerce(item, arg) for item, arg in zip(value, args))


def _at_most(section, limit: float, *names: str) -> None:
    for name in names:
        if getattr(section, name) > limit:
            raise ValueError(f"{name}: must be at most {limit!r}, got {getattr(section, name)!r}")


def _positive(section, *names: str) -> None:
    for name in names:
        if not getattr(section, name) > 0:
            raise ValueError(f"{name}: must be > 0, got {getattr(section, name)!r}")

