"""Drive the arm through each joystick function and mode and measure what it achieves.

Used by ``bomi sim-check``. Every run starts from the home pose,
reaches the mode with the real B1 presses, holds one function for a while and measures the
steady part (after ``settle`` seconds). ``verdict`` says whether a function reaches its commanded
speed, and if not whether a joint speed limit is the cause.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from sim.env import ArmSim
from sim.joystick import JoystickState, Kind, Mode


# A function reaches its commanded speed when achieved / commanded is within this of 1.
SPEED_TOLERANCE = 0.05
# A joint commanded at this share of its speed limit (or more) is at the limit: the controller
# scales the whole joint-velocity vector down so that none exceeds its limit.
AT_LIMIT = 0.99


@dataclass(frozen=True)
class DirectionResult:
    mode: str
    function: str
    commanded: float      # m/s (translation), rad/s (wrist), closure fraction/s (fingers)
    achieved: float       # same unit, along the commanded axis, steady part
    tracking_error: float  # translation: max distance from the commanded line (m); wrist: tool-point drift (m)
    speed_use: float = 0.0  # steady part: the largest share of a joint's speed limit that the arm was commanded
    busiest_joint: int = 0  # the arm joint (1..6) with that share

    @property
    def ratio(self) -> float:
        return self.achieved / self.commanded if self.commanded else float("nan")


def verdict(result: DirectionResult) -> str:
    """"ok" when the function reaches its commanded speed; else why not, as far as the arm tells."""
    if abs(result.ratio - 1.0) <= SPEED_TOLERANCE:
        return "ok"
    if result.ratio < 1.0 and result.speed_use >= AT_LIMIT:
        return f"capped: joint {result.busiest_joint} at its speed limit"
    return "too slow" if result.ratio < 1.0 else "too fast"


def enter_mode(sim: ArmSim, mode: Mode) -> None:
    """Press B1 until the arm is in ``mode`` (one press per tick, as a person would)."""
    while sim.mode is not mode:
        sim.step(JoystickState(pressed=frozenset({"B1"})))


def hold(sim: ArmSim, state: JoystickState, seconds: float
         ) -> list[tuple[float, np.ndarray, np.ndarray, float, np.ndarray]]:
    """Hold a stick state; return (time, tool position, tool rotation, finger closure, share of each
    arm joint's speed limit commanded) per tick."""
    samples = []
    for _ in range(round(seconds / sim.dt)):
        sim.step(state)
        speed_use = np.abs(sim.data.ctrl[sim.scene.arm_actuators]) / sim.limits.speed
        samples.append((sim.time, sim.tool_position, sim.tool_rotation, sim.finger_closure, speed_use))
    return samples


def measure(sim: ArmSim, mode: Mode, function: str, deflection: float = 1.0,
            seconds: float = 1.0, settle: float = 0.25) -> DirectionResult:
    """Hold ``function`` at ``deflection`` in ``mode`` (of the sim's joystick layout) from the home pose
    and measure the motion."""
    effect = sim.joystick.layout.effects[mode].get(function)
    sim.reset()
    enter_mode(sim, mode)
    sign = effect.axis if effect is not None and effect.kind is Kind.FINGERS else 0.0
    if sign < 0:
        hold(sim, JoystickState({"F": 1.0}), 1.5)  # close first, so that opening can be measured
    start_position = sim.tool_position
    samples = hold(sim, JoystickState({function: deflection}), seconds)
    steady = [s for s in samples if s[0] - samples[0][0] >= settle - 1e-9]
    (t0, p0, r0, c0, _), (t1, p1, r1, c1, _) = steady[0], steady[-1]
    use = np.max([s[4] for s in steady], axis=0)
    joint_use = {"speed_use": float(use.max()), "busiest_joint": int(use.argmax()) + 1}
    if effect is not None and effect.kind is Kind.LINEAR:
        axis = np.asarray(effect.axis)
        offsets = np.array([s[1] - start_position for s in samples])
        off_line = offsets - np.outer(offsets @ axis, axis)
        return DirectionResult(mode.value, function, sim.config.control.full_speed * deflection,
                               float((p1 - p0) @ axis / (t1 - t0)), float(np.linalg.norm(off_line, axis=1).max()),
                               **joint_use)
    if effect is not None and effect.kind is Kind.ANGULAR:
        axis = np.asarray(effect.axis)
        turned = pin.log3(r1 @ r0.T) @ axis
        drift = max(np.linalg.norm(s[1] - start_position) for s in samples)
        return DirectionResult(mode.value, function, sim.config.control.wrist_speed * deflection,
                               float(turned / (t1 - t0)), float(drift), **joint_use)
    finger_range = np.mean(np.diff(sim.scene.finger_range, axis=1))
    rate = sign * deflection * sim.config.control.finger_speed / finger_range
    return DirectionResult(mode.value, function, float(rate), float((c1 - c0) / (t1 - t0)), float("nan"))


def check_all(sim: ArmSim, deflection: float = 1.0, seconds: float = 1.0) -> list[DirectionResult]:
    """Every function that does something, mode by mode in the order of the sim's joystick layout."""
    layout = sim.joystick.layout
    return [measure(sim, mode, function, deflection, seconds)
            for mode in layout.modes for function in layout.effects[mode]]
