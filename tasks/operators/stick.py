"""Classifier decisions -> joystick state: the one mapping the simulated and the live BoMI share.

The joystick's vocabulary (function and button names, layouts) is the arm's, defined once in
sim/joystick.py; a profile names those functions and bomi/ passes them through as opaque names,
so a profile meant for the arm is checked against the arm's vocabulary here (``arm_profile``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from bomi.chain import Decision
from bomi.errors import BomiError
from bomi.gate import ButtonEvidence
from bomi.profiles import NEUTRAL_FUNCTION, Profile, load_profile
from sim.joystick import BUTTONS, FUNCTIONS, LAYOUTS, THREE_AXIS, JoystickState, Layout


def arm_profile(path_or_name: str | Path, overrides: Mapping[str, Any] | None = None) -> Profile:
    """``bomi.profiles.load_profile``, then: every class drives a function of the JACO's stick and
    the layout is one of the arm's. A failure is one line naming the file."""
    profile = load_profile(path_or_name, overrides)
    functions = (*FUNCTIONS, *BUTTONS)
    for cls in profile.classes:
        if cls.function not in (*functions, NEUTRAL_FUNCTION):
            raise BomiError(f"{profile.source}: class c{cls.label} ({cls.name}): function must be one of "
                            f"{', '.join(functions)} or \"{NEUTRAL_FUNCTION}\", got {cls.function!r}")
    if profile.joystick_layout is not None and profile.joystick_layout not in LAYOUTS:
        raise BomiError(f"{profile.source}: joystick: layout must be one of {', '.join(map(repr, LAYOUTS))}, "
                        f"got {profile.joystick_layout!r}")
    return profile


def profile_layout(profile: Profile) -> Layout:
    """The arm's joystick layout a profile's classes drive (the 3-axis stick unless it names another)."""
    return THREE_AXIS if profile.joystick_layout is None else LAYOUTS[profile.joystick_layout]


_NOTHING: frozenset[str] = frozenset()


def rising_edge(button: str | None, previous: str | None) -> frozenset[str]:
    """A button counts as pressed only on the tick it goes down."""
    return frozenset({button}) if button is not None and button != previous else frozenset()


class DecisionStick:
    """Decisions -> the stick: the latest decision's function deflected by its nu (held until the
    next decision); a B1/B2 class presses its button on its rising edge once decided for the
    profile's ``button_hold_s`` without a break (``bomi.gate.ButtonEvidence``: a shorter run, e.g. a
    misread on the way to another motion, centres the stick), simulated and live alike."""

    def __init__(self, profile: Profile) -> None:
        self._evidence = ButtonEvidence.held_for(profile.button_hold_s, BUTTONS)
        self.release()

    def release(self) -> None:
        """Forget the last decision and any button evidence: the stick is centred until a new one comes."""
        self.function, self.nu = NEUTRAL_FUNCTION, 0.0
        self._evidence.reset()

    def update(self, decisions: Sequence[Decision]) -> JoystickState:
        pressed = _NOTHING
        for decision, admitted in zip(decisions, self._evidence.admit(d.function for d in decisions)):
            function, nu = (decision.function, decision.nu) if admitted else (NEUTRAL_FUNCTION, 0.0)
            if function in BUTTONS:
                pressed = pressed | rising_edge(function, self.function)
            self.function, self.nu = function, nu
        # a function of the stick with nu in (0, 1], buttons among BUTTONS: what the constructor checks holds
        if self.function in FUNCTIONS and self.nu > 0:
            return JoystickState.trusted({self.function: min(1.0, self.nu)}, pressed)
        return JoystickState.trusted({}, pressed)
