"""The controller's pure pieces against independent formulations (hypothesis-generated inputs)."""
import numpy as np
import pinocchio as pin
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from helpers import assert_agree, numpy_clamp
from sim.controller import Workspace
from sim.kernels import damped_least_squares, speed_scale

finite = st.floats(-3.0, 3.0, allow_nan=False)
vec3 = arrays(float, 3, elements=finite)
vec6 = arrays(float, 6, elements=finite)
mat6 = arrays(float, (6, 6), elements=finite)

# A downward hand's box: 19 cm long behind the tool point, fingers up to 5 mm beyond it.
HAND_BOX = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.06, 0.03) for z in (-0.193, 0.005)])
WORKSPACE = Workspace(lower=np.array([-0.45, -0.75, 0.0]), upper=np.array([0.45, 0.25, 0.7]),
                      shoulder=np.array([0.0, 0.0, 0.2755]), reach_min=0.25, reach_max=0.8,
                      floor=0.005, hand_box=HAND_BOX)


def rotation_from_vector(vector: np.ndarray) -> np.ndarray:
    return pin.exp3(vector)


def rotations():
    return vec3.map(rotation_from_vector)


@settings(max_examples=200, deadline=None)
@given(mat6, vec6, st.floats(0.001, 0.5))
def test_dls_matches_the_normal_equations_form(jacobian, twist, damping):
    """J^T (J J^T + l^2 I)^-1 x == (J^T J + l^2 I)^-1 J^T x (push-through identity)."""
    expected = np.linalg.solve(jacobian.T @ jacobian + damping**2 * np.eye(6), jacobian.T @ twist)
    np.testing.assert_allclose(damped_least_squares(jacobian.copy(), twist, damping**2), expected,
                               rtol=1e-6, atol=1e-6)


@given(vec6)
def test_speed_scale_keeps_direction_and_fits_the_limits(qd):
    limit = np.array([0.63, 0.63, 0.63, 0.84, 0.84, 0.84])
    scale = speed_scale(qd, limit)
    assert 0 < scale <= 1
    assert np.all(np.abs(qd * scale) <= limit + 1e-12)
    if scale < 1:  # as fast as allowed: some joint is exactly at its limit
        assert np.isclose(np.max(np.abs(qd * scale) / limit), 1.0)


@settings(max_examples=300, deadline=None)
@given(arrays(float, 3, elements=st.floats(-1.5, 1.5)), rotations())
def test_clamp_keeps_box_and_floor_always_and_the_shell_where_they_allow(point, rotation):
    clamped = WORKSPACE.clamp(point, rotation)
    assert np.all(clamped >= WORKSPACE.lower - 1e-9) and np.all(clamped <= WORKSPACE.upper + 1e-9)
    corners = clamped + HAND_BOX @ rotation.T  # the whole hand box, corner by corner, in the world
    assert corners[:, 2].min() >= WORKSPACE.floor - 1e-9
    distance = np.linalg.norm(clamped - WORKSPACE.shoulder)
    if WORKSPACE.reach_min <= distance <= WORKSPACE.reach_max:
        np.testing.assert_allclose(WORKSPACE.clamp(clamped, rotation), clamped, atol=1e-9)  # idempotent


def test_floor_for_a_downward_hand_is_the_finger_overhang():
    down = np.diag([1.0, -1.0, -1.0])
    assert WORKSPACE.lowest_tool_height(down) == np.float64(0.005 + 0.005)
    # Tipped 30 deg about x: world z of a tool-frame point (x, y, z) is -0.5 y - 0.866 z.
    tipped = pin.exp3(np.array([np.radians(30), 0.0, 0.0])) @ down
    expected = 0.005 + 0.5 * 0.03 + np.cos(np.radians(30)) * 0.005
    assert np.isclose(WORKSPACE.lowest_tool_height(tipped), expected)
    # Tipped 30 deg about y: the 10 cm finger span swings down, world z = -0.5 x - 0.866 z.
    tipped = pin.exp3(np.array([0.0, np.radians(30), 0.0])) @ down
    assert np.isclose(WORKSPACE.lowest_tool_height(tipped), 0.005 + 0.5 * 0.1 + np.cos(np.radians(30)) * 0.005)


def test_the_reach_shell_pulls_far_points_in_and_pushes_near_points_out():
    down = np.diag([1.0, -1.0, -1.0])
    far = WORKSPACE.clamp(np.array([0.0, -0.75, 0.6]), down)  # in the box, 0.82 m from the shoulder
    assert np.isclose(np.linalg.norm(far - WORKSPACE.shoulder), 0.8)
    near = WORKSPACE.clamp(np.array([0.0, -0.1, 0.3]), down)
    assert np.isclose(np.linalg.norm(near - WORKSPACE.shoulder), 0.25)


def test_points_inside_are_left_alone():
    down = np.diag([1.0, -1.0, -1.0])
    point = np.array([0.1, -0.4, 0.2])
    np.testing.assert_array_equal(WORKSPACE.clamp(point, down), point)
    assert WORKSPACE.contains(point, down)
    assert not WORKSPACE.contains(np.array([0.1, -0.4, 0.0]), down)


@settings(max_examples=300, deadline=None)
@given(arrays(float, 3, elements=st.floats(-1.2, 1.2, allow_nan=False)), rotations())
def test_clamp_on_floats_agrees_with_the_array_form(point, rotation):
    """Inside and outside the shell, the box and the floor: what the array form gives, to 4 ulps (its
    distance is a BLAS dot product, which the CPU may fuse, the float form's three products and sums)."""
    assert_agree(WORKSPACE.clamp(point, rotation), numpy_clamp(WORKSPACE, point, rotation))
