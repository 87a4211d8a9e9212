"""The stacking task as a Gymnasium environment: the one loop every surface steps.

``StackingEnv`` (registered as ``ENV_ID`` on importing this module; ``gymnasium.make(ENV_ID,
layout="2-axis")``): ``reset(seed=s)`` puts the arm at home and the cubes at A, moved by the
jitter of task seed ``s`` (``task.start_poses``; no seed: one drawn from the env's generator, or
``options={"task_seed": s}``); ``step(action)`` is one control tick: the stick to the arm
(``ArmSim.step``), then the task's outcome (``StackingTask.outcome``), then what the person sees
next (``StackingTask.view``).  Nothing else: no physics call, random draw or read of its own, so
an episode stepped here is the episode ``tasks.stacking.episode.run_episode`` records, bit for bit.

Free mode, ``reset(options={"task": False})``: the arm at home and the cubes at A without a task
(no jitter drawn: the scene ``ArmSim.reset`` sets up, ``task_seed`` None), and no outcome judged
until the next reset: every step's reward is 0, terminated and truncated are False and its info's
``outcome`` is ``NOT_DONE`` (``bomi live``: a person drives the arm for as long as they like, and
a trial's wait before its first task).

- action: a ``Dict`` of ``stick`` (the deflections of F, B, R, L, Rr, Lr in [0, 1]) and ``buttons``
  (B1, B2 pressed this tick), or a ``sim.joystick.JoystickState`` (the project's own sources);
- observation: ``arm`` (joint angles, rad), ``hand`` (pinch point xyz m, yaw rad, tilt to level
  about x and y rad, closure 0 open .. 1 closed), ``cubes`` (per cube: centre xyz m, yaw rad),
  ``touching`` (the fingers hold cube k), ``mode`` (index in the layout's modes), ``phase`` (cubes
  in place: 0, 1 the lower at B, 2 stacked on it);
- reward: the change of ``phase`` (an episode's rewards sum to the cubes in place at its end);
- terminated: stacked and still (success) or a cube off the table; truncated: the time limit;
- info: ``view`` (the ``View`` the operators read), ``outcome`` (``Outcome``), ``state`` (the
  ``JoystickState`` the arm got), ``command`` (the arm's ``Command``), ``dt``, ``full_speed`` and ``wrist_speed``
  (the control period, the hand's speed and turn rate at full deflection: what a person judges speeds by).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import gymnasium
import numpy as np
from gymnasium import spaces

from sim.env import ArmSim
from sim.joystick import BUTTONS, FUNCTIONS, LAYOUTS, THREE_AXIS, JoystickState, Layout
from tasks.stacking.task import NOT_DONE, StackingTask, TaskConfig
from tasks.stacking.vocabulary import View

ENV_ID = "BomiJaco/Stacking-v0"
SEED_RANGE = 2**31  # a task seed drawn by the env's generator (reset without a seed) lies below this


class Command(NamedTuple):
    """The arm's command of a tick (``sim.joystick.ArmCommand``'s fields): a tuple, so that two infos
    compare (gymnasium's checker compares steps' infos)."""

    linear: np.ndarray
    angular: np.ndarray
    finger: float


def stick_state(stick: Sequence[float], buttons: Sequence[Any]) -> JoystickState:
    """The ``JoystickState`` of deflections in ``FUNCTIONS`` order (a function held when above 0) and
    button flags in ``BUTTONS`` order: what an action and a logged tick (``trials.replay``) are."""
    return JoystickState({f: float(v) for f, v in zip(FUNCTIONS, stick) if v > 0},
                         frozenset(b for b, p in zip(BUTTONS, buttons) if p))


def as_state(action: JoystickState | Mapping[str, Any]) -> JoystickState:
    """An action of ``ACTION_SPACE`` (or a ``JoystickState``, as it is) as the stick's state."""
    if isinstance(action, JoystickState):
        return action
    return stick_state(action["stick"], action["buttons"])


