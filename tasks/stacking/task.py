"""The paper's assembly task: two 5 cm cubes start at A, are carried one by one and stacked at B.

Composer style: the task composes the arm scene (``sim.env.ArmSim``), randomises the cube
start poses per seed, defines what the operator observes (``vocabulary.View``) and decides
success and failure.  Success = the top cube rests on the bottom one at B (xy offset and tilt
within tolerance), the hand has let go, and both cubes stay still for ``still_time``.
Failure = the time limit or a cube off the table.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.env import ArmSim
from tasks.stacking.vocabulary import View


@dataclass(frozen=True)
class TaskConfig:
    time_limit: float = 600.0  # s
    start_jitter: float = 0.01  # m: each cube's start is moved by up to this in x and y
    start_yaw_deg: float = 15.0  # each cube starts turned by up to this
    stack_xy: float = 0.015  # m: top cube centre over the bottom one
    stack_tilt_deg: float = 10.0
    at_b: float = 0.03  # m: bottom cube centre from B
    still_time: float = 1.0  # s
    still_speed: float = 0.01  # m/s: a cube moving slower than this is still


@dataclass(frozen=True)
class Outcome:
    done: bool
    success: bool
    completion_time: float | None  # s: when the finished stack started being still
    failure: str | None
    timed_out: bool = False  # ended by the time limit (a Gymnasium truncation, not a termination)


NOT_DONE = Outcome(False, False, None, None)


def cube_yaw(quat: Sequence[float]) -> float:
    """Heading (rad) of a cube's x axis about the vertical, from a (w, x, y, z) quaternion."""
    w, x, y, z = quat
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def cube_tilt_deg(quat: Sequence[float]) -> float:
    """Angle between the vertical and the cube's face normal closest to it."""
    w, x, y, z = quat
    world_z_in_cube = (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))
    return math.degrees(math.acos(min(1.0, float(max(abs(c) for c in world_z_in_cube)))))


def levelling_rotation(tool_z: Sequence[float]) -> np.ndarray:
    """(x, y) of the rotation vector that turns the tool's z axis to point straight down."""
    x, y, z = tool_z
    # np.cross(tool_z, down), its norm and tool_z.dot(down) written out on Python floats (the same
    # products, sums and square root, in the same order, at a tenth of the cost)
    ax, ay, az = y * -1.0 - z * 0.0, z * 0.0 - x * -1.0, x * 0.0 - y * 0.0
    sin, cos = math.sqrt(ax * ax + ay * ay + az * az), x * 0.0 + y * 0.0 + z * -1.0
    if sin < 1e-12:
        return np.zeros(2)
    angle = math.atan2(sin, cos)
    return np.array([ax * angle / sin, ay * angle / sin])  # (axis * angle / sin)[:2]


def start_poses(sim: ArmSim, config: TaskConfig, seed: int) -> np.ndarray:
    """(n, 3) cube starts (x, y, yaw): the configured spots at A moved by a seeded jitter."""
    rng = np.random.default_rng(seed)
    xy = sim.default_cube_positions()
    jitter = rng.uniform(-config.start_jitter, config.start_jitter, size=xy.shape)
    yaw = np.radians(rng.uniform(-config.start_yaw_deg, config.start_yaw_deg, size=len(xy)))
    return np.column_stack([xy + jitter, yaw])


