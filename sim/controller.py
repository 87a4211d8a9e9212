"""Cartesian velocity control: a commanded tool twist becomes joint velocities (damped least squares).

The commanded twist is integrated into a target pose; the joint velocities track the twist plus a
proportional pull toward that target, so a zero command holds the pose instead of drifting.
Virtual walls (a box and a reach shell around the shoulder) clamp the target, which makes the
hand stop at a wall without jitter. Limited joints stop a margin short of their range; the
joint-velocity vector is scaled as a whole when a joint would exceed its speed limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from operator import truediv

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack

from sim.config import ControlConfig, WorkspaceConfig
from sim.floats import clip
from sim.kinematics import ArmKinematics


@dataclass(frozen=True)
class JointLimits:
    lower: np.ndarray  # -inf for continuous joints
    upper: np.ndarray
    speed: np.ndarray  # rad/s


@dataclass(frozen=True)
class Workspace:
    """Where the tool point may go: a box intersected with a shell around the shoulder, and a floor.

    The floor keeps the whole hand above the table: ``hand_box`` holds the corners of the hand's
    bounding box (fingers open and closed) in the tool frame, so the tool point's lowest allowed
    height depends on the hand's orientation.
    """

    lower: np.ndarray
    upper: np.ndarray
    shoulder: np.ndarray
    reach_min: float
    reach_max: float
    floor: float           # lowest height for any point of the hand
    hand_box: np.ndarray   # (8, 3) corners in the tool frame

    def __post_init__(self) -> None:
        # ``clamp`` runs every control tick: its bounds as Python floats, made once
        lower = tuple(float(v) for v in self.lower)
        object.__setattr__(self, "_bounds", (lower, tuple(max(lo, float(hi)) for lo, hi in zip(lower, self.upper))))
        object.__setattr__(self, "_upper_z", float(self.upper[2]))
        object.__setattr__(self, "_shoulder", tuple(float(v) for v in self.shoulder))

    @classmethod
    def from_config(cls, config: WorkspaceConfig, shoulder: np.ndarray, table_top: float,
                    hand_box: np.ndarray) -> Workspace:
        bounds = np.array([config.x, config.y, config.z], dtype=float)
        return cls(bounds[:, 0], bounds[:, 1], np.asarray(shoulder, float), config.reach_min, config.reach_max,
                   table_top + config.table_clearance, hand_box)

    def lowest_tool_height(self, rotation: np.ndarray) -> float:
        """Tool height at which the hand, so oriented, just touches the floor."""
        return self.floor - float(np.minimum.reduce(self.hand_box @ rotation[2]))

    def clamp(self, point: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """The nearest allowed point: onto the reach shell, then into the box and above the floor.

        The box and the floor come last, so they always hold (the table is solid); where they
        disagree with the shell, the shell gives way.
        """
        return np.array(self.clamp_xyz(*point, self.lowest_tool_height(rotation)))

    def clamp_xyz(self, x: float, y: float, z: float, floor: float) -> tuple[float, float, float]:
        """``clamp`` on Python floats (what the controller calls every tick), ``floor`` being
        ``lowest_tool_height`` of the rotation (the controller's changes only when its target turns):
        the same differences, products, square root and comparisons as on arrays of three, at a
        fraction of the cost."""
        sx, sy, sz = self._shoulder
        ox, oy, oz = x - sx, y - sy, z - sz
        distance = math.sqrt(ox * ox + oy * oy + oz * oz)
        if distance > self.reach_max:
            scale = self.reach_max / distance
            x, y, z = sx + ox * scale, sy + oy * scale, sz + oz * scale
        elif 0 < distance < self.reach_min:
            scale = self.reach_min / distance
            x, y, z = sx + ox * scale, sy + oy * scale, sz + oz * scale
        (lx, ly, lz), (ux, uy, uz) = self._bounds
        if floor > lz:
            lz = floor
            uz = max(floor, self._upper_z)
        return clip(x, lx, ux), clip(y, ly, uy), clip(z, lz, uz)

    def contains(self, point: np.ndarray, rotation: np.ndarray, tolerance: float = 1e-9) -> bool:
        return bool(np.allclose(self.clamp(point, rotation), point, atol=tolerance, rtol=0))


def damped_least_squares(jacobian: np.ndarray, twist: np.ndarray, damping: float) -> np.ndarray:
    """qd = J^T (J J^T + lambda^2 I)^-1 twist: well-behaved near singularities."""
    jjt = jacobian @ jacobian.T  # a new C-ordered array: ravel() is a view of it
    jjt.ravel()[::len(jjt) + 1] += damping**2  # the diagonal
    # LAPACK's dgesv, as np.linalg.solve calls it (the same LU, bit for bit), without its wrapper's checks
    _, _, solution, info = lapack.dgesv(jjt, twist)
    if info > 0:
        raise np.linalg.LinAlgError("Singular matrix")
    return jacobian.T @ solution


def speed_scale(qd: np.ndarray | list[float], speed_limit: np.ndarray | list[float]) -> float:
    """Largest factor <= 1 that keeps every joint within its speed limit (same factor for all)."""
    ratio = max(map(truediv, map(abs, qd), speed_limit))  # each |qd| / limit, the largest
    return 1.0 if ratio <= 1.0 else 1.0 / ratio


def rotation_error(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Rotation vector (world axes) taking ``current`` to ``target``."""
    return pin.log3(target @ current.T)


class CartesianVelocityController:
    """Turns a tool twist into joint velocities, one control tick at a time."""

    def __init__(self, kinematics: ArmKinematics, limits: JointLimits, workspace: Workspace,
                 config: ControlConfig, dt: float):
        self.kinematics = kinematics
        self.limits = limits
        self.workspace = workspace
        self.config = config
        self.dt = dt
        self.target_position: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.target_rotation = np.eye(3)
        # where a limited joint stops (a margin short of its range): the same every tick
        self._stop_lower = (limits.lower + config.joint_limit_margin).tolist()
        self._stop_upper = (limits.upper - config.joint_limit_margin).tolist()
        self._speed_limit = limits.speed.tolist()

    @property
    def target_rotation(self) -> np.ndarray:
        """The target's rotation matrix (read-only: a turn sets a new one)."""
        return self._target_rotation

    @target_rotation.setter
    def target_rotation(self, rotation: np.ndarray) -> None:
        # the floor under the hand so turned: the same every tick until the target turns (a move of
        # the hand alone leaves it), so worked out here, not in every tick's clamp
        self._target_rotation = rotation
        rotation.flags.writeable = False
        self._floor = self.workspace.lowest_tool_height(rotation)

    def reset(self, q: np.ndarray) -> None:
        """Hold the pose the arm is in."""
        position, self.target_rotation = self.kinematics.tool_pose(q)
        self.target_position = self.workspace.clamp_xyz(*position.tolist(), self._floor)

    def joint_velocities(self, q: np.ndarray, linear: np.ndarray, angular: np.ndarray) -> np.ndarray:
        """Joint velocities for one tick of the twist (linear m/s, angular rad/s, world axes).

        The 3-vectors (the target's position, the command, the twist) are worked on Python floats
        (the same elementwise operations and, for a length, the same sum of squares in the same
        order as on arrays, so the same bits) and the 6-vectors and matrices with numpy, Pinocchio
        and LAPACK."""
        position, rotation, jacobian = self.kinematics.pose_and_jacobian(q)
        previous_position, previous_rotation = self.target_position, self.target_rotation
        wx, wy, wz = angular = np.asarray(angular, float).tolist()
        pull, turn = self._advance_target(position.tolist(), rotation, np.asarray(linear, float).tolist(), angular)
        gain, (ex, ey, ez) = self.config.orientation_gain, turn.tolist()
        twist = np.array([*pull, wx + gain * ex, wy + gain * ey, wz + gain * ez])
        qd = damped_least_squares(jacobian, twist, self.config.dls_damping)
        speeds = qd.tolist()
        blocked = self._blocked_joints(q.tolist(), speeds)
        if blocked:
            jacobian[:, blocked] = 0.0
            qd = damped_least_squares(jacobian, twist, self.config.dls_damping)
            qd[blocked] = 0.0
            speeds = qd.tolist()
        scale = speed_scale(speeds, self._speed_limit)
        if scale < 1.0:
            # The arm does only this fraction of the tick's motion: so does the target, which then
            # never runs ahead and the hand stops where it is when the command stops.
            self.target_position = tuple(p + scale * (t - p) for p, t in zip(previous_position, self.target_position))
            self.target_rotation = pin.exp3(scale * rotation_error(self.target_rotation, previous_rotation)) \
                @ previous_rotation
            return qd * scale
        return qd

    def _advance_target(self, position: list[float], rotation: np.ndarray, linear: list[float],
                        angular: list[float]) -> tuple[list[float], np.ndarray]:
        """Move the target by one tick of the command inside the walls; return the linear part of
        the twist (the feedforward velocity plus the pull toward the target) and the rotation error
        (``rotation_error``) from the hand's ``rotation`` to the new target."""
        dt = self.dt
        ax, ay, az = angular
        if ax or ay or az:  # (no turn leaves the target's rotation as it is: exp3(0) is the identity)
            self.target_rotation = pin.exp3(np.array([ax * dt, ay * dt, az * dt])) @ self.target_rotation
        tx, ty, tz = self.target_position
        lx, ly, lz = linear
        wx, wy, wz = self.workspace.clamp_xyz(tx + lx * dt, ty + ly * dt, tz + lz * dt, self._floor)
        fx, fy, fz = (wx - tx) / dt, (wy - ty) / dt, (wz - tz) / dt  # the feedforward velocity
        # Anti-windup: the target never runs further ahead of the hand than max_tracking_error.
        px, py, pz = position
        gx, gy, gz = wx - px, wy - py, wz - pz
        distance = math.sqrt(gx * gx + gy * gy + gz * gz)
        if distance > self.config.max_tracking_error:
            scale = self.config.max_tracking_error / distance
            wx, wy, wz = px + gx * scale, py + gy * scale, pz + gz * scale
        self.target_position = wx, wy, wz
        turn = rotation_error(self.target_rotation, rotation)
        angle = math.sqrt(turn @ turn)
        max_angle = self.config.max_tracking_error / 0.1  # the same lag at 10 cm from the tool point
        if angle > max_angle:
            self.target_rotation = pin.exp3(turn * (max_angle / angle)) @ rotation
            turn = rotation_error(self.target_rotation, rotation)
        gain = self.config.position_gain
        return [fx + gain * (wx - px), fy + gain * (wy - py), fz + gain * (wz - pz)], turn

    def _blocked_joints(self, q: list[float], qd: list[float]) -> list[int]:
        """Limited joints within the margin of a range end and moving further toward it (indices;
        on Python floats, the same comparisons as on arrays at a fraction of the cost)."""
        return [j for j, (a, v, lo, hi) in enumerate(zip(q, qd, self._stop_lower, self._stop_upper))
                if (a <= lo and v < 0) or (a >= hi and v > 0)]
