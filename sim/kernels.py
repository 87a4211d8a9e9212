"""The control tick's arithmetic on floats and small arrays: ``clip`` for the Python paths (the
arm's, the scripted user's: the builtin form's result, bit for bit, at a fraction of its call
overhead) and the arm's IK as compiled kernels (``bomi.compiled.kernel``: numba where installed,
the same Python function where not), which ``sim.kinematics`` and ``sim.controller`` call.

Every kernel that calls another lives in this one file, with its callees: numba's on-disk cache
checks only the file of a cached function, so a kernel calling one of another file would keep
running that one's old machine code after an edit there.
"""
from __future__ import annotations

import math

import numpy as np

from bomi.compiled import kernel


def clip(value: float, lower: float, upper: float) -> float:
    """``min(max(value, lower), upper)``: the same two comparisons, made in the same order with the
    same operands (so the same result, NaN and signed zeros included), without two builtin calls."""
    value = lower if lower > value else value
    return upper if upper < value else value


_clip = kernel(clip)  # the same function, for the kernels below


@kernel
def clamp_point(x: float, y: float, z: float, floor: float, walls: np.ndarray) -> tuple[float, float, float]:
    """``Workspace.clamp`` of the point (x, y, z) on floats, ``floor`` being ``lowest_tool_height`` of
    the hand's rotation (the controller's changes only when its target turns) and ``walls`` the
    workspace's ``walls``: the same differences, products, square root and comparisons as on arrays
    of three."""
    sx, sy, sz, reach_min, reach_max = walls[0], walls[1], walls[2], walls[3], walls[4]
    ox, oy, oz = x - sx, y - sy, z - sz
    distance = math.sqrt(ox * ox + oy * oy + oz * oz)
    if distance > reach_max:
        scale = reach_max / distance
        x, y, z = sx + ox * scale, sy + oy * scale, sz + oz * scale
    elif 0 < distance < reach_min:
        scale = reach_min / distance
        x, y, z = sx + ox * scale, sy + oy * scale, sz + oz * scale
    lz, uz = walls[7], walls[10]
    if floor > lz:
        lz = floor
        uz = walls[11] if walls[11] > floor else floor  # max(floor, the box's top)
    return _clip(x, walls[5], walls[8]), _clip(y, walls[6], walls[9]), _clip(z, lz, uz)


@kernel
def damped_least_squares(jacobian: np.ndarray, twist: np.ndarray, damping_squared: float) -> np.ndarray:
    """qd = J^T (J J^T + lambda^2 I)^-1 twist: well-behaved near singularities.  The products are
    BLAS's and the solve LAPACK's dgesv, as numpy calls them, compiled or not: the same bits."""
    jjt = jacobian @ jacobian.T
    for i in range(len(jjt)):
        jjt[i, i] += damping_squared
    return jacobian.T @ np.linalg.solve(jjt, twist)


@kernel
def speed_scale(qd: np.ndarray, speed_limit: np.ndarray) -> float:
    """Largest factor <= 1 that keeps every joint within its speed limit (same factor for all)."""
    ratio = abs(qd[0]) / speed_limit[0]  # the largest |qd| / limit (the first of equals, as max())
    for j in range(1, len(qd)):
        r = abs(qd[j]) / speed_limit[j]
        if r > ratio:
            ratio = r
    return 1.0 if ratio <= 1.0 else 1.0 / ratio


@kernel
def vector_length(vector: np.ndarray) -> float:
    """sqrt(v @ v), the dot product BLAS's ddot, as numpy's ``@``."""
    return math.sqrt(vector @ vector)


@kernel
def tool_in_world(base: np.ndarray, placement: np.ndarray, position: np.ndarray, rotation: np.ndarray) -> None:
    """The tool's world ``position`` and ``rotation`` (written into them) from the base's placement in
    the world and the tool's on the base (4x4 homogeneous each): ``base @ placement``'s products,
    each summed left to right.  (Pinocchio's own SE3 product sums its third row right to left, so on
    a base turned in the world the two may differ in the last bit; on the scene's base, at the
    world's origin and unturned, every product is exact and both give the same bits.)"""
    for i in range(3):
        b0, b1, b2 = base[i, 0], base[i, 1], base[i, 2]
        for j in range(3):
            rotation[i, j] = b0 * placement[0, j] + b1 * placement[1, j] + b2 * placement[2, j]
        position[i] = b0 * placement[0, 3] + b1 * placement[1, 3] + b2 * placement[2, 3] + base[i, 3]


