"""The JACO's joystick: functions with a deflection, two mode buttons, and a *layout* of modes.

Functions F, B, R, L, Rr, Lr each carry a deflection in [0, 1]; several may be held at once (a
3-axis stick combines axes). Buttons B1 and B2 are press events. A ``Layout`` is data: the cycle
of modes and, per mode, what each function does (``Effect``: move the hand along an axis, turn it
about an axis through the tool point, or close/open the fingers); a function absent from a mode
does nothing there. Two layouts, as on the real arm:

``THREE_AXIS`` (the default; Kinova's 3-axis stick), modes translation -> wrist -> fingers:

- translation: F/B/R/L/Rr/Lr move the hand along y-, y+, x-, x+, z+, z- at ``full_speed * deflection``;
- wrist: the same functions turn the hand about the tool point at ``wrist_speed * deflection``
  (F/B tip the fingers toward y-/y+, R/L toward x-/x+, Rr/Lr turn it about z+/z-);
- fingers: F closes, B opens the three fingers; the other functions do nothing.

``TWO_AXIS`` (Kinova's scheme for a 2-axis input: F, B, R, L only), modes translation -> height
-> wrist -> fingers:

- translation: F/B/R/L move the hand in xy as above;
- height: F moves the hand up (z+), B down (z-); R/L turn it about z+/z- (as Rr/Lr in wrist mode);
- wrist: F/B/R/L tip the hand as in the 3-axis wrist mode;
- fingers: F closes, B opens.

``ONE_AXIS`` (for a person with two directions: F and B only; ``bomi.derived``), modes translation
-> sideways -> height -> wrist -> fingers, F/B in each: along y-/y+, x-/x+ (as R/L), up/down, the
turn about z+/z- (as Rr/Lr in the 3-axis wrist mode), close/open.  It cannot tilt the hand.

B1 steps forward through the layout's cycle, B2 backward. Holding no function holds still. An
assistance may also put the arm in a mode directly (``JoystickInterpreter.switch_to``).
"""
from __future__ import annotations

import enum
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from sim.kernels import clip

FUNCTIONS = ("F", "B", "R", "L", "Rr", "Lr")
BUTTONS = ("B1", "B2")
_FUNCTION_SET, _BUTTON_SET = frozenset(FUNCTIONS), frozenset(BUTTONS)


class Mode(enum.Enum):
    TRANSLATION = "translation"
    SIDEWAYS = "sideways"  # the 1-axis layout's moves along x
    HEIGHT = "height"
    WRIST = "wrist"
    FINGERS = "fingers"

    # Members are singletons: hashed by identity in C, not by enum's Python ``__hash__`` (tables keyed
    # by mode are read a dozen times per control tick).  Equality is identity either way.
    __hash__ = object.__hash__


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


class Kind(enum.Enum):
    LINEAR = "move"  # the hand along ``axis`` (world, unit) at full_speed * deflection
    ANGULAR = "turn"  # the hand about ``axis`` (world, unit) through the tool point at wrist_speed * deflection
    FINGERS = "fingers"  # the fingers at the rate ``axis`` * deflection (+1 closes)

    __hash__ = object.__hash__  # as Mode's


@dataclass(frozen=True)
class Effect:
    """What one function does in one mode."""

    kind: Kind
    axis: tuple[float, float, float] | float

    @property
    def label(self) -> str:
        """Short words for captions: "move z+", "turn x-", "close"."""
        if self.kind is Kind.FINGERS:
            return "close" if self.axis > 0 else "open"
        (index,) = np.flatnonzero(self.axis)
        return f"{self.kind.value} {'xyz'[index]}{'+' if self.axis[index] > 0 else '-'}"


