"""Joystick layouts: the 3-axis one as it always was, Kinova's 2-axis scheme, and the arm under it."""
import sim  # noqa: F401  -- first: sim/__init__ selects headless EGL before mujoco loads

import numpy as np
import pytest

from sim.check import measure
from sim.env import ArmSim
from sim.joystick import (FINGER_DIRECTION, FUNCTIONS, LAYOUTS, THREE_AXIS, TRANSLATION_AXES, TWO_AXIS, WRIST_AXES,
                          JoystickInterpreter, JoystickState, Kind, Layout, Mode)
from sim.render import describe

B1 = JoystickState(pressed=frozenset({"B1"}))
B2 = JoystickState(pressed=frozenset({"B2"}))


def two_axis_stick() -> JoystickInterpreter:
    return JoystickInterpreter(full_speed=0.2, wrist_speed=0.6, layout=TWO_AXIS)


def test_three_axis_is_the_default_and_its_tables_are_the_papers():
    assert JoystickInterpreter(0.2, 0.6).layout is THREE_AXIS and LAYOUTS["3-axis"] is THREE_AXIS
    assert THREE_AXIS.modes == (Mode.TRANSLATION, Mode.WRIST, Mode.FINGERS)
    assert THREE_AXIS.axes(Mode.TRANSLATION, Kind.LINEAR) == TRANSLATION_AXES
    assert THREE_AXIS.axes(Mode.WRIST, Kind.ANGULAR) == WRIST_AXES
    assert THREE_AXIS.axes(Mode.FINGERS, Kind.FINGERS) == FINGER_DIRECTION
    assert THREE_AXIS.functions == FUNCTIONS


def test_two_axis_needs_four_directions():
    assert TWO_AXIS.functions == ("F", "B", "R", "L") and LAYOUTS["2-axis"] is TWO_AXIS


def test_two_axis_b1_steps_forward_through_four_modes_and_b2_back():
    stick = two_axis_stick()
    forward = [stick.mode] + [(stick.update(B1), stick.mode)[1] for _ in range(4)]
    assert forward == [Mode.TRANSLATION, Mode.HEIGHT, Mode.WRIST, Mode.FINGERS, Mode.TRANSLATION]
    backward = [(stick.update(B2), stick.mode)[1] for _ in range(4)]
    assert backward == [Mode.FINGERS, Mode.WRIST, Mode.HEIGHT, Mode.TRANSLATION]
    assert (stick.button_presses, stick.mode_switches) == (8, 8)


@pytest.mark.parametrize("presses, function, linear, angular, finger", [
    (0, "F", (0, -0.1, 0), (0, 0, 0), 0), (0, "B", (0, 0.1, 0), (0, 0, 0), 0),
    (0, "R", (-0.1, 0, 0), (0, 0, 0), 0), (0, "L", (0.1, 0, 0), (0, 0, 0), 0),
    (1, "F", (0, 0, 0.1), (0, 0, 0), 0), (1, "B", (0, 0, -0.1), (0, 0, 0), 0),  # height: up, down
    (1, "R", (0, 0, 0), (0, 0, 0.3), 0), (1, "L", (0, 0, 0), (0, 0, -0.3), 0),  # and turns as Rr/Lr do in wrist
    (2, "F", (0, 0, 0), (-0.3, 0, 0), 0), (2, "B", (0, 0, 0), (0.3, 0, 0), 0),
    (2, "R", (0, 0, 0), (0, 0.3, 0), 0), (2, "L", (0, 0, 0), (0, -0.3, 0), 0),
    (3, "F", (0, 0, 0), (0, 0, 0), 0.5), (3, "B", (0, 0, 0), (0, 0, 0), -0.5),
    (3, "R", (0, 0, 0), (0, 0, 0), 0), (0, "Rr", (0, 0, 0), (0, 0, 0), 0),  # nothing
])
def test_two_axis_function_effects_per_mode(presses, function, linear, angular, finger):
    stick = two_axis_stick()
    for _ in range(presses):
        stick.update(B1)
    command = stick.update(JoystickState({function: 0.5}))
    np.testing.assert_allclose(command.linear, linear, atol=1e-15)
    np.testing.assert_allclose(command.angular, angular, atol=1e-15)
    assert command.finger == pytest.approx(finger)


