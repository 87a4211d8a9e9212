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

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack

from sim.config import ControlConfig, WorkspaceConfig
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
        disagree with the shell, the shell gives way.  (On Python floats: the same comparisons as
        ``np.minimum(np.maximum(point, lower), np.maximum(lower, upper))``, at a fraction of the cost.)
        """
        offset = point - self.shoulder
        distance = math.sqrt(offset @ offset)
        if distance > self.reach_max:
            point = self.shoulder + offset * (self.reach_max / distance)
        elif 0 < distance < self.reach_min:
            point = self.shoulder + offset * (self.reach_min / distance)
        (lx, ly, lz), (ux, uy, uz) = self._bounds
        floor = self.lowest_tool_height(rotation)
        if floor > lz:
            lz = floor
            uz = max(floor, float(self.upper[2]))
        x, y, z = point.tolist()
        return np.array([min(max(x, lx), ux), min(max(y, ly), uy), min(max(z, lz), uz)])

    def contains(self, point: np.ndarray, rotation: np.ndarray, tolerance: float = 1e-9) -> bool:
        return bool(np.allclose(self.clamp(point, rotation), point, atol=tolerance, rtol=0))


def damped_least_squares(jacobian: np.ndarray, twist: np.ndarray, damping: float) -> np.ndarray:
    """qd = J^T (J J^T + lambda^2 I)^-1 twist: well-behaved near singularities."""
    jjt = jacobian @ jacobian.T
    jjt.flat[::len(jjt) + 1] += damping**2  # the diagonal
    # LAPACK's dgesv, as np.linalg.solve calls it (the same LU, bit for bit), without its wrapper's checks
    _, _, solution, info = lapack.dgesv(jjt, twist)
    if info > 0:
        raise np.linalg.LinAlgError("Singular matrix")
    return jacobian.T @ solution


def speed_scale(qd: np.ndarray, speed_limit: np.ndarray) -> float:
    """Largest factor <= 1 that keeps every joint within its speed limit (same factor for all)."""
    ratio = np.maximum.reduce(np.abs(qd) / speed_limit)  # .max() without the method's wrapper
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
        self.target_position = np.zeros(3)
        self.target_rotation = np.eye(3)
        # where a limited joint stops (a margin short of its range): the same every tick
        self._stop_lower = (limits.lower + config.joint_limit_margin).tolist()
        self._stop_upper = (limits.upper - config.joint_limit_margin).tolist()

    def reset(self, q: np.ndarray) -> None:
        """Hold the pose the arm is in."""
        self.target_position, self.target_rotation = self.kinematics.tool_pose(q)
        self.target_position = self.workspace.clamp(self.target_position, self.target_rotation)

    def joint_velocities(self, q: np.ndarray, linear: np.ndarray, angular: np.ndarray) -> np.ndarray:
        """Joint velocities for one tick of the twist (linear m/s, angular rad/s, world axes)."""
        position, rotation, jacobian = self.kinematics.pose_and_jacobian(q)
        previous_position, previous_rotation = self.target_position, self.target_rotation
        angular = np.asarray(angular, float)
        linear_ff, turn = self._advance_target(position, rotation, np.asarray(linear, float), angular)
        # the feedforward twist (linear_ff, angular) plus the pull toward the target
        twist = np.concatenate((linear_ff + self.config.position_gain * (self.target_position - position),
                                angular + self.config.orientation_gain * turn))
        qd = damped_least_squares(jacobian, twist, self.config.dls_damping)
        blocked = self._blocked_joints(q, qd)
        if blocked:
            jacobian[:, blocked] = 0.0
            qd = damped_least_squares(jacobian, twist, self.config.dls_damping)
            qd[blocked] = 0.0
        scale = speed_scale(qd, self.limits.speed)
        if scale < 1.0:
            # The arm does only this fraction of the tick's motion: so does the target, which then
            # never runs ahead and the hand stops where it is when the command stops.
            self.target_position = previous_position + scale * (self.target_position - previous_position)
            self.target_rotation = pin.exp3(scale * rotation_error(self.target_rotation, previous_rotation)) \
                @ previous_rotation
            return qd * scale
        return qd

    def _advance_target(self, position, rotation, linear, angular) -> tuple[np.ndarray, np.ndarray]:
        """Move the target by one tick of the command inside the walls; return the feedforward
        linear velocity and the rotation error (``rotation_error``) from the hand's ``rotation`` to
        the new target."""
        if angular.any():  # (no turn leaves the target's rotation as it is: exp3(0) is the identity)
            self.target_rotation = pin.exp3(angular * self.dt) @ self.target_rotation
        walled = self.workspace.clamp(self.target_position + linear * self.dt, self.target_rotation)
        linear_ff = (walled - self.target_position) / self.dt
        self.target_position = walled
        # Anti-windup: the target never runs further ahead of the hand than max_tracking_error.
        lag = self.target_position - position
        distance = math.sqrt(lag @ lag)
        if distance > self.config.max_tracking_error:
            self.target_position = position + lag * (self.config.max_tracking_error / distance)
        turn = rotation_error(self.target_rotation, rotation)
        angle = math.sqrt(turn @ turn)
        max_angle = self.config.max_tracking_error / 0.1  # the same lag at 10 cm from the tool point
        if angle > max_angle:
            self.target_rotation = pin.exp3(turn * (max_angle / angle)) @ rotation
            turn = rotation_error(self.target_rotation, rotation)
        return linear_ff, turn

    def _blocked_joints(self, q: np.ndarray, qd: np.ndarray) -> list[int]:
        """Limited joints within the margin of a range end and moving further toward it (indices;
        on Python floats, the same comparisons as on arrays at a fraction of the cost)."""
        return [j for j, (a, v, lo, hi) in enumerate(zip(q.tolist(), qd.tolist(), self._stop_lower, self._stop_upper))
                if (a <= lo and v < 0) or (a >= hi and v > 0)]
