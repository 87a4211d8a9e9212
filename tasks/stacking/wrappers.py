"""What sits between a source's stick and the arm, or watches the loop: Gymnasium wrappers of
``env.StackingEnv``, so that the loop itself has no branch for them.

- ``Assisted``: the assistance (``tasks.operators.assist.Assistance``: automatic mode switching,
  grasp help) turns the source's stick into the one the arm gets, seeing what the person saw;
- ``Recovering``: the recovery supervisor's gate (``tasks.operators.recovery.Supervisor.gate``):
  the arm at rest while a recovery action stops it;
- ``Filmed``: every n-th tick rendered into an MP4 with a caption (``Film``).

Order, outermost first: ``Filmed(Assisted(Recovering(env)))``: the assistance acts on the
source's stick before the supervisor's gate, as a person's stick goes through both.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium

from sim.env import ArmSim
from sim.joystick import JoystickState
from sim.render import FrameRenderer, VideoWriter, describe, site_colour
from tasks.operators.assist import Assistance
from tasks.operators.recovery import Supervisor
from tasks.stacking.env import as_state


class _Watching(gymnasium.Wrapper):
    """A wrapper that keeps the last info its env gave (what the person sees before the next tick)."""

    info: Mapping[str, Any] = {}

    def reset(self, *, seed=None, options=None):
        obs, self.info = self.env.reset(seed=seed, options=options)
        return obs, self.info

    def step(self, action):
        obs, reward, terminated, truncated, self.info = self.env.step(self.stick(as_state(action)))
        return obs, reward, terminated, truncated, self.info

    def stick(self, state: JoystickState) -> JoystickState:
        return state


class Assisted(_Watching):
    """The assistance between the source's stick and the arm (it may switch the arm's mode itself)."""

    def __init__(self, env: gymnasium.Env, assistance: Assistance):
        super().__init__(env)
        self.assistance = assistance

    def stick(self, state: JoystickState) -> JoystickState:
        return self.assistance.step(self.info["view"], state, self.env.unwrapped.sim)


class Recovering(gymnasium.ActionWrapper):
    """The supervisor's gate on the stick (its intent side is the source's: ``sources.Operator``)."""

    def __init__(self, env: gymnasium.Env, supervisor: Supervisor):
        super().__init__(env)
        self.supervisor = supervisor

    def action(self, action) -> JoystickState:
        return self.supervisor.gate(as_state(action))


class Film:
    """Every n-th control tick rendered into an MP4, with a caption (time and film speed, mode and
    stick, and the lines ``Filmed`` is given) and a legend of the discs A and B."""

    def __init__(self, sim: ArmSim, path: Path, speedup: float):
        render = sim.config.render
        self.sim, self.speedup = sim, speedup
        self.every = max(1, round(speedup * sim.config.physics.control_hz / render.fps))
        self.renderer = FrameRenderer(sim.model, render.camera, render.width, render.height)
        self.writer = VideoWriter(Path(path), render.fps)
        self.legend = (("A: where the cubes start", site_colour(sim.model, "location_a", "table")),
                       ("B: the target, stack them here", site_colour(sim.model, "location_b", "table")))
        self.ticks = 0

    def tick(self, t: float, command: str, lines: Sequence[str | None]) -> None:
        if self.ticks % self.every == 0:
            caption = (f"{t:6.1f} s (film {self.speedup:g}x)  {command}", *filter(None, lines))
            self.writer.append(self.renderer.render(self.sim.data, caption, self.legend))
        self.ticks += 1

    def close(self) -> None:
        self.writer.close()
        self.renderer.close()


class Filmed(_Watching):
    """The loop filmed (``Film``) after every tick: ``lines(t)`` gives the caption's lines below the
    stick's for the tick that began at task time ``t`` (None: a line left out)."""

    def __init__(self, env: gymnasium.Env, path: Path, speedup: float,
                 lines: Callable[[float], Sequence[str | None]] = lambda t: ()):
        super().__init__(env)
        self.film, self.lines = Film(env.unwrapped.sim, path, speedup), lines

    def step(self, action):
        t = self.info["view"].t
        result = super().step(action)
        sim, info = self.env.unwrapped.sim, result[-1]
        self.film.tick(t, describe(sim.mode, info["state"], sim.layout), self.lines(t))
        return result

    def close(self) -> None:
        self.film.close()
        super().close()