class StackingTask:
    """Observations, success and failure of one stacking trial on an ``ArmSim``."""

    def __init__(self, sim: ArmSim, config: TaskConfig = TaskConfig()):
        self.sim = sim
        self.config = config
        scene = sim.scene
        self.cube_size = 2 * scene.cube_half_size
        self.table_z = 0.0  # the scene's table top (models/scene.xml)
        table = scene.model.geom(scene.table_geom)
        self.table_lo = table.pos[:2] - table.size[:2]
        self.table_hi = table.pos[:2] + table.size[:2]
        self.target_pos = np.r_[scene.location_b, self.table_z]
        self._cubes = frozenset(scene.cube_geoms.tolist())
        # read every control tick: as Python floats, made once
        self._table_lo, self._table_hi = self.table_lo.tolist(), self.table_hi.tolist()
        self._target_xy = self.target_pos[:2].tolist()
        self._target_xy_array = self.target_pos[:2].copy()  # the view's, the same every tick: read-only
        self._target_xy_array.flags.writeable = False
        self._still_since: float | None = None
        self._previous: list[list[float]] | None = None

    def reset(self, seed: int) -> None:
        self.sim.reset(start_poses(self.sim, self.config, seed))
        self._still_since, self._previous = None, self.sim.cube_positions.tolist()

    def view(self) -> View:
        sim = self.sim
        r = sim.tool_rotation_rows
        return View(
            t=sim.time,
            hand_pos=sim.tool_position,
            hand_yaw=math.atan2(r[3], r[0]),
            hand_tilt=levelling_rotation((r[2], r[5], r[8])),
            closure=sim.finger_closure,
            mode=sim.mode,
            cube_pos=tuple(sim.cube_positions),
            cube_yaw=tuple([cube_yaw(q) for q in sim.cube_quats.tolist()]),
            touching=sim.cube_in_grasp(),
            target_xy=self._target_xy_array,
            table_z=self.table_z,
            cube_size=self.cube_size,
        )

    def placed(self, pos: list[list[float]]) -> tuple[int, int]:
        """(how many cubes stand in place: 0, 1 the lowest at B, 2 the other on it as well; the index
        of the upper one) from the cube centres ``pos`` (``ArmSim.cube_positions`` as lists).  On
        Python floats: the same differences, lengths and order as on arrays."""
        heights = [p[2] for p in pos]
        bottom, top = sorted(range(len(pos)), key=heights.__getitem__)[:2]  # np.argsort's order (stable)
        (bx, by, bz), (tx, ty, tz) = pos[bottom], pos[top]
        dx, dy = bx - self._target_xy[0], by - self._target_xy[1]
        if not math.sqrt(dx * dx + dy * dy) <= self.config.at_b:
            return 0, top
        ox, oy = tx - bx, ty - by
        on_top = (math.sqrt(ox * ox + oy * oy) <= self.config.stack_xy
                  and abs(tz - bz - self.cube_size) <= 0.1 * self.cube_size)
        return (2 if on_top else 1), top

    def stacked(self, pos: list[list[float]] | None = None) -> bool:
        """The top cube rests on the bottom one at B, level, and the hand touches neither (``pos``:
        the cube centres now, ``ArmSim.cube_positions`` as lists, if already read)."""
        count, top = self.placed(self.sim.cube_positions.tolist() if pos is None else pos)
        return bool(count == 2 and cube_tilt_deg(self.sim.cube_quats[top].tolist()) <= self.config.stack_tilt_deg
                    and not self.sim.touching(self.sim.scene.hand_geoms, self._cubes))

    def outcome(self) -> Outcome:
        """Call once per control tick, after the step."""
        t, pos = self.sim.time, self.sim.cube_positions.tolist()
        # the fastest cube's speed since the previous tick (np.linalg.norm's per cube, on Python floats)
        speed = max([math.sqrt((x - px) * (x - px) + (y - py) * (y - py) + (z - pz) * (z - pz))
                     for (x, y, z), (px, py, pz) in zip(pos, self._previous)]) / self.sim.dt
        self._previous = pos
        if speed <= self.config.still_speed and self.stacked(pos):
            self._still_since = t if self._still_since is None else self._still_since
            if t - self._still_since >= self.config.still_time - 1e-9:
                return Outcome(True, True, self._still_since, None)
        else:
            self._still_since = None
        (lo_x, lo_y), (hi_x, hi_y) = self._table_lo, self._table_hi
        for k, (x, y, z) in enumerate(pos):
            if z < self.table_z - self.cube_size or x < lo_x or y < lo_y or x > hi_x or y > hi_y:
                return Outcome(True, False, None, f"cube {k + 1} knocked off the table")
        if t >= self.config.time_limit:
            return Outcome(True, False, None, f"time limit {self.config.time_limit:g} s", timed_out=True)
        return NOT_DONE
