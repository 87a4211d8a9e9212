"""The stacking task's verdicts on placed cubes, a whole joystick episode, and the run-task command."""
import json
import math

import mujoco
import numpy as np
import pytest

from tasks.cli import main
from bomi.errors import BomiError
from bomi.profiles import PROFILE_DIR, load_profile
from helpers import assert_agree, edited_copy
from sim.env import ArmSim
from sim.joystick import THREE_AXIS, TWO_AXIS, JoystickState
from tasks.experiments.summary import aggregate, comparison
from tasks.experiments.jobs import benchmark_jobs
from tasks.stacking.channels import JoystickChannel, calibrated_channel, profile_controls
from tasks.stacking.episode import process_arm, run_episode
from tasks.stacking.summary import summarize
from tasks.stacking.vocabulary import Controls
from tasks.stacking.task import StackingTask, TaskConfig, cube_tilt_deg, levelling_rotation, start_poses


@pytest.fixture(scope="module")
def sim():
    return ArmSim()


def place(sim: ArmSim, positions, yaw_deg=(0.0, 0.0)):
    for address, pos, yaw in zip(sim.scene.cube_qpos, positions, np.radians(yaw_deg)):
        sim.data.qpos[address:address + 3] = pos
        sim.data.qpos[address + 3:address + 7] = (np.cos(yaw / 2), 0, 0, np.sin(yaw / 2))
    sim.data.qvel[:] = 0.0  # just reset: nothing else moves
    mujoco.mj_forward(sim.model, sim.data)


def hold_still(task: StackingTask, seconds: float):
    outcome = None
    for _ in range(int(round(seconds / task.sim.dt))):
        task.sim.step(JoystickState())
        outcome = task.outcome()
        if outcome.done:
            break
    return outcome


def test_start_poses_are_seeded_jitter_around_a(sim):
    config = TaskConfig()
    a, b = start_poses(sim, config, 7), start_poses(sim, config, 7)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, start_poses(sim, config, 8))
    offsets = a[:, :2] - sim.default_cube_positions()
    assert np.all(np.abs(offsets) <= config.start_jitter)
    assert np.all(np.abs(np.degrees(a[:, 2])) <= config.start_yaw_deg)


def test_tilt_of_a_cube_is_measured_from_its_nearest_face():
    half_turn = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0])  # 90 deg about x: still flat
    assert cube_tilt_deg(half_turn) == pytest.approx(0.0, abs=1e-9)
    tilted = np.array([np.cos(np.radians(6)), np.sin(np.radians(6)), 0, 0])  # 12 deg about x
    assert cube_tilt_deg(tilted) == pytest.approx(12.0)


def test_levelling_rotation_turns_the_tool_axis_straight_down():
    assert np.allclose(levelling_rotation(np.array([0.0, 0.0, -1.0])), 0.0)
    a = np.radians(20.0)
    tool_z = np.array([np.sin(a), 0.0, -np.cos(a)])  # tipped toward x+
    rotvec = np.r_[levelling_rotation(tool_z), 0.0]
    rotated = np.cos(a) * tool_z + np.sin(a) * np.cross(rotvec / a, tool_z)  # Rodrigues, axis _|_ tool_z
    assert np.allclose(rotated, [0.0, 0.0, -1.0]) and np.isclose(np.linalg.norm(rotvec), a)


def test_a_stack_at_b_that_stays_still_for_a_second_is_a_success(sim):
    task = StackingTask(sim)
    task.reset(0)
    b = task.target_pos[:2]
    place(sim, [(b[0], b[1], 0.025), (b[0] + 0.005, b[1], 0.0755)])
    outcome = hold_still(task, 1.5)
    assert outcome.success and outcome.completion_time < 0.2


def test_a_top_cube_20mm_off_is_not_a_stack(sim):
    task = StackingTask(sim)
    task.reset(0)
    b = task.target_pos[:2]
    place(sim, [(b[0], b[1], 0.025), (b[0] + 0.020, b[1], 0.0755)])
    outcome = hold_still(task, 1.5)
    assert not outcome.done and not task.stacked()


