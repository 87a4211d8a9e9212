"""One episode: a source of actions (``sources.Operator``: the scripted user or the human model at
a joystick or BoMI channel) steps the one loop (``env.StackingEnv``) at the 60 Hz control rate,
through the assistance, the recovery supervisor's gate and the film when they are on
(``wrappers``), until success or failure; its record is an ``EpisodeLog`` (``record``).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from functools import cache
from pathlib import Path

import gymnasium
import numpy as np

from bomi.errors import BomiError
from sim.env import ArmSim
from sim.joystick import Kind, Layout, Mode, combined
from tasks.operators.assist import Assist, Assistance, assist_label
from tasks.operators.params import DEFAULT_OPERATOR_FILE, OperatorParams, load_operator
from tasks.stacking.env import StackingEnv
from tasks.stacking.record import EpisodeLog
from tasks.stacking.sources import Operator, operator_at
from tasks.stacking.channels import OperatorChannel
from tasks.stacking.task import TaskConfig
from tasks.stacking.vocabulary import Phase, StickIntent, View
from tasks.stacking.wrappers import Assisted, Filmed, Recovering

OPERATORS = ("joystick", "bomi")
_MODE_VALUE = {mode: mode.value for mode in Mode}  # what a log records of a mode and a stage, looked up
_STAGE_VALUE = {None: "", **{phase: phase.value for phase in Phase}}


def intended_direction(mode: Mode, intent: StickIntent, layout: Layout) -> tuple[float, float, float]:
    """Unit hand direction the person wants this tick (zero unless moving the hand in ``mode`` of
    ``layout``), on Python floats (``norm`` and the division of the combined array, bit for bit)."""
    x, y, z = combined(intent.deflection, layout.axes(mode, Kind.LINEAR))
    length = math.sqrt(x * x + y * y + z * z)
    return (x / length, y / length, z / length) if length > 0 else (x, y, z)


@cache
def process_arm(layout: Layout) -> ArmSim:
    """The arm of this process's episodes with joystick ``layout`` (a module constant of
    ``sim.joystick``), built once: every episode's task resets it (``ArmSim.reset``: MuJoCo's data,
    controller, joystick and counters), so an episode's record does not depend on the ones run
    before it in the process (tests/test_engine.py runs them in both orders), and a sweep's worker
    compiles the scene and the arm's kinematics once, not once per episode."""
    return ArmSim(layout=layout)


def run_episode(channel: OperatorChannel, *, operator: str, participant: str, seed: int,
                operator_file: Path | str | OperatorParams = DEFAULT_OPERATOR_FILE, task_config: TaskConfig = TaskConfig(),
                video: Path | None = None, video_speedup: float = 4.0, sim: ArmSim | None = None,
                on_tick: Callable[[float], None] | None = None, assist: frozenset[Assist] = frozenset()) -> EpisodeLog:
    """Step the task at the control rate until success or failure; optionally film it (played
    ``video_speedup`` times faster than simulated time).  ``operator_file``: the scripted user's
    parameters, or the file they are read from. ``on_tick`` is told the simulated time after every
    tick (a progress bar). ``assist``: the assistances between the channel's stick and the arm
    (tasks.operators.assist)."""
    if not channel.controls.buttons and Assist.AUTO_MODE not in assist:
        raise BomiError(f"the controls {channel.controls.label} change mode only by the automatic mode switching: "
                        f"the scripted user needs --assist {Assist.AUTO_MODE.value}")
    sim = sim or process_arm(channel.controls.layout)
    if sim.layout is not channel.controls.layout:
        raise ValueError(f"the arm has the {sim.layout.name} joystick layout, the operator's controls the "
                         f"{channel.controls.layout.name} one")
    task_env = StackingEnv(sim, config=task_config)
    params = operator_file if isinstance(operator_file, OperatorParams) else load_operator(operator_file)
    person = operator_at(channel, seed, params)
    assistance = Assistance(assist, channel.controls.layout, channel.controls.buttons) if assist else None
    env = loop_env(task_env, person, assistance, video, video_speedup)
    seen_ticks: list[tuple[View, StickIntent]] = []  # what the person saw and wanted, tick by tick (both immutable)
    commanded: list[np.ndarray] = []  # the hand velocity each tick's stick commanded
    started, started_cpu = time.perf_counter(), time.process_time()
    try:
        _, info = env.reset(seed=seed)
        done = False
        while not done:
            view = info["view"]
            _, _, terminated, truncated, info = env.step(person.act(info))
            seen_ticks.append((view, person.intent))
            commanded.append(info["command"].linear)
            if on_tick is not None:
                on_tick(sim.time)
            done = terminated or truncated
    finally:
        env.close()
    views, intents = zip(*seen_ticks)
    outcome, task, supervisor = info["outcome"], task_env.task, person.supervisor
    return EpisodeLog(
        operator=operator, participant=participant, seed=seed, controls=channel.controls.label,
        t=np.array([view.t for view in views]), hand_pos=np.array([view.hand_pos for view in views]),
        intended_dir=np.array([intended_direction(view.mode, intent, sim.layout) for view, intent in seen_ticks]
                              ).reshape(-1, 3),
        mode=[_MODE_VALUE[view.mode] for view in views], presses=sim.button_presses,
        cube_pos=np.array([view.cube_pos for view in views]),
        touching=np.array([view.touching for view in views], dtype=bool), target_pos=task.target_pos.copy(),
        goals=tuple(intent.goal.step for intent in intents),
        stages=tuple(_STAGE_VALUE[intent.goal.phase] for intent in intents),
        pushing=np.array([bool(intent.deflection) for intent in intents], dtype=bool),
        success=outcome.success, completion_time=outcome.completion_time, failure=outcome.failure,
        wall_time=time.perf_counter() - started, cpu_time=time.process_time() - started_cpu,
        assist=assist_label(frozenset(assist)),
        automatic=tuple(assistance.switches) if assistance is not None else (),
        grasp_helps=assistance.grasp_helps if assistance is not None else 0,
        commanded=np.array(commanded).reshape(-1, 3), recovery=params.recovery.label,
        recoveries=tuple(supervisor.events) if supervisor is not None else (), **channel.log_fields())


def loop_env(env: StackingEnv, person: Operator, assistance: Assistance | None = None, video: Path | None = None,
             video_speedup: float = 4.0) -> gymnasium.Env:
    """``env`` with what is on between ``person``'s stick and the arm, and the film (``wrappers``:
    ``Filmed(Assisted(Recovering(env)))``, each only when on).  The film's caption: what happens
    between the person and the stick, their goal, the assistance's last switch."""
    if person.supervisor is not None:
        env = Recovering(env, person.supervisor)
    if assistance is not None:
        env = Assisted(env, assistance)
    if video is not None:
        env = Filmed(env, video, video_speedup, lambda t: (person.channel.caption(), f"goal: {person.intent.goal}",
                                                            None if assistance is None else assistance.caption(t)))
    return env
