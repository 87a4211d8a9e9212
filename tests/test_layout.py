"""Joystick layouts: the 3-axis one as it always was, Kinova's 2-axis scheme, the 1-axis one (F/B
alone), and the arm under them."""
import sim  # noqa: F401  -- first: sim/__init__ selects headless EGL before mujoco loads

import numpy as np
import pytest

from sim.check import measure
from sim.env import ArmSim
from sim.joystick import (FUNCTIONS, LAYOUTS, ONE_AXIS, THREE_AXIS, TWO_AXIS,
                          JoystickInterpreter, JoystickState, Kind, Layout, Mode)
from sim.render import describe

B1 = JoystickState(pressed=frozenset({"B1"}))
B2 = JoystickState(pressed=frozenset({"B2"}))


def two_axis_stick() -> JoystickInterpreter:
    return JoystickInterpreter(full_speed=0.2, wrist_speed=0.6, layout=TWO_AXIS)


def command_after(layout, presses: int, function: str, deflection: float = 0.5):
    """What a stick of ``layout`` commands for ``function`` after ``presses`` presses of B1."""
    stick = JoystickInterpreter(full_speed=0.2, wrist_speed=0.6, layout=layout)
    for _ in range(presses):
        stick.update(B1)
    return stick.update(JoystickState({function: deflection}))


def test_three_axis_is_the_default_and_each_mode_does_one_kind_of_thing():
    assert JoystickInterpreter(0.2, 0.6).layout is THREE_AXIS and LAYOUTS["3-axis"] is THREE_AXIS
    pairs = (("F", "B"), ("R", "L"), ("Rr", "Lr"))
    for presses, field in ((0, "linear"), (1, "angular")):  # translation, then wrist
        vectors = {fn: np.asarray(getattr(command_after(THREE_AXIS, presses, fn), field)) for fn in FUNCTIONS}
        for a, b in pairs:  # opposite functions do opposite things at the same speed
            np.testing.assert_allclose(vectors[a], -vectors[b])
        units = np.array([vectors[a] / np.linalg.norm(vectors[a]) for a, _ in pairs])
        np.testing.assert_allclose(np.abs(units) @ np.abs(units).T, np.eye(3), atol=1e-12)  # three distinct axes
        other = "angular" if field == "linear" else "linear"
        assert all(not np.any(getattr(command_after(THREE_AXIS, presses, fn), other)) for fn in FUNCTIONS)
    assert command_after(THREE_AXIS, 0, "Lr").linear[2] < 0  # Lr lowers the hand in translation
    fingers = {fn: command_after(THREE_AXIS, 2, fn).finger for fn in FUNCTIONS}
    assert fingers["F"] > 0 > fingers["B"] and not any(fingers[fn] for fn in ("R", "L", "Rr", "Lr"))


def test_two_axis_needs_four_directions():
    assert TWO_AXIS.functions == ("F", "B", "R", "L") and LAYOUTS["2-axis"] is TWO_AXIS


def test_one_axis_moves_turns_and_grips_with_f_and_b_alone_in_five_modes():
    assert ONE_AXIS.functions == ("F", "B") and LAYOUTS["1-axis"] is ONE_AXIS
    # per mode (B1 presses from translation): what F does, as the other layouts' functions do it
    same = {0: ("linear", TWO_AXIS, 0, "F"), 1: ("linear", TWO_AXIS, 0, "R"), 2: ("linear", TWO_AXIS, 1, "F"),
            3: ("angular", THREE_AXIS, 1, "Rr")}
    for presses, (field, layout, their_presses, theirs) in same.items():
        for fn, their_fn in (("F", theirs), ("B", {"F": "B", "R": "L", "Rr": "Lr"}[theirs])):
            np.testing.assert_array_equal(getattr(command_after(ONE_AXIS, presses, fn), field),
                                          getattr(command_after(layout, their_presses, their_fn), field))
    assert command_after(ONE_AXIS, 4, "F").finger > 0 > command_after(ONE_AXIS, 4, "B").finger
    # it cannot tilt the hand, so the scripted user never tries to level it with this layout
    assert not ONE_AXIS.levels and TWO_AXIS.levels and THREE_AXIS.levels


def test_two_axis_b1_steps_forward_through_four_modes_and_b2_back():
    stick = two_axis_stick()
    forward = [stick.mode] + [(stick.update(B1), stick.mode)[1] for _ in range(4)]
    assert forward == [Mode.TRANSLATION, Mode.HEIGHT, Mode.WRIST, Mode.FINGERS, Mode.TRANSLATION]
    backward = [(stick.update(B2), stick.mode)[1] for _ in range(4)]
    assert backward == [Mode.FINGERS, Mode.WRIST, Mode.HEIGHT, Mode.TRANSLATION]
    assert (stick.button_presses, stick.mode_switches) == (8, 8)


@pytest.mark.parametrize("function", ["F", "B", "R", "L"])
def test_two_axis_modes_do_what_the_three_axis_stick_does_with_its_six_directions(function):
    """Translation: the 3-axis xy moves; height: F/B up/down like Rr/Lr move, R/L turn like the 3-axis
    wrist's Rr/Lr; wrist: the 3-axis wrist's F/B/R/L tilts; fingers: F closes, B opens."""
    height_twin = {"F": "Rr", "B": "Lr", "R": "Rr", "L": "Lr"}[function]
    translation = command_after(TWO_AXIS, 0, function)
    np.testing.assert_allclose(translation.linear, command_after(THREE_AXIS, 0, function).linear)
    assert translation.linear[2] == 0 and not np.any(translation.angular)
    height = command_after(TWO_AXIS, 1, function)
    if function in ("F", "B"):
        np.testing.assert_allclose(height.linear, command_after(THREE_AXIS, 0, height_twin).linear)
        assert not np.any(height.linear[:2]) and not np.any(height.angular)
    else:
        np.testing.assert_allclose(height.angular, command_after(THREE_AXIS, 1, height_twin).angular)
        assert not np.any(height.linear)
    np.testing.assert_allclose(command_after(TWO_AXIS, 2, function).angular,
                               command_after(THREE_AXIS, 1, function).angular)
    assert command_after(TWO_AXIS, 3, function).finger == command_after(THREE_AXIS, 2, function).finger
    assert not np.any(command_after(TWO_AXIS, 0, "Rr").linear)  # no Rr/Lr on a four-direction stick


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
