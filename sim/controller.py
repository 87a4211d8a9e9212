"""Cartesian velocity control: a commanded tool twist becomes joint velocities (damped least squares).

The commanded twist is integrated into a target pose; the joint velocities track the twist plus a
proportional pull toward that target, so a zero command holds the pose instead of drifting.
Virtual walls (a box and a reach shell around the shoulder) clamp the target, which makes the
hand stop at a wall without jitter. Limited joints stop a margin short of their range; the
joint-velocity vector is scaled as a whole when a joint would exceed its speed limit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from sim.config import ControlConfig, WorkspaceConfig
from sim.kernels import advance_target, clamp_point, solve_joint_velocities, vector_length
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
        # what ``clamp_point`` reads every control tick, made once, 12 floats: the shoulder (3), the
        # reach shell (min, max), the box's lower (3) and upper bounds (3; one below its lower bound
        # raised to it) and the box's own top
        lower = [float(v) for v in self.lower]
        upper = [max(lo, float(hi)) for lo, hi in zip(lower, self.upper)]
        object.__setattr__(self, "walls", np.array([*map(float, self.shoulder), float(self.reach_min),
                                                    float(self.reach_max), *lower, *upper, float(self.upper[2])]))

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
        x, y, z = np.asarray(point, float).tolist()
        return np.array(clamp_point(x, y, z, self.lowest_tool_height(rotation), self.walls))

    def contains(self, point: np.ndarray, rotation: np.ndarray, tolerance: float = 1e-9) -> bool:
        return bool(np.allclose(self.clamp(point, rotation), point, atol=tolerance, rtol=0))


def rotation_error(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Rotation vector (world axes) taking ``current`` to ``target``."""
    return pin.log3(target @ current.T)


class CartesianVelocityController:
    """Turns a tool twist into joint velocities, one control tick at a time.

    A tick's arithmetic runs in two compiled kernels (``sim.kernels.advance_target``, ``solve_joint_velocities``);
    between them, in Python, Pinocchio's C++ (the Jacobian pass, ``log3``/``exp3``)."""

    def __init__(self, kinematics: ArmKinematics, limits: JointLimits, workspace: Workspace,
                 config: ControlConfig, dt: float):
        self.kinematics = kinematics
        self.limits = limits
        self.workspace = workspace
        self.config = config
        self.dt = dt
        # the target's position (row 0) and where it was at the tick's start (row 1)
        self._target = np.zeros((2, 3))
        self.target_rotation = np.eye(3)
        self._gains = np.array([dt, config.position_gain, config.max_tracking_error])
        self._damping_squared = config.dls_damping**2
        # where a limited joint stops (a margin short of its range), each joint's speed limit: the same every tick
        self._joint_bounds = np.array([limits.lower + config.joint_limit_margin,
                                       limits.upper - config.joint_limit_margin, limits.speed], dtype=float)
        # each tick's scratch: the hand's pose, the rotation from it to the target, the twist
        self._hand_position, self._hand_rotation = np.empty(3), np.empty((3, 3))
        self._to_target, self._twist = np.empty((3, 3)), np.empty(6)

    @property
    def target_position(self) -> tuple[float, float, float]:
        """Where the target is (the tool point's goal in the world)."""
        return tuple(self._target[0].tolist())

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
        self._target[0] = clamp_point(*position.tolist(), self._floor, self.workspace.walls)

    def joint_velocities(self, q: np.ndarray, linear: np.ndarray, angular: np.ndarray) -> np.ndarray:
        """Joint velocities for one tick of the twist (linear m/s, angular rad/s, world axes).

        The target moves by the tick's command inside the walls, never further than
        max_tracking_error ahead of the hand; the twist is the command plus a pull toward the
        target; damped least squares turns it into joint velocities, with the joints at a range end
        left out, all scaled to the joints' speed limits (the target then moves by as much)."""
        kinematics = self.kinematics
        jacobian = kinematics.jacobian_in_base(q)  # places the tool frame at q as it goes
        previous_rotation = self.target_rotation
        angular = np.asarray(angular, float)
        ax, ay, az = angular.tolist()
        if ax or ay or az:  # (no turn leaves the target's rotation as it is: exp3(0) is the identity)
            dt = self.dt
            self.target_rotation = pin.exp3(np.array([ax * dt, ay * dt, az * dt])) @ previous_rotation
        hand, to_target, twist = self._hand_rotation, self._to_target, self._twist
        advance_target(jacobian, kinematics.base_rotation, kinematics.base_homogeneous,
                       kinematics.tool_placement.homogeneous, np.asarray(linear, float), self._target,
                       self.target_rotation, self._floor, self.workspace.walls, self._gains, self._hand_position,
                       hand, to_target, twist)
        turn = pin.log3(to_target)  # the rotation error from the hand to the target, world axes
        angle = vector_length(turn)
        max_angle = self.config.max_tracking_error / 0.1  # the same lag at 10 cm from the tool point
        if angle > max_angle:  # (anti-windup, as for the position)
            self.target_rotation = pin.exp3(turn * (max_angle / angle)) @ hand
            turn = rotation_error(self.target_rotation, hand)
        qd, scale = solve_joint_velocities(jacobian, twist, angular, turn, self.config.orientation_gain,
                                           self._damping_squared, q, self._joint_bounds, self._target)
        if scale < 1.0:  # the target's position did only this fraction of the tick's motion: so does its rotation
            self.target_rotation = pin.exp3(scale * rotation_error(self.target_rotation, previous_rotation)) \
                @ previous_rotation
        return qd
