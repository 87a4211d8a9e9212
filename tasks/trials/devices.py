"""The joystick condition's input devices (``session.StickDevice``): a gamepad through pygame's
joystick API (the optional extra ``bomi-jaco[gamepad]``), or the keys of MuJoCo's viewer.

Gamepad: left stick x -> R/L, left stick y -> F (up) / B, right stick x -> Rr/Lr (the JACO's
3-axis stick: its twist), button 0 -> B1, button 1 -> B2 (pressed on the rising edge); a dead
zone of ``DEAD_ZONE`` around the centre. A gamepad unplugged mid-session stops the session
(``DeviceLost``): the running trial is cut short and everything so far is kept.

Keyboard (viewer window): arrows -> F/B/L/R, Q/E -> Lr/Rr, 1/2 -> B1/B2. The viewer reports key
presses only, so a key press holds its function at full deflection for ``KEY_HOLD_S``; the key's
auto-repeat keeps it held.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

from bomi.errors import BomiError
from sim.joystick import JoystickState
from tasks.operators.stick import rising_edge

DEAD_ZONE = 0.15
KEY_HOLD_S = 0.25
AXES = ((0, "R", "L"), (1, "B", "F"), (2, "Rr", "Lr"))  # (axis, function at +1, function at -1)
GAMEPAD_BUTTONS = ((0, "B1"), (1, "B2"))
GAMEPAD_HELP = "pip install 'bomi-jaco[gamepad]'"


class DeviceLost(BomiError):
    """The input device went away mid-session."""


def deflections(values: dict[int, float], dead_zone: float = DEAD_ZONE) -> dict[str, float]:
    """Axis values in [-1, 1] -> the stick's functions and deflections, outside the dead zone rescaled to [0, 1]."""
    out = {}
    for axis, positive, negative in AXES:
        value = values.get(axis, 0.0)
        if abs(value) > dead_zone:
            out[positive if value > 0 else negative] = min(1.0, (abs(value) - dead_zone) / (1.0 - dead_zone))
    return out


@dataclass
class Gamepad:
    """Gamepad ``index`` (pygame's numbering). Refuses a device with too few axes or buttons."""

    index: int = 0
    _pad: object = field(default=None, init=False, repr=False)
    _button: str | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # events need the video subsystem, not a window
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        try:
            import pygame
        except ImportError:
            raise BomiError(f"--gamepad: the gamepad needs pygame ({GAMEPAD_HELP})") from None
        self._pygame = pygame
        pygame.display.init()  # only what the joystick API needs (no audio)
        pygame.joystick.init()
        count = pygame.joystick.get_count()
        if not 0 <= self.index < count:
            raise BomiError(f"--gamepad {self.index}: no such gamepad ({count} found)")
        pad = pygame.joystick.Joystick(self.index)
        axes, buttons = pad.get_numaxes(), pad.get_numbuttons()
        if axes < len(AXES) or buttons < len(GAMEPAD_BUTTONS):
            name = pad.get_name()
            raise BomiError(f"--gamepad {self.index}: {name!r} has {axes} axes and {buttons} buttons; a gamepad for "
                            f"the JACO stick needs {len(AXES)} axes and {len(GAMEPAD_BUTTONS)} buttons")
        self._pad, self.name = pad, pad.get_name()

    def read(self, now: float) -> JoystickState:
        pygame = self._pygame
        for event in pygame.event.get():
            if event.type == pygame.JOYDEVICEREMOVED and event.instance_id == self._pad.get_instance_id():
                raise DeviceLost(f"--gamepad {self.index}: {self.name!r} was unplugged")
        pad = self._pad
        values = {axis: float(pad.get_axis(axis)) for axis, _, _ in AXES}
        held = next((name for button, name in GAMEPAD_BUTTONS if pad.get_button(button)), None)
        pressed = rising_edge(held, self._button)
        self._button = held
        return JoystickState(deflections(values), pressed)

    def close(self) -> None:
        self._pygame.quit()


GLFW_KEYS = {265: "F", 264: "B", 263: "L", 262: "R", 81: "Lr", 69: "Rr", 49: "B1", 50: "B2"}


@dataclass
class ViewerKeys:
    """The viewer's keys as a stick: ``key`` is the viewer's key callback (GLFW key codes)."""

    clock: object = None  # the session's clock
    _held: dict[str, float] = field(default_factory=dict)  # function -> held until
    _presses: set[str] = field(default_factory=set)

    def key(self, keycode: int) -> None:
        function = GLFW_KEYS.get(keycode)
        if function in ("B1", "B2"):
            self._presses.add(function)
        elif function is not None:
            self._held[function] = self.clock() + KEY_HOLD_S

    def read(self, now: float) -> JoystickState:
        held = {f: 1.0 for f, until in self._held.items() if until > now}
        pressed, self._presses = frozenset(self._presses), set()
        return JoystickState(held, pressed)

    def close(self) -> None:
        """Nothing to release."""
