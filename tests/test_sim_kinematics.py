"""Pinocchio kinematics of the tool frame against MuJoCo's own site pose and Jacobian."""
import sim  # noqa: F401  -- first: sim/__init__ selects headless EGL before mujoco loads
import mujoco
import numpy as np
import pytest

from helpers import assert_agree
from sim.config import load_config
from sim.env import HAND_DOWN
from sim.kinematics import arm_kinematics
from sim.scene import build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene(load_config())


@pytest.fixture(scope="module")
def kinematics(scene):
    return arm_kinematics(scene)


def random_configurations(count: int, seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.uniform(-np.pi, np.pi, size=(count, 6))
    q[:, 1] = rng.uniform(0.85, 5.4, count)  # joints 2 and 3 are limited
    q[:, 2] = rng.uniform(0.35, 5.9, count)
    return q


def mujoco_tool(scene, q):
    data = mujoco.MjData(scene.model)
    data.qpos[scene.arm_qpos] = q
    data.qpos[scene.finger_qpos] = np.random.default_rng(0).uniform(0.15, 1.35, 3)  # fingers must not matter
    mujoco.mj_forward(scene.model, data)
    jacp = np.zeros((3, scene.model.nv))
    jacr = np.zeros((3, scene.model.nv))
    mujoco.mj_jacSite(scene.model, data, jacp, jacr, scene.tool_site)
    return (data.site_xpos[scene.tool_site].copy(), data.site_xmat[scene.tool_site].reshape(3, 3).copy(),
            np.vstack((jacp[:, scene.arm_dof], jacr[:, scene.arm_dof])))


def rotation_angle(a, b) -> float:
    return float(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1)))


@pytest.mark.parametrize("q", random_configurations(40))
def test_forward_kinematics_and_jacobian_match_mujoco(scene, kinematics, q):
    position, rotation, jacobian = mujoco_tool(scene, q)
    pin_position, pin_rotation = kinematics.tool_pose(q)
    assert np.linalg.norm(pin_position - position) <= 1e-6
    assert rotation_angle(pin_rotation, rotation) <= 1e-4
    pin_jacobian = kinematics.jacobian(q)
    assert np.abs(pin_jacobian[:3] - jacobian[:3]).max() <= 1e-6
    assert np.abs(pin_jacobian[3:] - jacobian[3:]).max() <= 1e-4


def test_tool_frame_is_the_pinch_point_between_the_fingers(scene, kinematics):
    """The tool point sits on the hand's axis, beyond the wrist, between the three fingertips."""
    data = mujoco.MjData(scene.model)
    data.qpos[scene.arm_qpos] = random_configurations(1, seed=3)[0]
    mujoco.mj_forward(scene.model, data)
    tool = data.site_xpos[scene.tool_site]
    wrist = data.site_xpos[scene.wrist_site]
    assert 0.18 < np.linalg.norm(tool - wrist) < 0.21  # dm_control's pinch site: 19.3 cm down the hand
    tips = [data.xpos[scene.model.body(f"jaco_arm/jaco_hand/b_finger_tip_{k}").id] for k in (1, 2, 3)]
    assert np.linalg.norm(np.mean(tips, axis=0) - tool) < 0.07


def test_solve_pose_reaches_the_requested_pose(kinematics):
    target = np.array([0.1, -0.5, 0.15])
    q = kinematics.solve_pose(target, HAND_DOWN, np.array([4.71, 3.6, 1.5, 4.2, 1.5, 0.0]))
    position, rotation = kinematics.tool_pose(q)
    assert np.linalg.norm(position - target) < 1e-6
    assert rotation_angle(rotation, HAND_DOWN) < 1e-6


@pytest.mark.parametrize("q", random_configurations(20, seed=11))
def test_ik_step_agrees_with_the_naive_forms(kinematics, q):
    """The controller's Jacobian (the base rotation times each block, in place) and DLS solve
    (compiled where numba is) give what the plain numpy forms give, to a few ulps (the solve's grown
    by its condition), and agree with a pinv-based DLS."""
    import pinocchio as pin
    from sim.kernels import damped_least_squares

    jac = pin.computeFrameJacobian(kinematics.model, kinematics.data, q, kinematics.tool_frame,
                                   pin.LOCAL_WORLD_ALIGNED)
    rot = kinematics.base.rotation
    naive_jacobian = np.vstack((rot @ jac[:3], rot @ jac[3:]))
    jacobian = kinematics.jacobian(q)
    assert_agree(jacobian, naive_jacobian)       # 3x3 times 3x6 products: a few roundings each
    twist = np.random.default_rng(int(1000 * q[0]) % 2**32).normal(size=6)
    damping = 0.05
    qd = damped_least_squares(jacobian.copy(), twist, damping**2)
    normal = naive_jacobian @ naive_jacobian.T + damping**2 * np.eye(6)
    naive = naive_jacobian.T @ np.linalg.solve(normal, twist)
    assert_agree(qd, naive, ulps=8 * np.linalg.cond(normal))
    by_pinv = naive_jacobian.T @ np.linalg.pinv(naive_jacobian @ naive_jacobian.T + damping**2 * np.eye(6)) @ twist
    np.testing.assert_allclose(qd, by_pinv, rtol=1e-9, atol=1e-9)


def test_the_jacobian_pass_places_the_tool_as_forward_kinematics_bit_for_bit(kinematics):
    """The Jacobian's kinematics pass leaves the tool frame where framesForwardKinematics puts it,
    at every configuration, never where the previous call left it."""
    import pinocchio as pin

    for q in random_configurations(50, seed=11):
        kinematics.jacobian_in_base(q)
        placed = kinematics.tool_placement.homogeneous
        pin.framesForwardKinematics(kinematics.model, kinematics.data, q)
        assert np.array_equal(placed, kinematics.tool_placement.homogeneous)


def test_tool_in_world_is_pinocchios_se3_product(kinematics):
    """On the scene's base (the world's origin, unturned) the same bits as Pinocchio's ``base *
    placement``; on bases turned and moved anywhere, the same to rounding."""
    import pinocchio as pin

    from sim.kernels import tool_in_world

    rng = np.random.default_rng(3)
    for q in random_configurations(20, seed=5):
        position, rotation = kinematics.tool_pose(q)
        world = kinematics.base * kinematics.tool_placement
        assert np.array_equal(position, world.translation) and np.array_equal(rotation, world.rotation)
        base = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
        tool_in_world(base.homogeneous, kinematics.tool_placement.homogeneous, position, rotation)
        world = base * kinematics.tool_placement
        np.testing.assert_allclose(position, world.translation, rtol=0, atol=1e-15)
        np.testing.assert_allclose(rotation, world.rotation, rtol=0, atol=1e-15)
