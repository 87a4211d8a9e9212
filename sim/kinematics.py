"""Pinocchio kinematics of the JACO arm, built from the same MJCF file MuJoCo uses.

Pinocchio 4.1 places sites inside welded (jointless) child bodies wrongly, and the hand is such
a body; so the arm is loaded alone (``jaco_arm.xml``) and the tool frame is added on joint 6 with
its placement read once from MuJoCo's pinch-site pose (sim_notes: then Jacobians agree to 1e-14).
Everything here is in the world frame: the arm base placement is read from MuJoCo as well.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import mujoco
import numpy as np
import pinocchio as pin
from dm_control.entities.manipulators.kinova import assets_path

from sim.kernels import jacobian_in_world, tool_in_world
from sim.scene import Scene

JACO_ARM_XML = os.path.join(assets_path.KINOVA_ROOT, "jaco_arm.xml")
TOOL_FRAME = "tool"


@dataclass
class ArmKinematics:
    """Forward kinematics and the world-aligned Jacobian of the tool frame."""

    model: pin.Model
    data: pin.Data
    tool_frame: int
    base: pin.SE3  # arm base in the world

    def __post_init__(self) -> None:
        # read every tick: one copy out of Pinocchio each, not one a tick
        self.base_rotation = self.base.rotation.copy()
        self.base_homogeneous = self.base.homogeneous
        # the tool frame's placement in Pinocchio's data: a reference, which every kinematics pass updates in place
        self.tool_placement = self.data.oMf[self.tool_frame]

    def tool_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) and rotation matrix (3, 3) of the tool frame."""
        pin.framesForwardKinematics(self.model, self.data, q)
        position, rotation = np.empty(3), np.empty((3, 3))
        tool_in_world(self.base_homogeneous, self.tool_placement.homogeneous, position, rotation)
        return position, rotation

    def jacobian_in_base(self, q: np.ndarray) -> np.ndarray:
        """Pinocchio's Jacobian of the tool point in the base's axes (a new array); its kinematics pass
        places the tool frame as it goes (the same bits as framesForwardKinematics), so
        ``tool_placement`` is then the tool's at ``q``."""
        return pin.computeFrameJacobian(self.model, self.data, q, self.tool_frame, pin.LOCAL_WORLD_ALIGNED)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """6x6 Jacobian [linear; angular] of the tool point, world axes (mj_jacSite's convention)."""
        jacobian = self.jacobian_in_base(q)
        jacobian_in_world(self.base_rotation, jacobian)
        return jacobian

    def solve_pose(self, position: np.ndarray, rotation: np.ndarray, seed: np.ndarray,
                   iterations: int = 200, tolerance: float = 1e-8) -> np.ndarray:
        """Joint angles putting the tool at a world pose (damped Newton from ``seed``)."""
        target = self.base.inverse() * pin.SE3(rotation, position)
        q = np.array(seed, dtype=float)
        for _ in range(iterations):
            pin.framesForwardKinematics(self.model, self.data, q)
            current = self.data.oMf[self.tool_frame]
            error = pin.log6(current.actInv(target)).vector  # in the tool frame
            if np.linalg.norm(error) < tolerance:
                return q
            jac = pin.computeFrameJacobian(self.model, self.data, q, self.tool_frame, pin.LOCAL)
            q = q + jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), error)
        raise ValueError(f"no joint solution puts the tool at {np.round(position, 3).tolist()}")


def arm_kinematics(scene: Scene) -> ArmKinematics:
    """Build the Pinocchio model and place base and tool frame from the compiled MuJoCo scene."""
    model = pin.buildModelFromMJCF(JACO_ARM_XML)
    data = model.createData()
    mj = mujoco.MjData(scene.model)
    q = np.zeros(model.nq)
    mj.qpos[scene.arm_qpos] = q
    mujoco.mj_kinematics(scene.model, mj)
    base_body = scene.model.body("jaco_arm/b_base").id
    base = pin.SE3(mj.xmat[base_body].reshape(3, 3).copy(), mj.xpos[base_body].copy())
    site_world = pin.SE3(mj.site_xmat[scene.tool_site].reshape(3, 3).copy(), mj.site_xpos[scene.tool_site].copy())
    pin.forwardKinematics(model, data, q)
    joint6 = model.getJointId("joint_6")
    placement = data.oMi[joint6].inverse() * base.inverse() * site_world
    tool = model.addFrame(pin.Frame(TOOL_FRAME, joint6, placement, pin.FrameType.OP_FRAME))
    return ArmKinematics(model, model.createData(), tool, base)
