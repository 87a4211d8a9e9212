"""Classifier decisions -> joystick state: the one mapping the simulated and the live BoMI share."""
from __future__ import annotations

from collections.abc import Iterable

from bomi.chain import Decision
from bomi.profiles import NEUTRAL_FUNCTION
from sim.joystick import BUTTONS, FUNCTIONS, JoystickState


def rising_edge(button: str | None, previous: str | None) -> frozenset[str]:
    """A button counts as pressed only on the tick it goes down."""
    return frozenset({button}) if button is not None and button != previous else frozenset()


class DecisionStick:
    """Decisions -> the stick: the latest decision's function deflected by its nu (held until the
    next decision); a B1/B2 class presses its button on its rising edge."""

    def __init__(self) -> None:
        self.release()

    def release(self) -> None:
        """Forget the last decision: the stick is centred until a new one comes."""
        self.function, self.nu = NEUTRAL_FUNCTION, 0.0

    def update(self, decisions: Iterable[Decision]) -> JoystickState:
        pressed: set[str] = set()
        for decision in decisions:
            pressed |= rising_edge(decision.function if decision.function in BUTTONS else None, self.function)
            self.function, self.nu = decision.function, decision.nu
        if self.function in FUNCTIONS and self.nu > 0:
            return JoystickState({self.function: min(1.0, self.nu)}, frozenset(pressed))
        return JoystickState(pressed=frozenset(pressed))
