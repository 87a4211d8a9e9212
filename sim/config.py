"""Simulation configuration: a TOML file (default ``models/sim.toml``) validated into dataclasses.

Every value is checked on load (``bomi.config_files``: each section's keys by their type hints,
then the section's ``__post_init__``); a bad file raises a one-line BomiError naming the file, the
section, the key and what is wrong.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from bomi.config_files import at_most, from_table, load_toml, positive

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

    def __post_init__(self) -> None:
        positive(self, "control_hz", "substeps")
        at_most(self, MAX_CONTROL_HZ, "control_hz")
        at_most(self, MAX_SUBSTEPS, "substeps")


@dataclass(frozen=True)
class ArmConfig:
    base_pos: Vec3
    armature_large: float
    armature_small: float
    gravity_compensation: bool
    home_tool_pos: Vec3
    home_seed: Vec6

    def __post_init__(self) -> None:
        positive(self, "armature_large", "armature_small")


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

    def __post_init__(self) -> None:
        positive(self, *(f.name for f in dataclasses.fields(self)))


@dataclass(frozen=True)
class WorkspaceConfig:
    x: Vec2
    y: Vec2
    z: Vec2
    reach_max: float
    reach_min: float
    table_clearance: float

    def __post_init__(self) -> None:
        for name in ("x", "y", "z"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"{name}: lower bound {lo} must be below upper bound {hi}")
        positive(self, "reach_max")
        if not 0 <= self.reach_min < self.reach_max:
            raise ValueError("reach_min must be in [0, reach_max)")
        if self.table_clearance < 0:
            raise ValueError("table_clearance must be >= 0")


@dataclass(frozen=True)
class SceneConfig:
    location_a: Vec2
    location_b: Vec2
    cube_offsets: tuple[Vec2, ...]

    def __post_init__(self) -> None:
        if not self.cube_offsets:
            raise ValueError("cube_offsets: at least one cube is needed")


@dataclass(frozen=True)
class RenderConfig:
    camera: str
    width: int
    height: int
    fps: float

    def __post_init__(self) -> None:
        if not self.camera:
            raise ValueError("camera: expected a camera's name, got ''")
        positive(self, "width", "height", "fps")


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
    """Read and validate a simulation config; a one-line BomiError naming the file on any problem."""
    return load_toml(DEFAULT_CONFIG if path is None else path, MODELS_DIR, "simulation config", _parse)


def _parse(data: dict, source: str) -> SimConfig:
    config = from_table(SimConfig, data, source=Path(source))
    for gain in GAINS:  # a pull of g per second applied once per tick overshoots beyond g = control_hz
        value = getattr(config.control, gain)
        if value > config.physics.control_hz:
            raise ValueError(f"[control] {gain}: {value!r} per s exceeds [physics] control_hz "
                             f"({config.physics.control_hz!r}): each tick would overshoot its target")
    return config
