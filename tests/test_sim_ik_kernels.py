"""The IK tick's compiled kernels (sim.kernels): their Python form's results on random inputs and
along real runs, and the tick written naively on arrays, each to a tolerance the operation justifies
(``helpers.disagreement``: libm, numpy and BLAS pick their code paths by the CPU, so only the same
form on the same machine gives the same bits)."""
import sim  # noqa: F401  -- first: sim/__init__ selects headless EGL before mujoco loads
import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sim.controller
import sim.kernels
import sim.kinematics
from bomi.compiled import COMPILED, interpreted
from helpers import disagreement, numpy_clamp
from sim.config import load_config
from sim.env import ArmSim
from sim.kernels import (advance_target, clamp_point, damped_least_squares, jacobian_in_world, solve_joint_velocities,
                         speed_scale, tool_in_world, vector_length)

compiled_only = pytest.mark.skipif(not COMPILED, reason="numba absent or BOMI_NO_JIT set: nothing is compiled")
KERNEL_MODULES = (sim.kernels, sim.controller, sim.kinematics)  # the kernels and where they are called


@pytest.fixture(scope="module")
def arm():
    arm = ArmSim()
    yield arm
    arm.close()


@pytest.fixture(scope="module")
def open_arm():
    """Walls wide open, so that only the joint ranges stop the arm."""
    config = load_config()
    open_space = dataclasses.replace(config.workspace, x=(-2.0, 2.0), y=(-2.0, 2.0), z=(-1.0, 2.0),
                                     reach_min=0.0, reach_max=3.0, table_clearance=0.0)
    arm = ArmSim(dataclasses.replace(config, workspace=open_space))
    yield arm
    arm.close()


def rotation(rng: np.random.Generator) -> np.ndarray:
    return pin.exp3(rng.normal(size=3))


# A tick's joint velocities are a damped solve (condition at most (1 + damping^2) / damping^2, ~400 for
# the controller's 0.05 and a unit-scale Jacobian) followed by a few products: 1e-9 of their largest
# magnitude (~4e6 ulps) bounds the rounding of either form with room for the closed loop's accumulation
# over a run, and is far below any branch the tick takes (a wall, a blocked joint, a speed limit).
RUN_TOLERANCE = 1e-9


def same(a, b, ulps: float = 4.0) -> bool:
    """Equal to ``ulps`` units in the last place of the largest magnitude (arrays, floats or tuples)."""
    return disagreement(np.asarray(a, dtype=float), np.asarray(b, dtype=float), ulps) is None


def close(a, b) -> bool:
    """Equal to RUN_TOLERANCE relative to the largest magnitude (at least 1)."""
    b = np.asarray(b, dtype=float)
    return disagreement(a, b, scale=max(1.0, float(np.max(np.abs(b), initial=0.0))),
                        ulps=RUN_TOLERANCE / np.finfo(float).eps) is None


def both(kernel, *args):
    """``kernel`` compiled and interpreted on copies of the same arguments: (result, arguments after) each."""
    runs = []
    for run in (kernel, interpreted(kernel)):
        copies = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
        runs.append((run(*copies), copies))
    return runs


def assert_same_runs(kernel, *args, ulps: float = 4.0) -> None:
    """Compiled and interpreted agree to ``ulps`` (results, and what they wrote in place)."""
    (result, after), (expected, expected_after) = both(kernel, *args)
    if isinstance(result, tuple):
        assert len(result) == len(expected) and all(same(a, b, ulps) for a, b in zip(result, expected))
    else:
        assert same(result, expected, ulps)
    assert all(same(a, b, ulps) for a, b in zip(after, expected_after))


