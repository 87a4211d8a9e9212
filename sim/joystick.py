"""The JACO's 3-axis joystick: functions with a deflection, two mode buttons, three modes.

Functions F, B, R, L, Rr, Lr each carry a deflection in [0, 1]; several may be held at once (a
3-axis stick combines axes). Buttons B1 and B2 are press events. Modes, as on the real arm:

- translation: F/B/R/L/Rr/Lr move the hand along y-, y+, x-, x+, z+, z- at ``full_speed * deflection``;
- wrist: the same functions turn the hand about the tool point at ``wrist_speed * deflection``
  (F/B tip the fingers toward y-/y+, R/L toward x-/x+, Rr/Lr turn it about z+/z-);
- fingers: F closes, B opens the three fingers; the other functions do nothing.

B1 cycles translation -> wrist -> fingers -> translation; B2 cycles the other way. Holding no
function holds still.
"""
from __future__ import annotations

import enum
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

FUNCTIONS = ("F", "B", "R", "L", "Rr", "Lr")
BUTTONS = ("B1", "B2")


class Mode(enum.Enum):
    TRANSLATION = "translation"
    WRIST = "wrist"
    FINGERS = "fingers"


MODE_CYCLE = (Mode.TRANSLATION, Mode.WRIST, Mode.FINGERS)
BUTTON_STEP = {"B1": 1, "B2": -1}

TRANSLATION_AXES = {
    "F": (0.0, -1.0, 0.0), "B": (0.0, 1.0, 0.0),
    "R": (-1.0, 0.0, 0.0), "L": (1.0, 0.0, 0.0),
    "Rr": (0.0, 0.0, 1.0), "Lr": (0.0, 0.0, -1.0),
}
# Rotation axes chosen so that, with the hand pointing down, F tips the fingers toward y- (where F
# translates), R toward x-, and Rr/Lr turn the hand about the vertical.
WRIST_AXES = {
    "F": (-1.0, 0.0, 0.0), "B": (1.0, 0.0, 0.0),
    "R": (0.0, 1.0, 0.0), "L": (0.0, -1.0, 0.0),
    "Rr": (0.0, 0.0, 1.0), "Lr": (0.0, 0.0, -1.0),
}
FINGER_DIRECTION = {"F": 1.0, "B": -1.0}  # +1 closes


@dataclass(frozen=True)
class JoystickState:
    """What the stick reports at one control tick."""

    deflection: dict[str, float] = field(default_factory=dict)
    pressed: frozenset[str] = frozenset()

    def __post_init__(self):
        unknown = set(self.deflection) - set(FUNCTIONS)
        if unknown:
            raise ValueError(f"unknown joystick function(s) {sorted(unknown)}; expected {FUNCTIONS}")
        bad = {k: v for k, v in self.deflection.items() if not 0.0 <= v <= 1.0}
        if bad:
            raise ValueError(f"deflection must be in [0, 1], got {bad}")
        if not set(self.pressed) <= set(BUTTONS):
            raise ValueError(f"unknown button(s) {sorted(set(self.pressed) - set(BUTTONS))}; expected {BUTTONS}")
        object.__setattr__(self, "pressed", frozenset(self.pressed))


@dataclass(frozen=True)
class ArmCommand:
    """What the arm does for one tick: a tool twist (world axes) and a finger rate in [-1, 1]."""

    linear: np.ndarray
    angular: np.ndarray
    finger: float


def combine(deflection: dict[str, float], axes: dict[str, tuple[float, float, float]]) -> np.ndarray:
    """Sum of each held function's axis weighted by its deflection."""
    total = np.zeros(3)
    for name, amount in deflection.items():
        if name in axes:
            total += amount * np.asarray(axes[name])
    return total


class JoystickInterpreter:
    """The arm's mode logic: buttons cycle modes; functions mean what the current mode says."""

    def __init__(self, full_speed: float, wrist_speed: float):
        self.full_speed = full_speed
        self.wrist_speed = wrist_speed
        self.reset()

    def reset(self) -> None:
        self.mode = Mode.TRANSLATION
        self.mode_switches = 0
        self.button_presses = 0

    def update(self, state: JoystickState) -> ArmCommand:
        """Apply this tick's button presses (B1 then B2), then read the functions in the new mode."""
        before = self.mode
        for button in BUTTONS:
            if button in state.pressed:
                self.button_presses += 1
                index = (MODE_CYCLE.index(self.mode) + BUTTON_STEP[button]) % len(MODE_CYCLE)
                self.mode = MODE_CYCLE[index]
        self.mode_switches += self.mode is not before
        zero = np.zeros(3)
        if self.mode is Mode.TRANSLATION:
            return ArmCommand(self.full_speed * combine(state.deflection, TRANSLATION_AXES), zero, 0.0)
        if self.mode is Mode.WRIST:
            return ArmCommand(zero, self.wrist_speed * combine(state.deflection, WRIST_AXES), 0.0)
        finger = sum(FINGER_DIRECTION.get(name, 0.0) * amount for name, amount in state.deflection.items())
        return ArmCommand(zero, zero, float(np.clip(finger, -1.0, 1.0)))


def script_states(script: Iterable[tuple[float, JoystickState]], control_hz: float) -> Iterator[JoystickState]:
    """One state per control tick from (seconds, state) segments; buttons press at a segment's first tick."""
    for seconds, state in script:
        for tick in range(round(seconds * control_hz)):
            yield state if tick == 0 else JoystickState(state.deflection)
