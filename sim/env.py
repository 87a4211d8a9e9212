"""The physics loop: one 60 Hz control tick = joystick -> twist -> DLS IK -> velocity actuators -> substeps.

``ArmSim`` knows nothing of any task: the caller places the cubes, drives the stick (or a twist
directly) and reads positions, grasp state, mode and counters.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin

from sim.config import MODELS_DIR, SimConfig, load_config
from sim.controller import CartesianVelocityController, JointLimits, Workspace
from sim.errors import SimError
from sim.kernels import clip
from sim.joystick import THREE_AXIS, ArmCommand, JoystickInterpreter, JoystickState, Layout, Mode
from sim.kinematics import arm_kinematics
from sim.render import FrameRenderer, Legend
from sim.scene import Scene, build_scene

# Tool frame with the hand pointing down (tool z = -world z) and the fingers closing along world x.
HAND_DOWN = np.diag([1.0, -1.0, -1.0])


def as_slice(ids: np.ndarray) -> slice | np.ndarray:
    """``ids`` as a slice where they are consecutive (indexing then takes a view, not a gather)."""
    ids = np.asarray(ids)
    if len(ids) and np.array_equal(ids, np.arange(ids[0], ids[0] + len(ids))):
        return slice(int(ids[0]), int(ids[0]) + len(ids))
    return ids


def joint_limits(scene: Scene) -> JointLimits:
    """Ranges (infinite for the continuous joints) and speed limits (the actuators' ctrlrange) of joints 1-6."""
    model = scene.model
    joints = model.actuator_trnid[scene.arm_actuators, 0]
    limited = model.jnt_limited[joints].astype(bool)
    ranges = model.jnt_range[joints]
    return JointLimits(lower=np.where(limited, ranges[:, 0], -np.inf),
                       upper=np.where(limited, ranges[:, 1], np.inf),
                       speed=model.actuator_ctrlrange[scene.arm_actuators, 1].copy())


class ArmSim:
    """The JACO arm, hand and cubes on the table, advanced one control tick at a time."""

    def __init__(self, config: SimConfig | None = None, models_dir: Path = MODELS_DIR, layout: Layout = THREE_AXIS):
        self.config = config or load_config()
        self.scene = build_scene(self.config, models_dir)
        self.model = self.scene.model
        self._check_frame_size()
        self.data = mujoco.MjData(self.model)
        self.dt = 1.0 / self.config.physics.control_hz
        self.kinematics = arm_kinematics(self.scene)
        self.limits = joint_limits(self.scene)
        self.home_q = self._solve_home()
        self.workspace = self._workspace()
        self.controller = CartesianVelocityController(self.kinematics, self.limits, self.workspace,
                                                      self.config.control, self.dt)
        self.joystick = JoystickInterpreter(self.config.control.full_speed, self.config.control.wrist_speed, layout)
        self.finger_target: list[float] = [0.0, 0.0, 0.0]  # the fingers' servo targets (rad)
        self._cube_quat_index = np.array([np.arange(a + 3, a + 7) for a in self.scene.cube_qpos], dtype=np.intp)
        # geom id -> finger (0, 1, 2) and -> cube (0 .. n-1): a contact's role looked up, not searched for
        self._finger_of = {g: i for i, geoms in enumerate(self.scene.finger_geoms) for g in geoms}
        self._cube_of = {g: k for k, g in enumerate(self.scene.cube_geoms.tolist())}
        self._finger_span = (self.scene.finger_range[:, 1] - self.scene.finger_range[:, 0]).tolist()
        self._finger_limit = self.model.actuator_ctrlrange[self.scene.finger_actuators, 1].tolist()
        self._finger_bounds = self.scene.finger_range.tolist()  # (lower, upper) per finger
        # the addresses read and written every control tick
        self._arm_q, self._finger_q = as_slice(self.scene.arm_qpos), as_slice(self.scene.finger_qpos)
        self._arm_ctrl, self._finger_ctrl = as_slice(self.scene.arm_actuators), as_slice(self.scene.finger_actuators)
        self._cube_rows = as_slice(self.scene.cube_geoms)
        # MjData's arrays keep their buffers for its lifetime: the ones read every control tick are
        # fetched once (each attribute read of MjData makes a new array object)
        self._qpos, self._geom_xpos, self._ctrl = self.data.qpos, self.data.geom_xpos, self.data.ctrl
        self._substeps = self.config.physics.substeps
        self._tool_xpos = self.data.site_xpos[self.scene.tool_site]  # live views of the tool site's row
        self._tool_xmat = self.data.site_xmat[self.scene.tool_site]
        self._finger_lower = self.scene.finger_range[:, 0].tolist()
        self._renderer: FrameRenderer | None = None
        # the tick's compiled kernels loaded now: a kernel's first call imports numba and loads its
        # machine code (~0.5 s), which a paced loop (bomi live) must not spend between two ticks;
        # reset() below puts the controller back
        self.controller.reset(self.home_q)
        self.controller.joint_velocities(self.home_q, np.zeros(3), np.zeros(3))
        self.reset()

    def _check_frame_size(self) -> None:
        """The configured frame must fit the scene's offscreen framebuffer (MJCF ``<global offwidth
        offheight>``): checked here, before any work, not when the first frame is filmed."""
        render, visual = self.config.render, self.model.vis.global_
        for name, size, buffer in (("width", render.width, visual.offwidth), ("height", render.height, visual.offheight)):
            if size > buffer:
                raise SimError(f"{self.config.source}: [render] {name}: {size} px exceeds the scene's offscreen "
                               f"framebuffer ({buffer} px, <global off{name}> in the scene's MJCF)")

    def _solve_home(self) -> np.ndarray:
        """Joint angles of the configured home pose (hand down), checked against the joint ranges."""
        home = np.array(self.config.arm.home_tool_pos)
        try:
            q = self.kinematics.solve_pose(home, HAND_DOWN, np.array(self.config.arm.home_seed))
        except ValueError as exc:
            raise SimError(f"{self.config.source}: [arm] home_tool_pos: {exc} (hand down)") from None
        if np.any(q < self.limits.lower) or np.any(q > self.limits.upper):
            raise SimError(f"{self.config.source}: [arm] home_tool_pos: the joint solution from home_seed "
                           "leaves a joint range; choose another home_seed")
        return q

    def _workspace(self) -> Workspace:
        """The virtual walls; the home pose must lie inside them."""
        table = self.scene.table_geom
        table_top = float(self.model.geom_pos[table, 2] + self.model.geom_size[table, 2])
        workspace = Workspace.from_config(self.config.workspace, self._shoulder_position(), table_top,
                                          self._hand_box())
        home = np.array(self.config.arm.home_tool_pos)
        if not workspace.contains(home, HAND_DOWN, tolerance=1e-6):
            raise SimError(f"{self.config.source}: [arm] home_tool_pos {home.tolist()} lies outside the [workspace]")
        return workspace

    def _shoulder_position(self) -> np.ndarray:
        """World position of joint 2's axis: the centre of the reach shell."""
        pin.forwardKinematics(self.kinematics.model, self.kinematics.data, self.home_q)
        joint2 = self.kinematics.model.getJointId("joint_2")
        return self.kinematics.base.act(self.kinematics.data.oMi[joint2].translation)

    def _hand_box(self) -> np.ndarray:
        """Corners (8, 3) of the box around every hand mesh vertex, fingers open and closed, tool frame."""
        points = []
        for closure in (0, 1):
            self.data.qpos[self.scene.finger_qpos] = self.scene.finger_range[:, closure]
            mujoco.mj_kinematics(self.model, self.data)
            tool_rotation = self.data.site_xmat[self.scene.tool_site].reshape(3, 3)
            tool_position = self.data.site_xpos[self.scene.tool_site]
            for geom in self.scene.hand_geoms:
                mesh = self.model.geom_dataid[geom]
                start = self.model.mesh_vertadr[mesh]
                vertices = self.model.mesh_vert[start:start + self.model.mesh_vertnum[mesh]]
                world = self.data.geom_xpos[geom] + vertices @ self.data.geom_xmat[geom].reshape(3, 3).T
                points.append((world - tool_position) @ tool_rotation)
        points = np.vstack(points)
        lo, hi = points.min(axis=0), points.max(axis=0)
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])

    # -- episode -------------------------------------------------------------------------------

    def default_cube_positions(self) -> np.ndarray:
        """Cubes side by side at location A, as configured: (n, 2) x, y."""
        return self.scene.location_a + np.array(self.config.scene.cube_offsets)

    def reset(self, cube_positions: Sequence[Sequence[float]] | None = None,
              arm_qpos: Sequence[float] | None = None) -> None:
        """Arm at home (or ``arm_qpos``), hand open, cubes on the table at ``(x, y)`` or ``(x, y, yaw)`` each."""
        poses = self.default_cube_positions() if cube_positions is None else np.asarray(cube_positions, float)
        if poses.ndim != 2 or poses.shape[0] != len(self.scene.cube_qpos) or poses.shape[1] not in (2, 3):
            raise ValueError(f"cube_positions must be {len(self.scene.cube_qpos)} rows of (x, y) or (x, y, yaw), "
                             f"got shape {poses.shape}")
        mujoco.mj_resetData(self.model, self.data)
        start = self.home_q if arm_qpos is None else np.asarray(arm_qpos, float)
        self.data.qpos[self.scene.arm_qpos] = start
        self.data.qpos[self.scene.finger_qpos] = self.scene.finger_range[:, 0]
        for address, pose in zip(self.scene.cube_qpos, poses):
            yaw = pose[2] if len(pose) == 3 else 0.0
            self.data.qpos[address:address + 3] = (pose[0], pose[1], self.scene.cube_half_size)
            self.data.qpos[address + 3:address + 7] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
        mujoco.mj_forward(self.model, self.data)
        self.controller.reset(start)
        self.joystick.reset()
        self.finger_target = self.data.qpos[self.scene.finger_qpos].tolist()

    # -- control ---------------------------------------------------------------------------------

    def step(self, state: JoystickState) -> ArmCommand:
        """One control tick driven by the joystick; returns the command it produced."""
        command = self.joystick.update(state)
        self.step_twist(command.linear, command.angular, command.finger)
        return command

    def step_twist(self, linear: Sequence[float], angular: Sequence[float] = (0.0, 0.0, 0.0),
                   finger: float = 0.0) -> None:
        """One control tick below the joystick: a tool twist (m/s, rad/s, world axes), finger rate in [-1, 1]."""
        ctrl = self._ctrl
        ctrl[self._arm_ctrl] = self.controller.joint_velocities(self.arm_qpos, linear, angular)
        ctrl[self._finger_ctrl] = self._finger_velocities(min(1.0, max(-1.0, float(finger))))
        mujoco.mj_step(self.model, self.data, nstep=self._substeps)

    def _finger_velocities(self, rate: float) -> list[float]:
        """Move the finger target at ``rate * finger_speed``; servo toward it so a grip keeps squeezing.
        (On Python floats: the same sums, products and bounds as on arrays of three.)"""
        control = self.config.control
        step, gain = rate * control.finger_speed * self.dt, control.finger_gain
        self.finger_target = [clip(target + step, lower, upper)
                              for target, (lower, upper) in zip(self.finger_target, self._finger_bounds)]
        return [clip(gain * (target - q), -limit, limit)
                for target, q, limit in zip(self.finger_target, self._qpos[self._finger_q].tolist(),
                                            self._finger_limit)]

    # -- read-outs -------------------------------------------------------------------------------

    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def arm_qpos(self) -> np.ndarray:
        return self._qpos[self._arm_q].copy()

    @property
    def tool_position(self) -> np.ndarray:
        return self._tool_xpos.copy()

    @property
    def tool_rotation(self) -> np.ndarray:
        return self._tool_xmat.reshape(3, 3).copy()

    @property
    def tool_rotation_rows(self) -> list[float]:
        """The tool's rotation matrix as 9 Python floats, row after row (what a per-tick reader needs)."""
        return self._tool_xmat.tolist()

    @property
    def finger_closure(self) -> float:
        """Mean finger closure: 0 fully open, 1 fully closed."""
        # np.mean's sum (left to right; not sum(), compensated from Python 3.12) and division, on floats
        closures = [(q - lower) / span for q, lower, span in zip(self._qpos[self._finger_q].tolist(), self._finger_lower,
                                                                  self._finger_span)]
        total = closures[0]
        for closure in closures[1:]:
            total += closure
        return total / len(closures)

    @property
    def cube_positions(self) -> np.ndarray:
        """(n, 3) cube centres."""
        return self._geom_xpos[self._cube_rows].copy()

    @property
    def cube_quats(self) -> np.ndarray:
        """(n, 4) cube orientations (w, x, y, z)."""
        return self._qpos[self._cube_quat_index]

    @property
    def mode(self) -> Mode:
        return self.joystick.mode

    @property
    def layout(self) -> Layout:
        return self.joystick.layout

    @property
    def mode_switches(self) -> int:
        return self.joystick.mode_switches

    @property
    def button_presses(self) -> int:
        return self.joystick.button_presses

    @property
    def automatic_switches(self) -> int:
        return self.joystick.automatic_switches

    def switch_mode(self, mode: Mode) -> None:
        """Put the arm in ``mode`` without a button press (what an assistance does; counted apart)."""
        self.joystick.switch_to(mode)

    def _contact_pairs(self) -> list[list[int]]:
        """The [geom1, geom2] pairs of the active contacts."""
        return self.data.contact.geom.tolist()

    def touching(self, geoms_a: frozenset[int], geoms_b: frozenset[int],
                 pairs: list[list[int]] | None = None) -> bool:
        """Whether any active contact (of ``pairs``, by default the current ones) joins a geom of
        ``geoms_a`` to one of ``geoms_b``."""
        return any((a in geoms_a and b in geoms_b) or (a in geoms_b and b in geoms_a)
                   for a, b in (self._contact_pairs() if pairs is None else pairs))

    def cube_in_grasp(self) -> tuple[bool, ...]:
        """Per cube: held between finger 1 and at least one of the opposing fingers 2, 3."""
        touched = set()  # (finger, cube) of the active contacts
        finger_of, cube_of = self._finger_of, self._cube_of
        for a, b in self._contact_pairs():
            if a in finger_of and b in cube_of:
                touched.add((finger_of[a], cube_of[b]))
            if b in finger_of and a in cube_of:
                touched.add((finger_of[b], cube_of[a]))
        return tuple([(0, k) in touched and ((1, k) in touched or (2, k) in touched) for k in range(len(cube_of))])

    # -- rendering -------------------------------------------------------------------------------

    def render(self, caption: str | Sequence[str] | None = None, legend: Legend = ()) -> np.ndarray:
        """An RGB frame from the fixed workspace camera, with optional caption lines on top and a
        legend of marker colours below."""
        if self._renderer is None:
            settings = self.config.render
            self._renderer = FrameRenderer(self.model, settings.camera, settings.width, settings.height)
        return self._renderer.render(self.data, caption, legend)

    def close(self) -> None:
        """Release the rendering context (if a frame was rendered)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