def test_height_mode_turns_like_the_three_axis_wrist_rr_lr():
    height = TWO_AXIS.effects[Mode.HEIGHT]
    assert (height["R"].axis, height["L"].axis) == (WRIST_AXES["Rr"], WRIST_AXES["Lr"])


def test_layout_finds_the_first_mode_that_does_something():
    assert TWO_AXIS.find(Kind.LINEAR, (0.0, 0.0, -1.0)) == (Mode.HEIGHT, "B")
    assert TWO_AXIS.find(Kind.ANGULAR, (0.0, 0.0, 1.0)) == (Mode.HEIGHT, "R")
    assert TWO_AXIS.find(Kind.ANGULAR, (0.0, 1.0, 0.0)) == (Mode.WRIST, "R")
    assert THREE_AXIS.find(Kind.LINEAR, (0.0, 0.0, -1.0)) == (Mode.TRANSLATION, "Lr")
    assert TWO_AXIS.presses(Mode.TRANSLATION, Mode.FINGERS, "B1") == 3
    assert TWO_AXIS.presses(Mode.TRANSLATION, Mode.FINGERS, "B2") == 1
    with pytest.raises(ValueError):
        Layout("broken", (Mode.TRANSLATION, Mode.FINGERS), {Mode.TRANSLATION: {}})


def test_caption_says_what_the_held_function_does_in_the_layout():
    assert "F=0.50 (move z+)" in describe(Mode.HEIGHT, JoystickState({"F": 0.5}), TWO_AXIS)
    assert "F=0.50 (move y-)" in describe(Mode.TRANSLATION, JoystickState({"F": 0.5}))
    assert "R=1.00 (nothing)" in describe(Mode.FINGERS, JoystickState({"R": 1.0}), TWO_AXIS)


@pytest.fixture(scope="module")
def arm():
    arm = ArmSim(layout=TWO_AXIS)
    yield arm
    arm.close()


def hand_yaw(arm: ArmSim) -> float:
    rotation = arm.tool_rotation
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


@pytest.mark.parametrize("function, up", [("F", 1), ("B", -1)])
def test_two_axis_height_mode_moves_the_real_hand_up_and_down(arm, function, up):
    home_z = arm.config.arm.home_tool_pos[2]
    result = measure(arm, Mode.HEIGHT, function, deflection=0.5, seconds=1.25, settle=0.25)
    assert arm.mode is Mode.HEIGHT
    assert abs(result.achieved / 0.1 - 1) < 0.05, result
    assert result.tracking_error < 0.005, result
    assert up * (arm.tool_position[2] - home_z) == pytest.approx(0.1 * 1.25, rel=0.15)


@pytest.mark.parametrize("function, turn", [("R", 1), ("L", -1)])
def test_two_axis_height_mode_turns_the_real_hand_about_the_vertical(arm, function, turn):
    arm.reset()
    home_yaw = hand_yaw(arm)
    result = measure(arm, Mode.HEIGHT, function, deflection=0.5, seconds=1.0, settle=0.25)
    assert abs(result.achieved / result.commanded - 1) < 0.05, result
    assert result.tracking_error < 0.005, result  # the tool point stays put
    turned = (hand_yaw(arm) - home_yaw + np.pi) % (2 * np.pi) - np.pi
    assert turn * turned == pytest.approx(0.3 * 1.0, rel=0.15)  # counter-clockwise seen from above for R


def test_two_axis_translation_mode_moves_the_real_hand_in_xy_only(arm):
    home = np.array(arm.config.arm.home_tool_pos)
    result = measure(arm, Mode.TRANSLATION, "L", deflection=0.5, seconds=1.25, settle=0.25)
    assert abs(result.achieved / 0.1 - 1) < 0.05 and result.tracking_error < 0.005, result
    moved = arm.tool_position - home
    assert moved[0] == pytest.approx(0.125, rel=0.15) and abs(moved[2]) < 0.005