def action_space() -> spaces.Dict:
    return spaces.Dict({"stick": spaces.Box(0.0, 1.0, (len(FUNCTIONS),), np.float64),
                        "buttons": spaces.MultiBinary(len(BUTTONS))})


class StackingEnv(gymnasium.Env):
    """The paper's stacking task on the simulated JACO (module docstring).  ``sim``: an arm to use (a
    process's shared one, ``episode.process_arm``), else one of ``layout`` is built."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, sim: ArmSim | None = None, *, layout: str | Layout = THREE_AXIS,
                 config: TaskConfig = TaskConfig(), render_mode: str | None = None):
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.sim = sim or ArmSim(layout=LAYOUTS[layout] if isinstance(layout, str) else layout)
        self.task = StackingTask(self.sim, config)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.sim.config.render.fps}
        self._modes = {mode: k for k, mode in enumerate(self.sim.layout.modes)}
        cubes, joints = len(self.sim.scene.cube_qpos), len(self.sim.arm_qpos)
        self.action_space = action_space()
        self.observation_space = spaces.Dict({
            "arm": spaces.Box(-np.inf, np.inf, (joints,), np.float64),
            "hand": spaces.Box(-np.inf, np.inf, (7,), np.float64),
            "cubes": spaces.Box(-np.inf, np.inf, (cubes, 4), np.float64),
            "touching": spaces.MultiBinary(cubes),
            "mode": spaces.Discrete(len(self._modes)),
            "phase": spaces.Discrete(3),
        })
        self._phase = 0
        self._free = False  # free mode (module docstring): no task, no outcome
        control = self.sim.config.control
        # the units the info gives with every view: what a person judges the arm's speeds by
        self.scales = {"dt": self.sim.dt, "full_speed": control.full_speed, "wrist_speed": control.wrist_speed}

    def reset(self, *, seed: int | None = None, options: Mapping[str, Any] | None = None):
        super().reset(seed=seed)
        options = options or {}
        self._free = not options.get("task", True)
        task_seed = None if self._free else options.get("task_seed", seed)
        if self._free:
            self.sim.reset()  # the scene as built: no jitter drawn
        else:
            if task_seed is None:
                task_seed = int(self.np_random.integers(SEED_RANGE))
            self.task.reset(task_seed)
        view = self.task.view()
        obs = self._observe(view)
        self._phase = obs["phase"]
        return obs, {"view": view, "task_seed": task_seed, **self.scales}

    def step(self, action: JoystickState | Mapping[str, Any]):
        state = as_state(action)
        command = self.sim.step(state)
        outcome = NOT_DONE if self._free else self.task.outcome()
        view = self.task.view()
        obs = self._observe(view)
        reward, self._phase = 0.0 if self._free else float(obs["phase"] - self._phase), obs["phase"]
        info = {"view": view, "outcome": outcome, "state": state,
                "command": Command(command.linear, command.angular, command.finger), **self.scales}
        return obs, reward, outcome.done and not outcome.timed_out, outcome.timed_out, info

    def _observe(self, view: View) -> dict[str, Any]:
        cubes = [[*pos.tolist(), yaw] for pos, yaw in zip(view.cube_pos, view.cube_yaw)]
        placed, _ = self.task.placed([cube[:3] for cube in cubes])
        return {"arm": self.sim.arm_qpos,
                "hand": np.array([*view.hand_pos.tolist(), view.hand_yaw, *view.hand_tilt.tolist(), view.closure]),
                "cubes": np.array(cubes), "touching": np.array(view.touching, dtype=np.int8),
                "mode": self._modes[view.mode], "phase": placed}

    def render(self) -> np.ndarray | None:
        """The fixed workspace camera's frame (``render_mode="rgb_array"``; otherwise None)."""
        return self.sim.render() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self.sim.close()  # the rendering context, if a frame was rendered (the arm itself stays usable)


def register_envs() -> None:
    """Register the project's environments with Gymnasium (once; ``import tasks.stacking.env`` does)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(ENV_ID, entry_point="tasks.stacking.env:StackingEnv")


register_envs()