def test_a_cube_off_the_table_fails_the_episode(sim):
    task = StackingTask(sim)
    task.reset(0)
    place(sim, [(0.9, -0.3, -0.2), (-0.14, -0.51, 0.025)])
    outcome = hold_still(task, 0.1)
    assert outcome.done and not outcome.success and "cube 1 knocked off the table" in outcome.failure


def test_time_limit_fails_the_episode(sim):
    task = StackingTask(sim, TaskConfig(time_limit=0.5))
    task.reset(0)
    outcome = hold_still(task, 1.0)
    assert outcome.done and outcome.failure == "time limit 0.5 s"


def test_joystick_operator_stacks_the_cubes_on_a_fixed_seed(sim):
    log = run_episode(JoystickChannel(), operator="joystick", participant="P1", seed=0, sim=sim,
                      task_config=TaskConfig(time_limit=120.0))
    summary = summarize(log)
    assert summary["success"], summary["failure"]
    assert 10.0 < summary["completion_time"] < 120.0
    # two grasps and two releases in finger mode, and back to translation each time
    assert summary["button_presses"] >= 4 and summary["mode_switches"] == summary["button_presses"]
    assert summary["cube_drops"] == 0
    bottom, top = np.argsort(log.cube_pos[-1, :, 2])
    assert np.linalg.norm(log.cube_pos[-1, top, :2] - log.cube_pos[-1, bottom, :2]) <= 0.015
    assert "accuracy_all_decisions" not in summary  # no classifier in this channel


def test_run_task_writes_json_and_plot(tmp_path, capsys):
    out, plot = tmp_path / "run.json", tmp_path / "timeline.png"
    code = main(["run-task", "--operator", "joystick", "--seed", "1", "--time-limit", "120",
                 "--json", str(out), "--plot", str(plot)])
    record = json.loads(out.read_text())
    assert code == 0 and record["success"] is True and record["completion_time"] > 0
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    captured = capsys.readouterr()
    row = next(line for line in captured.out.splitlines() if line.startswith("any "))
    assert row.split()[:3] == ["any", "joystick", "1/1"] and "[" not in row  # no interval for one episode
    # it says what it wrote, and showed the episode's progress meanwhile
    written = captured.out[captured.out.index("wrote:"):].splitlines()[1:]
    assert [line.split()[0] for line in written] == [str(plot), str(out)]
    assert "P1 joystick seed 1: episode:" in captured.err and "s simulated" in captured.err