@dataclass(frozen=True, eq=False)
class Layout:
    """A joystick layout: the ordered mode cycle and, per mode, function -> effect."""

    name: str
    modes: tuple[Mode, ...]
    effects: Mapping[Mode, Mapping[str, Effect]]
    levels: bool = field(init=False)  # it tilts the hand both ways about x and y (can level it)

    def __post_init__(self):
        if set(self.effects) != set(self.modes) or len(set(self.modes)) != len(self.modes):
            raise ValueError(f"layout {self.name}: every mode of the cycle needs one effect table")
        if any(set(table) - set(FUNCTIONS) for table in self.effects.values()):
            raise ValueError(f"layout {self.name}: effects for unknown functions; expected {FUNCTIONS}")
        # ``axes`` and ``find`` are asked several times per control tick: answered from tables made once
        axes = {(mode, kind): MappingProxyType({fn: effect.axis for fn, effect in self.effects[mode].items()
                                                if effect.kind is kind})
                for mode in self.modes for kind in Kind}
        found: dict[tuple[Kind, tuple[float, float, float] | float], tuple[Mode, str]] = {}
        for mode in self.modes:
            for fn, effect in self.effects[mode].items():
                found.setdefault((effect.kind, effect.axis), (mode, fn))  # the first in the cycle's order
        object.__setattr__(self, "_axes", axes)
        object.__setattr__(self, "_found", found)
        tilts = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0))
        object.__setattr__(self, "levels", all((Kind.ANGULAR, axis) in found for axis in tilts))

    def __reduce__(self):
        """Pickled as its fields (the tables are made again): `bomi live --video` sends the layout to
        the film's own process."""
        return type(self), (self.name, self.modes, self.effects)

    @property
    def functions(self) -> tuple[str, ...]:
        """The functions the layout uses in some mode (the stick directions a user needs)."""
        return tuple(fn for fn in FUNCTIONS if any(fn in table for table in self.effects.values()))

    def after(self, mode: Mode, button: str) -> Mode:
        """The mode one press of ``button`` leads to."""
        return self.modes[(self.modes.index(mode) + BUTTON_STEP[button]) % len(self.modes)]

    def presses(self, current: Mode, wanted: Mode, button: str) -> int:
        """How many presses of ``button`` lead from ``current`` to ``wanted``."""
        forward = self.modes.index(wanted) - self.modes.index(current)
        return (forward * BUTTON_STEP[button]) % len(self.modes)

    def axes(self, mode: Mode, kind: Kind) -> Mapping[str, tuple[float, float, float] | float]:
        """Function -> axis of the functions that have an effect of ``kind`` in ``mode`` (read-only)."""
        return self._axes[mode, kind]

    def find(self, kind: Kind, axis: tuple[float, float, float] | float) -> tuple[Mode, str]:
        """The first mode of the cycle, and the function, whose effect is ``kind`` along ``axis`` (a
        unit axis as the tables give it, or +1/-1 for the fingers)."""
        try:
            return self._found[kind, axis]
        except KeyError:
            raise ValueError(f"layout {self.name} has no function that does {kind.value} along {axis}") from None


def _effects(kind: Kind, axes: Mapping[str, tuple[float, float, float] | float], functions: Iterable[str]
             ) -> dict[str, Effect]:
    return {fn: Effect(kind, axes[fn]) for fn in functions}


_FINGERS = _effects(Kind.FINGERS, FINGER_DIRECTION, FINGER_DIRECTION)
THREE_AXIS = Layout("3-axis", (Mode.TRANSLATION, Mode.WRIST, Mode.FINGERS), {
    Mode.TRANSLATION: _effects(Kind.LINEAR, TRANSLATION_AXES, FUNCTIONS),
    Mode.WRIST: _effects(Kind.ANGULAR, WRIST_AXES, FUNCTIONS),
    Mode.FINGERS: _FINGERS,
})
# Kinova's 2-axis scheme: the vertical moves and the turn about it get a mode of their own, R/L
# turning the way Rr/Lr do in the 3-axis wrist mode.
TWO_AXIS = Layout("2-axis", (Mode.TRANSLATION, Mode.HEIGHT, Mode.WRIST, Mode.FINGERS), {
    Mode.TRANSLATION: _effects(Kind.LINEAR, TRANSLATION_AXES, ("F", "B", "R", "L")),
    Mode.HEIGHT: {"F": Effect(Kind.LINEAR, TRANSLATION_AXES["Rr"]), "B": Effect(Kind.LINEAR, TRANSLATION_AXES["Lr"]),
                  "R": Effect(Kind.ANGULAR, WRIST_AXES["Rr"]), "L": Effect(Kind.ANGULAR, WRIST_AXES["Lr"])},
    Mode.WRIST: _effects(Kind.ANGULAR, WRIST_AXES, ("F", "B", "R", "L")),
    Mode.FINGERS: _FINGERS,
})
# F/B alone: each mode one axis of the 2-axis layout's, F taking R's or Rr's part where it has no F
ONE_AXIS = Layout("1-axis", (Mode.TRANSLATION, Mode.SIDEWAYS, Mode.HEIGHT, Mode.WRIST, Mode.FINGERS), {
    Mode.TRANSLATION: _effects(Kind.LINEAR, TRANSLATION_AXES, ("F", "B")),
    Mode.SIDEWAYS: {"F": Effect(Kind.LINEAR, TRANSLATION_AXES["R"]), "B": Effect(Kind.LINEAR, TRANSLATION_AXES["L"])},
    Mode.HEIGHT: {"F": Effect(Kind.LINEAR, TRANSLATION_AXES["Rr"]), "B": Effect(Kind.LINEAR, TRANSLATION_AXES["Lr"])},
    Mode.WRIST: {"F": Effect(Kind.ANGULAR, WRIST_AXES["Rr"]), "B": Effect(Kind.ANGULAR, WRIST_AXES["Lr"])},
    Mode.FINGERS: _FINGERS,
})
LAYOUTS = {layout.name: layout for layout in (THREE_AXIS, TWO_AXIS, ONE_AXIS)}


