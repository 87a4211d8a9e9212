"""The stacking task as a Gymnasium environment: gymnasium's own checker, the action -> stick
conversion, episodes stepped through the raw Gymnasium API against ``run_episode``'s records (to the
bit), and what ends an episode (terminated: stacked or a cube off the table; truncated: the time limit)."""
from types import SimpleNamespace

import gymnasium
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from sim.joystick import THREE_AXIS, JoystickState
from tasks.stacking.env import ENV_ID, StackingEnv, as_state, stick_state
from tasks.stacking.channels import JoystickChannel, calibrated_channel
from tasks.stacking.episode import process_arm, run_episode
from tasks.stacking.sources import DeviceSource, Operator, bomi_user, joystick_user
from tasks.stacking.task import TaskConfig
from tasks.trials.replay import LoggedStick

@pytest.fixture(scope="module")
def env():
    return StackingEnv(process_arm(THREE_AXIS))


def test_gymnasium_checker_passes(env):
    check_env(env, skip_render_check=True)


def test_registered_and_made_by_id():
    made = gymnasium.make(ENV_ID, config=TaskConfig(time_limit=1.0))
    obs, info = made.reset(seed=4)
    assert obs in made.observation_space and info["task_seed"] == 4
    made.close()


def test_an_action_is_the_stick_a_logged_tick_is():
    action = {"stick": np.array([0.0, 0.25, 0.0, 1.0, 0.0, 0.5]), "buttons": np.array([0, 1], dtype=np.int8)}
    state = as_state(action)
    # F, B, R, L, Rr, Lr: the functions above 0 are held; B1, B2: B2 pressed
    assert state == JoystickState({"B": 0.25, "L": 1.0, "Lr": 0.5}, frozenset({"B2"}))
    assert list(state.deflection) == ["B", "L", "Lr"]  # in FUNCTIONS order, as a log's columns are
    assert all(type(v) is float for v in state.deflection.values())
    logged = LoggedStick(action["stick"][None, :], action["buttons"][None, :].astype(bool))
    assert logged.read(0.0) == state
    logged.k = 0  # a device is an action source too: read at the view's time
    assert DeviceSource(logged).act({"view": SimpleNamespace(t=0.0)}) == state
    assert as_state(state) is state  # the fast path: a stick as it is
    assert stick_state([0.0] * 6, [0, 0]) == JoystickState()


def _gym_episode(env, source: Operator, seed: int) -> tuple[np.ndarray, tuple[str, ...], dict, float]:
    """Reset/step through the Gymnasium API until done: the hand seen before each tick, the person's
    goal at each tick, the last info and the rewards' sum."""
    obs, info = env.reset(seed=seed)
    hand, goals, rewards, done = [], [], 0.0, False
    while not done:
        hand.append(info["view"].hand_pos)
        obs, reward, terminated, truncated, info = env.step(source.act(info))
        goals.append(source.intent.goal.step)
        assert obs in env.observation_space
        rewards += reward
        done = terminated or truncated
    assert rewards == obs["phase"]  # the rewards sum to the cubes in place at the end
    return np.array(hand), tuple(goals), info, rewards


def _same_episode(log, hand, goals, info) -> None:
    np.testing.assert_array_equal(hand, log.hand_pos)  # every tick's hand, bit for bit
    assert goals == log.goals
    outcome = info["outcome"]
    assert (outcome.success, outcome.completion_time, outcome.failure) == (log.success, log.completion_time, log.failure)


def test_a_scripted_episode_through_the_api_is_run_episodes_to_the_bit():
    seed, config = 2, TaskConfig(time_limit=40.0)
    log = run_episode(JoystickChannel(), operator="joystick", participant="-", seed=seed, task_config=config)
    hand, goals, info, _ = _gym_episode(StackingEnv(process_arm(THREE_AXIS), config=config),
                                        joystick_user(seed=seed), seed)
    _same_episode(log, hand, goals, info)


@pytest.mark.long
def test_a_virtual_participant_through_the_api_is_run_episodes_to_the_bit():
    """The README's lines: a simulated BoMI user (P1's twin through the chain) as the action source
    of ``gymnasium.make``'s environment, against ``run_episode`` on the same seed."""
    seed, config = 3, TaskConfig(time_limit=20.0)
    log = run_episode(calibrated_channel("P1", seed), operator="bomi", participant="P1", seed=seed, task_config=config)
    user = bomi_user("P1", seed=seed)
    env = gymnasium.make(ENV_ID, layout=user.layout, config=config)
    hand, goals, info, _ = _gym_episode(env, user, seed)
    env.close()
    _same_episode(log, hand, goals, info)
    decisions = user.channel.log_fields()["decisions"]
    for name in ("t", "intended", "decided", "gamma", "nu"):
        np.testing.assert_array_equal(getattr(decisions, name), getattr(log.decisions, name))
    assert len(decisions.t) > 100  # the chain decided all along