def test_run_task_with_a_bad_operator_file_is_one_line_and_writes_nothing(tmp_path, capsys):
    bad, out = tmp_path / "op.toml", tmp_path / "run.json"
    bad.write_text("[timing]\nreaction_time = 0.3\n")
    code = main(["run-task", "--operator", "joystick", "--operator-file", str(bad), "--json", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and not out.exists()
    assert err.startswith("bomi: error:") and str(bad) in err and "\n" not in err


def test_benchmark_runs_episodes_in_worker_processes_with_95_percent_intervals(tmp_path, capsys):
    out = tmp_path / "bench.json"
    code = main(["benchmark", "--participants", "P1", "--operators", "joystick", "--seeds", "2", "--jobs", "2",
                 "--time-limit", "120", "--json", str(out)])
    record = json.loads(out.read_text())
    assert code == 0 and [e["seed"] for e in record["episodes"]] == [0, 1]
    row, = record["rows"]
    assert row["successes"] == 2 and row["episodes"] == 2
    times = [e["completion_time"] for e in record["episodes"]]
    assert row["completion_time_mean"] == pytest.approx(sum(times) / 2)
    # two values a and b: mean +- t(0.975, 1) x |a - b| / 2 with t = 12.7062
    half = 12.7062 * abs(times[0] - times[1]) / 2
    assert row["completion_time_ci95"] == pytest.approx([sum(times) / 2 - half, sum(times) / 2 + half], rel=1e-4)
    assert row["success_ci95"] == pytest.approx([2 / (2 + 1.959964 ** 2), 1.0], abs=1e-6)
    assert row["layout"] == "3-axis, B1+B2" and row["participant"] == "any"


def test_benchmark_rejects_an_unknown_operator(capsys):
    assert main(["benchmark", "--operators", "joystick,telepathy", "--seeds", "1"]) == 2
    assert "unknown telepathy" in capsys.readouterr().err


def test_benchmark_runs_the_joystick_once_per_set_of_controls():
    """P4 and P5 have the same controls (2-axis, B1): one joystick row for both, on their layout."""
    jobs = benchmark_jobs(["P1", "P4", "P5"], ["joystick", "bomi"], 1, 60.0, "operator.toml")
    assert [(j.operator, j.participant) for j in jobs] == [("joystick", "P1"), ("bomi", "P1"), ("joystick", "P4"),
                                                           ("bomi", "P4"), ("bomi", "P5")]


def test_bomi_rows_are_compared_with_the_joystick_row_of_their_layout():
    def record(participant, operator, layout, time):
        return {"participant": participant, "operator": operator, "layout": layout, "seed": 0, "success": True,
                "completion_time": time, "failure": None, "mode_switches": 1, "unintended_displacement_mm": 0.0,
                "cube_drops": 0, "realtime_factor": 10.0}
    rows = aggregate([record("P1", "joystick", "3-axis, B1+B2", 20.0), record("P4", "joystick", "2-axis, B1", 40.0),
                      record("P1", "bomi", "3-axis, B1+B2", 80.0), record("P4", "bomi", "2-axis, B1", 200.0)])
    assert [(r["participant"], r["operator"], r["layout"]) for r in rows] == [
        ("P1", "bomi", "3-axis, B1+B2"), ("P4", "bomi", "2-axis, B1"),
        ("any", "joystick", "2-axis, B1"), ("any", "joystick", "3-axis, B1+B2")]
    assert {c["participant"]: c["time_ratio"] for c in comparison(rows)} == {"P1": 4.0, "P4": 5.0}


def test_benchmark_seeds_can_start_anywhere(capsys):
    jobs = benchmark_jobs(["P1", "P4"], ["bomi"], 3, 60.0, "operator.toml", first_seed=20)
    assert [(j.participant, j.seed) for j in jobs] == [("P1", 20), ("P1", 21), ("P1", 22), ("P4", 20), ("P4", 21),
                                                       ("P4", 22)]
    assert main(["benchmark", "--operators", "joystick", "--first-seed", "-1"]) == 2
    assert "argument --first-seed: must not be negative" in capsys.readouterr().err


@pytest.mark.parametrize("old, new, missing", [
    ('layout = "2-axis"', 'layout = "3-axis"', "no class for Rr, Lr"),  # P4's four directions cannot drive 3 axes
    ('function = "B1"', 'function = "B2"', "no class for B1"),
])
def test_a_profile_lacking_a_class_of_its_layout_is_a_one_line_error(tmp_path, old, new, missing):
    path = edited_copy(PROFILE_DIR / "P4.toml", tmp_path / "p4.toml", old, new)
    with pytest.raises(BomiError) as info:
        profile_controls(load_profile(path))
    message = str(info.value)
    assert str(path) in message and missing in message and "\n" not in message


def test_profiles_give_their_layout_and_the_buttons_they_have():
    assert profile_controls(load_profile("P1")) == Controls(THREE_AXIS, ("B1", "B2"))
    assert profile_controls(load_profile("P4")) == Controls(TWO_AXIS, ("B1",))
    assert JoystickChannel().controls == Controls(THREE_AXIS, ("B1", "B2"))  # by default a real 3-axis stick


def test_p4_bomi_episode_moves_the_hand_down_in_height_mode():
    """P4 (four directions and B1) through the 2-axis layout: the hand goes down to a cube.  Seed 0
    reaches the height mode after about 22 s of travel in xy, and is down at the cube by 30 s."""
    channel = calibrated_channel("P4", 0)
    log = run_episode(channel, operator="bomi", participant="P4", seed=0, task_config=TaskConfig(time_limit=32.0))
    assert log.failure.startswith("time limit") and {"translation", "height"} <= set(log.mode)
    height = np.array([mode == "height" for mode in log.mode])[:-1]
    dz = np.diff(log.hand_pos[:, 2])
    assert dz[height].sum() < -0.10  # down by more than 10 cm in height mode
    assert np.abs(dz[~height]).sum() < 0.02  # translation moves the hand in xy only


def test_levelling_rotation_agrees_with_the_one_made_with_numpy_cross():
    """The written-out cross product (a speed-up) gives numpy's rotation to 8 ulps (a norm, an atan2
    and a division, each rounded by whichever libm or BLAS path the CPU picks), zeros as zeros."""
    rng = np.random.default_rng(5)
    down = np.array([0.0, 0.0, -1.0])
    for _ in range(2000):
        tool_z = rng.normal(size=3)
        tool_z /= np.linalg.norm(tool_z)
        tool_z[rng.integers(3)] *= rng.integers(2)  # a zero component now and then
        axis = np.cross(tool_z, down)
        sin, cos = float(np.linalg.norm(axis)), float(np.dot(tool_z, down))
        expected = np.zeros(2) if sin < 1e-12 else (axis * math.atan2(sin, cos) / sin)[:2]
        got = levelling_rotation(tool_z)
        assert_agree(got, expected, ulps=8)
        assert np.array_equal(got == 0.0, expected == 0.0), tool_z


def test_an_episode_on_the_process_s_reused_arm_is_the_episode_on_a_fresh_arm():
    """process_arm is built once per layout: whatever an episode leaves in it (a grasp, a mode,
    counters, MuJoCo's warm start) must not reach the next episode's record."""
    def episode(seed: int, sim: ArmSim | None = None):
        return run_episode(JoystickChannel(), operator="joystick", participant="P1", seed=seed, sim=sim,
                           task_config=TaskConfig(time_limit=6.0))

    episode(1)   # leaves the shared arm moved, mode-switched, maybe holding a cube
    reused, fresh = episode(0), episode(0, ArmSim(layout=THREE_AXIS))
    assert process_arm(THREE_AXIS) is process_arm(THREE_AXIS)
    assert reused.presses > 0 and reused.mode == fresh.mode and reused.presses == fresh.presses
    for field in ("t", "hand_pos", "cube_pos", "touching"):
        assert np.array_equal(getattr(reused, field), getattr(fresh, field)), field


def test_view_and_outcome_equal_their_naive_forms_along_the_demo_carry(sim):
    """The task's view and its off-table and tilt tests, written on Python floats, give what the numpy
    formulations give (np.cross, np.linalg.norm, np.any per axis), tick by tick: positions and the
    off-table test exactly (copies and comparisons), the angles to a few ulps (libm's or numpy's acos
    and atan2, whichever path the CPU takes)."""
    from sim.joystick import script_states
    from tasks.cli.sim import DEMO_SCRIPT

    task = StackingTask(sim)
    task.reset(7)
    table_lo, table_hi = task.table_lo, task.table_hi
    for state in script_states(DEMO_SCRIPT, sim.config.physics.control_hz):
        sim.step(state)
        view = task.view()
        rotation = sim.data.site_xmat[sim.scene.tool_site].reshape(3, 3)
        tool_z, down = rotation[:, 2], np.array([0.0, 0.0, -1.0])
        axis = np.cross(tool_z, down)
        sin, cos = np.linalg.norm(axis), np.dot(tool_z, down)
        naive = np.zeros(2) if sin < 1e-12 else (axis * math.atan2(sin, cos) / sin)[:2]
        assert np.allclose(view.hand_tilt, naive, rtol=0, atol=1e-15)
        pos = sim.data.geom_xpos[sim.scene.cube_geoms]
        assert all(np.array_equal(a, b) for a, b in zip(view.cube_pos, pos))
        for quat in sim.cube_quats:
            w, x, y, z = quat
            naive = np.degrees(np.arccos(min(1.0, np.max(np.abs(
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])))))
            assert_agree(cube_tilt_deg(quat.tolist()), naive)
        off = (pos[:, 2] < task.table_z - task.cube_size) | np.any(pos[:, :2] < table_lo, axis=1) \
            | np.any(pos[:, :2] > table_hi, axis=1)
        assert task.outcome().failure == (f"cube {int(np.flatnonzero(off)[0]) + 1} knocked off the table"
                                          if off.any() else None)