@dataclass(frozen=True)
class JoystickState:
    """What the stick reports at one control tick."""

    deflection: dict[str, float] = field(default_factory=dict)
    pressed: frozenset[str] = frozenset()

    def __post_init__(self):
        unknown = self.deflection.keys() - _FUNCTION_SET
        if unknown:
            raise ValueError(f"unknown joystick function(s) {sorted(unknown)}; expected {FUNCTIONS}")
        bad = {k: v for k, v in self.deflection.items() if not 0.0 <= v <= 1.0}
        if bad:
            raise ValueError(f"deflection must be in [0, 1], got {bad}")
        if not _BUTTON_SET.issuperset(self.pressed):
            raise ValueError(f"unknown button(s) {sorted(set(self.pressed) - set(BUTTONS))}; expected {BUTTONS}")
        object.__setattr__(self, "pressed", frozenset(self.pressed))

    @classmethod
    def trusted(cls, deflection: dict[str, float], pressed: frozenset[str] = frozenset()) -> JoystickState:
        """A state from internal code that guarantees what the constructor checks (known functions with
        deflections in [0, 1], known buttons, a frozenset): without the checks, which would otherwise
        run at every control tick of a channel (``tasks.operators.stick.DecisionStick``). Input from a user, a
        file or a planner goes through the constructor."""
        state = object.__new__(cls)
        object.__setattr__(state, "deflection", deflection)
        object.__setattr__(state, "pressed", pressed)
        return state


@dataclass(frozen=True)
class ArmCommand:
    """What the arm does for one tick: a tool twist (world axes) and a finger rate in [-1, 1]."""

    linear: np.ndarray
    angular: np.ndarray
    finger: float


def combined(deflection: Mapping[str, float], axes: Mapping[str, tuple[float, float, float]]
             ) -> tuple[float, float, float]:
    """Sum of each held function's axis weighted by its deflection, as Python floats (the same
    products and sums, in the same order, as on arrays of three, at a fraction of the cost)."""
    x = y = z = 0.0
    for name, amount in deflection.items():
        if name in axes:
            ax, ay, az = axes[name]
            x, y, z = x + amount * ax, y + amount * ay, z + amount * az
    return x, y, z


def combine(deflection: Mapping[str, float], axes: Mapping[str, tuple[float, float, float]]) -> np.ndarray:
    """``combined`` as an array (3,)."""
    return np.array(combined(deflection, axes))


class JoystickInterpreter:
    """The arm's mode logic: buttons step through the layout's modes; functions do what the mode says."""

    def __init__(self, full_speed: float, wrist_speed: float, layout: Layout = THREE_AXIS):
        self.full_speed = full_speed
        self.wrist_speed = wrist_speed
        self.layout = layout
        self.reset()

    def reset(self) -> None:
        self.mode = self.layout.modes[0]
        self.mode_switches = 0
        self.button_presses = 0
        self.automatic_switches = 0

    def switch_to(self, mode: Mode) -> None:
        """Put the arm in ``mode`` without a button (an assistance's switch; counted apart from the buttons')."""
        if mode not in self.layout.modes:
            raise ValueError(f"layout {self.layout.name} has no {mode.value} mode")
        self.automatic_switches += mode is not self.mode
        self.mode = mode

    def update(self, state: JoystickState) -> ArmCommand:
        """Apply this tick's button presses (B1 then B2), then read the functions in the new mode."""
        if state.pressed:
            before = self.mode
            for button in BUTTONS:
                if button in state.pressed:
                    self.button_presses += 1
                    self.mode = self.layout.after(self.mode, button)
            self.mode_switches += self.mode is not before
        fingers = self.layout.axes(self.mode, Kind.FINGERS)
        finger = 0
        for name, amount in state.deflection.items():  # sum() of the products, in the same order
            if name in fingers:
                finger = finger + fingers[name] * amount
        # full_speed x the sum (x, y, z), on floats: the same products as the scalar times the array
        speed, turn = self.full_speed, self.wrist_speed
        x, y, z = combined(state.deflection, self.layout.axes(self.mode, Kind.LINEAR))
        rx, ry, rz = combined(state.deflection, self.layout.axes(self.mode, Kind.ANGULAR))
        return ArmCommand(np.array([speed * x, speed * y, speed * z]), np.array([turn * rx, turn * ry, turn * rz]),
                          float(clip(finger, -1.0, 1.0)))


def script_states(script: Iterable[tuple[float, JoystickState]], control_hz: float) -> Iterator[JoystickState]:
    """One state per control tick from (seconds, state) segments; buttons press at a segment's first tick."""
    for seconds, state in script:
        for tick in range(round(seconds * control_hz)):
            yield state if tick == 0 else JoystickState(state.deflection)