def _place(env: StackingEnv, positions) -> None:
    sim = env.sim
    for address, pos in zip(sim.scene.cube_qpos, positions):
        sim.data.qpos[address:address + 3] = pos
        sim.data.qpos[address + 3:address + 7] = (1.0, 0.0, 0.0, 0.0)
    sim.data.qvel[:] = 0.0
    mujoco.mj_forward(sim.model, sim.data)


def test_the_time_limit_truncates(env):
    short = StackingEnv(env.sim, config=TaskConfig(time_limit=0.5))
    _, info = short.reset(seed=0)
    times, terminated, truncated = [info["view"].t], False, False
    while not (terminated or truncated):
        _, reward, terminated, truncated, info = short.step(JoystickState())
        times.append(info["view"].t)
        assert reward == 0.0
    assert truncated and not terminated and info["outcome"].timed_out
    assert times[-2] < 0.5 <= times[-1]  # the first tick whose end reaches the limit
    assert len(times) - 1 in (30, 31)  # 30 ticks of 1/60 s sum to 0.5 s, give or take a last bit


def test_a_cube_off_the_table_terminates(env):
    env.reset(seed=0)
    _place(env, [(5.0, 5.0, 0.025), env.sim.cube_positions[1]])
    _, _, terminated, truncated, info = env.step(JoystickState())
    assert terminated and not truncated
    assert info["outcome"].failure == "cube 1 knocked off the table" and not info["outcome"].success


def test_a_stack_at_b_rewards_both_cubes_and_terminates_once_still(env):
    _, info = env.reset(seed=0)
    b = info["view"].target_xy
    size = info["view"].cube_size
    _place(env, [(b[0], b[1], size / 2), (b[0], b[1], 1.5 * size)])
    rewards, terminated, truncated, ticks = 0.0, False, False, 0
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env.step(JoystickState())
        rewards, ticks = rewards + reward, ticks + 1
    assert terminated and not truncated and info["outcome"].success
    assert rewards == 2.0 and obs["phase"] == 2
    assert ticks == pytest.approx(TaskConfig().still_time / env.sim.dt, abs=2)


def test_the_film_is_a_wrapper_that_films_every_nth_tick(tmp_path):
    """run_episode's film (``wrappers.Filmed``): at 4x, a 60 Hz loop filmed at the render rate keeps
    every (4 x 60 / fps)-th tick, from the first."""
    import imageio.v2 as imageio

    sim = process_arm(THREE_AXIS)
    path = tmp_path / "film.mp4"
    log = run_episode(JoystickChannel(), operator="joystick", participant="-", seed=1,
                      task_config=TaskConfig(time_limit=1.0), video=path, video_speedup=4.0)
    every = max(1, round(4.0 * sim.config.physics.control_hz / sim.config.render.fps))
    assert imageio.get_reader(path).count_frames() == -(-len(log.t) // every)


def test_free_mode_resets_the_arm_without_a_task_and_judges_nothing(env):
    """``reset(options={"task": False})``: the scene as built (a new arm's state to the bit: the cubes at A
    unturned, no jitter drawn, no task seed), then no outcome at all: a stack at B is not rewarded or
    ended, a cube off the table does not terminate, the time limit does not truncate; the next reset
    with a seed is a task again."""
    from sim.env import ArmSim
    from tasks.stacking.task import NOT_DONE

    fresh = ArmSim()
    free = StackingEnv(env.sim, config=TaskConfig(time_limit=0.05))
    obs, info = free.reset(seed=3, options={"task": False})
    assert info["task_seed"] is None and obs in free.observation_space
    np.testing.assert_array_equal(env.sim.data.qpos, fresh.data.qpos)
    np.testing.assert_array_equal(env.sim.cube_positions, fresh.cube_positions)
    b, size = info["view"].target_xy, info["view"].cube_size
    _place(free, [(b[0], b[1], size / 2), (b[0], b[1], 1.5 * size)])   # stacked at B
    for _ in range(90):                          # 1.5 s: still for longer than still_time, beyond the limit
        obs, reward, terminated, truncated, info = free.step(JoystickState())
        assert (reward, terminated, truncated, info["outcome"]) == (0.0, False, False, NOT_DONE)
    assert obs["phase"] == 2
    _place(free, [(5.0, 5.0, 0.025), (b[0], b[1], size / 2)])            # a cube off the table
    obs, reward, terminated, truncated, info = free.step(JoystickState({"F": 1.0}))
    assert (reward, terminated, truncated, info["outcome"]) == (0.0, False, False, NOT_DONE)
    assert info["command"].linear.any()          # the arm follows the stick
    _, info = free.reset(seed=3)
    truncated = [free.step(JoystickState())[3] for _ in range(4)]   # a task again: its time limit ends it
    assert info["task_seed"] == 3 and not truncated[0] and truncated[-1]
    fresh.close()