@compiled_only
def test_each_kernel_compiled_equals_its_python_form_on_random_inputs(arm):
    rng = np.random.default_rng(12)
    walls, bounds = arm.workspace.walls, arm.controller._joint_bounds
    for _ in range(300):
        jacobian = rng.normal(size=(6, 6)) * rng.uniform(0.01, 1.0, (6, 6))
        twist, q = rng.normal(size=6), rng.uniform(-1, 7, 6)
        point = rng.uniform(-1.2, 1.2, 3)
        base = np.eye(4)
        base[:3, :3], base[:3, 3] = rotation(rng), rng.normal(size=3)
        placement = np.eye(4)
        placement[:3, :3], placement[:3, 3] = rotation(rng), rng.normal(size=3)
        floor = rng.uniform(-0.1, 0.3)
        damping = rng.uniform(1e-4, 0.1)
        # a solve's rounding grows with its condition: 8 ulps of it (the damped normal matrix's)
        solve_ulps = 8 * np.linalg.cond(jacobian @ jacobian.T + damping * np.eye(6))
        assert_same_runs(clamp_point, *point.tolist(), floor, walls)
        assert_same_runs(damped_least_squares, jacobian, twist, damping, ulps=solve_ulps)
        assert_same_runs(speed_scale, rng.normal(size=6), rng.uniform(0.3, 1.0, 6))
        assert_same_runs(vector_length, rng.normal(size=3) * rng.uniform(1e-6, 3))
        assert_same_runs(tool_in_world, base, placement, np.empty(3), np.empty((3, 3)))
        assert_same_runs(jacobian_in_world, base[:3, :3].copy(), jacobian)
        target = np.array([point, point])
        gains = np.array([1 / 60, rng.uniform(0, 10), rng.uniform(0.001, 0.1)])
        assert_same_runs(advance_target, jacobian, base[:3, :3].copy(), base, placement, rng.normal(size=3) * 0.3,
                         target, rotation(rng), floor, walls, gains, np.empty(3), np.empty((3, 3)), np.empty((3, 3)),
                         twist)
        assert_same_runs(solve_joint_velocities, jacobian, twist, rng.normal(size=3), rng.normal(size=3) * 0.1,
                         rng.uniform(0, 5), damping_squared := rng.uniform(1e-4, 0.01), q, bounds, target,
                         ulps=8 * np.linalg.cond(jacobian @ jacobian.T + damping_squared * np.eye(6)))


def scripted_twists(arm: ArmSim) -> list[tuple[np.ndarray, np.ndarray]]:
    """A run through every branch of the tick: holding still, moving into the walls, the table and
    the reach shell, turning fast enough to meet the joints' speed limits, and turning and moving at once."""
    ticks = round(arm.config.physics.control_hz)
    still, segments = np.zeros(3), []
    for linear, angular, seconds in (
            (still, still, 0.5), ((0.2, 0.0, 0.0), still, 3.0), ((0.0, 0.0, -0.2), still, 2.0),
            ((0.0, -0.3, 0.1), still, 3.0), (still, (1.2, 0.0, 0.0), 1.0), (still, (0.0, 0.0, -1.5), 1.0),
            ((-0.1, 0.1, 0.05), (0.0, 0.8, 0.0), 1.5), (still, still, 0.5)):
        segments += [(np.array(linear, float), np.array(angular, float))] * round(seconds * ticks)
    return segments


def limit_run(arm: ArmSim, joint: int, angle: float, push: float) -> tuple[list[tuple[np.ndarray, np.ndarray]],
                                                                       np.ndarray]:
    """Twists driving one joint outward, into its range's end, from a start near it (returned too):
    the joint's own motion (a move and a turn), which the other joints can make up only in part."""
    start = arm.home_q.copy()
    start[joint] = angle
    twist = push * 0.5 * arm.kinematics.jacobian(start)[:, joint]
    return [(twist[:3], twist[3:])] * 120, start


Tick = dict  # one tick: q, linear, angular, the target before (position rows, rotation); qd, target after


def recorded_ticks(arm: ArmSim, twists, start: np.ndarray | None = None) -> list[Tick]:
    """Each tick of a run of ``twists`` from a reset (arm at ``start``), the physics stepped: the
    controller's inputs and state before the tick and what it gave (joint velocities, target after)."""
    arm.reset(arm_qpos=start)
    controller, ticks = arm.controller, []
    solve = controller.joint_velocities

    def recorded(q, linear, angular):
        tick = {"q": q.copy(), "linear": np.array(linear, float), "angular": np.array(angular, float),
                "target": controller._target.copy(), "rotation": controller.target_rotation.copy()}
        tick["qd"] = solve(q, linear, angular)
        tick["target_after"], tick["rotation_after"] = controller._target.copy(), controller.target_rotation.copy()
        ticks.append(tick)
        return tick["qd"]
    controller.joint_velocities = recorded  # instance attribute shadows the method
    try:
        for linear, angular in twists:
            arm.step_twist(linear, angular)
    finally:
        del controller.joint_velocities
    return ticks


