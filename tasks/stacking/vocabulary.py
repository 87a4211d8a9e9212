"""The stacking task's vocabulary: what the person sees (``View``), wants (``Goal``, ``StickIntent``)
and has (``Controls``), and the recovery actions an episode's record names.  The task, the
operators, the participants and the loop all speak it; it imports nothing from them."""
from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field, fields

import numpy as np

from sim.joystick import BUTTONS, THREE_AXIS, Layout, Mode

@dataclass(frozen=True, eq=False)
class View:
    """What the person sees at one moment (built by the task from the simulation).  Two views are
    equal when every field is (arrays element for element)."""

    t: float
    hand_pos: np.ndarray  # (3,) pinch point, world frame, m
    hand_yaw: float  # rad, heading of the hand about the vertical
    hand_tilt: np.ndarray  # (2,) rad: rotation about world x and y that would point the hand straight down
    closure: float  # fingers, 0 open .. 1 closed
    mode: Mode  # the arm's current joystick mode
    cube_pos: tuple[np.ndarray, ...]  # (3,) centre of each cube
    cube_yaw: tuple[float, ...]
    touching: tuple[bool, ...]  # the fingers touch cube k
    target_xy: np.ndarray  # (2,) location B
    table_z: float  # table top height
    cube_size: float

    def __eq__(self, other: object) -> bool:
        if type(other) is not View:
            return NotImplemented
        return all(_same(getattr(self, f.name), getattr(other, f.name)) for f in fields(View))

    __hash__ = None  # arrays inside: not hashable


def _same(a: object, b: object) -> bool:
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(a, b))
    return bool(a == b)


class Phase(enum.Enum):
    """The stage of a move toward a point (``_approach``), or the rise before a wrist turn."""

    RISE = "rise"
    TRAVEL = "travel"
    DESCEND = "descend"
    RISE_TO_TURN = "rise to turn"

    __hash__ = object.__hash__  # members are singletons: hashed by identity in C (sim.joystick.Mode's)


@dataclass(frozen=True)
class Goal:
    """What the person is after: a step of the task (plain words, e.g. "reach cube 1"), the stage of
    its approach, and the mode a button press is meant to reach first.  ``str`` gives the words
    logs, captions and figures show ("reach cube 1: descend: height mode")."""

    step: str = "rest"
    phase: Phase | None = None
    mode: Mode | None = None  # the press of a mode button this goal waits for

    def __str__(self) -> str:
        parts = [self.step, *(() if self.phase is None else (self.phase.value,)),
                 *(() if self.mode is None else (f"{self.mode.value} mode",))]
        return ": ".join(parts)

    @property
    def descending(self) -> bool:
        """The hand is being taken down onto its goal (not a press on the way there)."""
        return self.phase is Phase.DESCEND and self.mode is None


@dataclass(frozen=True)
class StickIntent:
    """What the person wants from the stick now: functions with deflections, or one button."""

    deflection: Mapping[str, float] = field(default_factory=dict)
    button: str | None = None
    goal: Goal = Goal()
    remaining: float = 0.0  # m: a move of the hand: how far its goal still is along the pushed axes, as judged

    @property
    def functions(self) -> frozenset[str]:
        return frozenset(self.deflection)

    @property
    def is_rest(self) -> bool:
        return not self.deflection and self.button is None


REST = StickIntent()


NO_BUTTON = "no button"  # what a results row says of controls without a mode button


@dataclass(frozen=True)
class Controls:
    """The controls the person has and knows: the arm's joystick layout (which mode moves, turns or
    grips along which axis, with which function) and the mode buttons they can press.  No button:
    the modes change only by the automatic mode switching (the person rests and waits for it)."""

    layout: Layout = THREE_AXIS
    buttons: tuple[str, ...] = BUTTONS

    def __post_init__(self):
        if not set(self.buttons) <= set(BUTTONS):
            raise ValueError(f"controls' buttons must be among {BUTTONS}, got {self.buttons}")

    @property
    def label(self) -> str:
        """What a results row says of the controls, e.g. "2-axis, B1" or "2-axis, no button"."""
        return f"{self.layout.name}, {'+'.join(self.buttons) or NO_BUTTON}"



class RecoveryAction(str, enum.Enum):
    """What the person (or whoever runs the session) does after a while without progress
    (``tasks.operators.recovery``; docs/task.md, "Recovery")."""

    REZERO = "rezero"  # hold still while the chain takes the neutral posture anew
    BACKOFF = "backoff"  # lift the hand and make the plan afresh
    PAUSE = "pause"  # stop the arm and rest
    RECALIBRATE = "recalibrate"  # a short calibration session and a retrain of the classifier


NO_RECOVERY = "none"


@dataclass(frozen=True)
class RecoveryEvent:
    """One recovery action (``tasks.operators.recovery``): which, and when (task time, s; a backoff
    lasts until its lift is done, which the log's goals show: its event has start == end)."""

    action: RecoveryAction
    start_s: float
    end_s: float
    obeyed: float | None = None  # the share of the stick moves asked that the arm answered before it (None: none asked)