@kernel
def jacobian_in_world(base_rotation: np.ndarray, jacobian: np.ndarray) -> None:
    """A Jacobian [linear; angular] in the base's axes turned, in place, into the world's: the base
    rotation times each block (BLAS's dgemm, as numpy's ``@``: the same bits compiled or not)."""
    jacobian[:3] = base_rotation @ jacobian[:3]
    jacobian[3:] = base_rotation @ jacobian[3:]


@kernel
def advance_target(jacobian: np.ndarray, base_rotation: np.ndarray, base: np.ndarray, placement: np.ndarray,
                   linear: np.ndarray, target: np.ndarray, target_rotation: np.ndarray, floor: float,
                   walls: np.ndarray, gains: np.ndarray, hand_position: np.ndarray, hand_rotation: np.ndarray,
                   to_target: np.ndarray, twist: np.ndarray) -> None:
    """A tick's first half, in place: the tool's pose (``hand_position``, ``hand_rotation``) and the
    ``jacobian`` turned into the world's axes; the ``target``'s position (row 0; row 1 keeps where
    it was) moved by the command ``linear`` inside the walls and held within max_tracking_error of
    the hand (anti-windup); the twist's linear part (the feedforward velocity plus the pull toward
    the target) and ``to_target = target_rotation @ hand_rotation.T`` (whose ``log3`` is the
    rotation error).  ``gains``: dt, position_gain, max_tracking_error."""
    tool_in_world(base, placement, hand_position, hand_rotation)
    jacobian_in_world(base_rotation, jacobian)
    dt, gain, max_tracking_error = gains[0], gains[1], gains[2]
    tx, ty, tz = target[0, 0], target[0, 1], target[0, 2]
    target[1] = target[0]
    wx, wy, wz = clamp_point(tx + linear[0] * dt, ty + linear[1] * dt, tz + linear[2] * dt, floor, walls)
    fx, fy, fz = (wx - tx) / dt, (wy - ty) / dt, (wz - tz) / dt  # the feedforward velocity
    px, py, pz = hand_position[0], hand_position[1], hand_position[2]
    gx, gy, gz = wx - px, wy - py, wz - pz
    distance = math.sqrt(gx * gx + gy * gy + gz * gz)
    if distance > max_tracking_error:
        scale = max_tracking_error / distance
        wx, wy, wz = px + gx * scale, py + gy * scale, pz + gz * scale
    target[0, 0], target[0, 1], target[0, 2] = wx, wy, wz
    twist[0], twist[1], twist[2] = fx + gain * (wx - px), fy + gain * (wy - py), fz + gain * (wz - pz)
    to_target[:] = target_rotation @ hand_rotation.T


@kernel
def solve_joint_velocities(jacobian: np.ndarray, twist: np.ndarray, angular: np.ndarray, turn: np.ndarray,
                           orientation_gain: float, damping_squared: float, q: np.ndarray,
                           joint_bounds: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float]:
    """A tick's second half: the twist's angular part (the command plus the pull toward the target's
    rotation, ``turn`` its rotation error); damped least squares; the limited joints within the
    margin of a range end and moving further toward it (``joint_bounds`` rows: where each stops
    below, above, and its speed limit) blocked and the rest solved again without them; the whole
    vector scaled to the speed limits and the ``target``'s position moved back by as much (the arm
    does only this fraction of the tick's motion: so does the target, which then never runs ahead,
    and the hand stops where it is when the command stops).  Returns the joint velocities and the
    scale."""
    for i in range(3):
        twist[3 + i] = angular[i] + orientation_gain * turn[i]
    qd = damped_least_squares(jacobian, twist, damping_squared)
    blocked = np.zeros(len(qd), dtype=np.bool_)
    for j in range(len(qd)):
        a, v = q[j], qd[j]
        blocked[j] = (a <= joint_bounds[0, j] and v < 0) or (a >= joint_bounds[1, j] and v > 0)
    if blocked.any():
        for j in range(len(qd)):
            if blocked[j]:
                jacobian[:, j] = 0.0
        qd = damped_least_squares(jacobian, twist, damping_squared)
        for j in range(len(qd)):
            if blocked[j]:
                qd[j] = 0.0
    scale = speed_scale(qd, joint_bounds[2])
    if scale < 1.0:
        for i in range(3):
            previous = target[1, i]
            target[0, i] = previous + scale * (target[0, i] - previous)
        for j in range(len(qd)):
            qd[j] = qd[j] * scale
    return qd, scale