def replayed(arm: ArmSim, tick: Tick) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The controller's tick from a recorded tick's inputs and state: (qd, target after, rotation after)."""
    controller = arm.controller
    controller._target[:] = tick["target"]
    controller.target_rotation = np.array(tick["rotation"], float)
    qd = controller.joint_velocities(np.array(tick["q"], float), tick["linear"], tick["angular"])
    return qd, controller._target.copy(), controller.target_rotation.copy()


def agrees(tick: Tick, again: tuple) -> bool:
    return all(close(a, b) for a, b in zip(again, (tick["qd"], tick["target_after"], tick["rotation_after"])))


# Runs are compared tick by tick from the same inputs, not as two closed loops: the arm's loop (physics,
# the target's lag and walls) grows a last-bit difference by up to ~100x a tick (seen on an AVX-512
# machine: 3e-16 rad/s at tick 32 of the scripted run, 9e-4 at tick 42), so two loops agree only
# as distributions of episodes (benchmarks/records_identity.py --no-jit), never to a tolerance.
@compiled_only
def test_a_real_run_compiled_and_interpreted_agree(arm, open_arm, monkeypatch):
    """Along runs through walls, speed limits and a joint's range end, every tick of the compiled
    controller is replayed with every kernel as its Python function: the same joint velocities and
    target, to RUN_TOLERANCE."""
    runs = [(arm, recorded_ticks(arm, scripted_twists(arm))),
            (open_arm, recorded_ticks(open_arm, *limit_run(open_arm, 2, 5.85, 1.0)))]
    for module in KERNEL_MODULES:
        for name, value in vars(module).copy().items():
            if hasattr(value, "py_func"):
                monkeypatch.setattr(module, name, value.py_func)
    for a, ticks in runs:
        assert len(ticks) > 100 and all(agrees(tick, replayed(a, tick)) for tick in ticks)


class NaiveTick:
    """The controller's tick written on arrays the plain way (Pinocchio's SE3 product, numpy's
    products, np.linalg.solve), an independent reference; it counts the branches it takes."""

    def __init__(self, arm: ArmSim):
        controller = arm.controller
        self.kinematics, self.workspace, self.config, self.dt = (controller.kinematics, controller.workspace,
                                                                  controller.config, controller.dt)
        self.position, self.rotation = np.array(controller.target_position), controller.target_rotation.copy()
        margin = self.config.joint_limit_margin
        self.lower, self.upper, self.speed = arm.limits.lower + margin, arm.limits.upper - margin, arm.limits.speed
        self.branches = dict.fromkeys(("wall", "lag", "turn_lag", "blocked", "scaled"), 0)

    def step(self, q: np.ndarray, linear: np.ndarray, angular: np.ndarray) -> np.ndarray:
        kinematics, config, dt = self.kinematics, self.config, self.dt
        local = pin.computeFrameJacobian(kinematics.model, kinematics.data, q, kinematics.tool_frame,
                                         pin.LOCAL_WORLD_ALIGNED)
        base = kinematics.base.rotation
        jacobian = np.vstack((base @ local[:3], base @ local[3:]))
        world = kinematics.base * kinematics.data.oMf[kinematics.tool_frame]
        hand_position, hand = world.translation.copy(), world.rotation.copy()
        previous_position, previous_rotation = self.position, self.rotation
        if np.any(angular):
            self.rotation = pin.exp3(angular * dt) @ self.rotation
        moved = self.position + linear * dt
        target = numpy_clamp(self.workspace, moved, self.rotation)
        self.branches["wall"] += not np.array_equal(target, moved)
        feedforward = (target - self.position) / dt
        gap = target - hand_position
        distance = np.sqrt(np.sum(gap * gap))
        if distance > config.max_tracking_error:
            self.branches["lag"] += 1
            target = hand_position + gap * (config.max_tracking_error / distance)
        self.position = target
        turn = pin.log3(self.rotation @ hand.T)
        angle, max_angle = np.sqrt(turn @ turn), config.max_tracking_error / 0.1
        if angle > max_angle:
            self.branches["turn_lag"] += 1
            self.rotation = pin.exp3(turn * (max_angle / angle)) @ hand
            turn = pin.log3(self.rotation @ hand.T)
        twist = np.concatenate((feedforward + config.position_gain * (target - hand_position),
                                angular + config.orientation_gain * turn))

        def dls(j):
            return j.T @ np.linalg.solve(j @ j.T + config.dls_damping**2 * np.eye(6), twist)
        qd = dls(jacobian)
        blocked = ((q <= self.lower) & (qd < 0)) | ((q >= self.upper) & (qd > 0))
        if blocked.any():
            self.branches["blocked"] += 1
            jacobian[:, blocked] = 0.0
            qd = dls(jacobian)
            qd[blocked] = 0.0
        ratio = np.max(np.abs(qd) / self.speed)
        if ratio > 1.0:
            self.branches["scaled"] += 1
            scale = 1.0 / ratio
            self.position = previous_position + scale * (self.position - previous_position)
            self.rotation = pin.exp3(scale * pin.log3(self.rotation @ previous_rotation.T)) @ previous_rotation
            qd = qd * scale
        return qd


def test_a_real_run_agrees_with_the_naive_tick(arm, open_arm):
    """Tick for tick, the controller's joint velocities and target equal the naive tick's to
    RUN_TOLERANCE, along runs that take every branch (walls, lag, the turn's lag, blocked joints,
    speed limits)."""
    branches = dict.fromkeys(("wall", "lag", "turn_lag", "blocked", "scaled"), 0)
    for a, twists, start in ((arm, scripted_twists(arm), None), (open_arm, *limit_run(open_arm, 1, 0.95, -1.0)),
                             (open_arm, *limit_run(open_arm, 2, 5.85, 1.0))):
        a.reset(arm_qpos=start)
        naive = NaiveTick(a)
        solve = a.controller.joint_velocities

        def checked(q, linear, angular):
            expected = naive.step(q.copy(), np.asarray(linear, float), np.asarray(angular, float))
            qd = solve(q, linear, angular)
            assert close(qd, expected)
            assert close(a.controller.target_position, naive.position)
            assert close(a.controller.target_rotation, naive.rotation)
            return qd
        a.controller.joint_velocities = checked
        try:
            for linear, angular in twists:
                a.step_twist(linear, angular)
        finally:
            del a.controller.joint_velocities
        branches = {k: branches[k] + naive.branches[k] for k in branches}
    assert all(count > 0 for count in branches.values()), branches


def replay_file(path: str) -> None:
    """Replay the ticks saved in ``path`` (.npz, one array per field) and save what each gave beside
    them (what the BOMI_NO_JIT=1 subprocess runs)."""
    arm = ArmSim()
    with np.load(path) as saved:
        fields = {key: saved[key] for key in saved.files}
    ticks = [dict(zip(fields, values)) for values in zip(*fields.values())]
    again = [replayed(arm, tick) for tick in ticks]
    arm.close()
    np.savez(path, **{key: np.array([a[i] for a in again]) for i, key in enumerate(("qd", "target_after",
                                                                                      "rotation_after"))})


@compiled_only
def test_no_jit_moves_the_arm_as_the_compiled_kernels_do(arm, tmp_path):
    """``BOMI_NO_JIT=1`` (every kernel as its Python function, in a fresh process) gives each tick of
    the compiled scripted run the same joint velocities and target, to RUN_TOLERANCE."""
    ticks = recorded_ticks(arm, scripted_twists(arm))
    path = tmp_path / "ticks.npz"
    np.savez(path, **{key: np.array([tick[key] for tick in ticks]) for key in ticks[0]})
    code = f"from test_sim_ik_kernels import replay_file; replay_file({str(path)!r})"
    tests = Path(__file__).resolve().parent
    env = os.environ | {"BOMI_NO_JIT": "1", "PYTHONPATH": os.pathsep.join(
        [str(tests), str(tests.parent), os.environ.get("PYTHONPATH", "")])}
    subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600, cwd=tests,
                   check=True)
    with np.load(path) as again:
        assert len(again["qd"]) == len(ticks) > 500
        assert all(agrees(tick, (again["qd"][i], again["target_after"][i], again["rotation_after"][i]))
                   for i, tick in enumerate(ticks))
