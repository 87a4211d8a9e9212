"""The scripted JACO user on hand-made views: which mode, function, deflection and timing it picks."""
import math
from dataclasses import replace

import numpy as np
import pytest

from bomi.errors import BomiError
from helpers import assert_agree, assert_one_line_error
from sim.joystick import THREE_AXIS, TWO_AXIS, Kind, Mode
from tasks.operators.params import DEFAULT_OPERATOR_FILE, load_operator
from tasks.stacking.vocabulary import Controls, Goal, Phase, View
from tasks.operators.planner import FixedTiming, ScriptedUser, _updated, hand_velocity, mode_button, plan
from tasks.operators.judgement import (Memory, cube_to_take, deflection_for, held_cube, norm, placed_cubes,
                                       turn_deflection_for, xy_distance)

P = load_operator()
TWO_AXIS_B1 = Memory(controls=Controls(TWO_AXIS, ("B1",)))  # P4, P5: four directions and one button
B = np.array([0.14, -0.45])
HALF = 0.025


def view(hand=(0.0, -0.42, 0.22), cubes=((-0.14, -0.39), (-0.14, -0.51)), mode=Mode.TRANSLATION, closure=0.0,
         touching=(False, False), t=0.0, cube_z=(HALF, HALF), yaw=(0.0, 0.0)) -> View:
    return View(t=t, hand_pos=np.array(hand, float), hand_yaw=0.0, hand_tilt=np.zeros(2), closure=closure, mode=mode,
                cube_pos=tuple(np.array([x, y, z]) for (x, y), z in zip(cubes, cube_z)), cube_yaw=yaw,
                touching=touching, target_xy=B, table_z=0.0, cube_size=2 * HALF)


def test_shipped_operator_file_loads():
    assert P.coarse == 1.0 and 0 < P.fine < P.coarse and P.reaction_time > 0


@pytest.mark.parametrize("text, fault", [
    ("", "[timing] section missing"),
    (None, "[timing] reaction_time: expected a number, got 'slow'"),
    ("negative", "[timing] reaction_time: must be >= 0, got -0.3"),
    ("unknown", "[timing] unknown key(s) ['wobble']"),
    ("not toml [", "not valid TOML"),
])
def test_bad_operator_file_is_one_clear_error(tmp_path, text, fault):
    good = DEFAULT_OPERATOR_FILE.read_text()
    content = {None: good.replace("reaction_time = 0.30", 'reaction_time = "slow"'),
               "negative": good.replace("reaction_time = 0.30", "reaction_time = -0.3"),
               "unknown": good.replace("[timing]\n", "[timing]\nwobble = 1\n")}.get(text, text)
    assert_one_line_error(load_operator, tmp_path / "op.toml", content, fault)


def test_operator_file_by_shipped_name_and_missing_file(tmp_path):
    assert load_operator("operator") == P
    with pytest.raises(BomiError, match="no such operator file"):
        load_operator(tmp_path / "absent.toml")


def test_mode_button_takes_the_short_way_round():
    # cycle translation -> wrist -> fingers -> translation; B1 forward, B2 back
    assert mode_button(Mode.TRANSLATION, Mode.WRIST) == "B1"
    assert mode_button(Mode.TRANSLATION, Mode.FINGERS) == "B2"
    assert mode_button(Mode.FINGERS, Mode.TRANSLATION) == "B1"
    assert mode_button(Mode.WRIST, Mode.TRANSLATION) == "B2"


def test_mode_button_chooses_only_among_the_buttons_the_user_has():
    # 2-axis cycle translation -> height -> wrist -> fingers
    both = Controls(TWO_AXIS)
    assert mode_button(Mode.TRANSLATION, Mode.FINGERS, both) == "B2"  # one press back instead of three
    assert mode_button(Mode.TRANSLATION, Mode.WRIST, both) == "B1"  # a tie: two either way
    assert mode_button(Mode.HEIGHT, Mode.TRANSLATION, both) == "B2"
    for current, wanted in [(Mode.TRANSLATION, Mode.FINGERS), (Mode.HEIGHT, Mode.TRANSLATION)]:
        assert mode_button(current, wanted, Controls(TWO_AXIS, ("B1",))) == "B1"
        assert mode_button(current, wanted, Controls(TWO_AXIS, ("B2",))) == "B2"
    assert mode_button(Mode.TRANSLATION, Mode.FINGERS, Controls(THREE_AXIS, ("B1",))) == "B1"
    # no button is a choice (the modes change automatically, tasks/operators/assist.py); an unknown one is not
    assert Controls(TWO_AXIS, ()).label == "2-axis, no button"
    with pytest.raises(ValueError):
        Controls(TWO_AXIS, ("B3",))


def test_two_axis_descent_needs_the_height_mode_and_b_goes_down():
    above = view(hand=(-0.14, -0.39, 0.15))
    intent, memory = plan(above, TWO_AXIS_B1, P, combine_axes=False)
    assert intent.button == "B1" and str(intent.goal) == "reach cube 1: descend: height mode"
    assert memory.controls is TWO_AXIS_B1.controls  # the controls stay with the person
    intent, _ = plan(replace(above, mode=Mode.HEIGHT), TWO_AXIS_B1, P, combine_axes=False)
    assert str(intent.goal) == "reach cube 1: descend" and set(intent.deflection) == {"B"}


def test_two_axis_rise_is_f_in_height_mode_and_travel_goes_back_to_translation_with_b1():
    low = view(hand=(0.10, -0.45, 0.03), mode=Mode.HEIGHT)
    intent, _ = plan(low, TWO_AXIS_B1, P, combine_axes=True)
    assert str(intent.goal) == "reach cube 1: rise" and dict(intent.deflection) == {"F": P.coarse}  # 7 cm up
    high = view(hand=(0.10, -0.45, 0.12), mode=Mode.HEIGHT)  # at the travel height, far from the cube
    intent, _ = plan(high, TWO_AXIS_B1, P, combine_axes=False)
    assert str(intent.goal) == "reach cube 1: travel: translation mode" and intent.button == "B1"  # 3 presses on
    intent, _ = plan(high, Memory(controls=Controls(TWO_AXIS)), P, combine_axes=False)
    assert intent.button == "B2"  # with both buttons: one press back


def test_two_axis_finishes_the_axis_of_the_current_mode_before_switching():
    # descending onto the cube with x 14 mm off (beyond twice the stop tolerance) and z 12 cm off
    off = view(hand=(-0.14 + 0.014, -0.39, 0.15))
    for mode, functions in [(Mode.HEIGHT, {"B"}), (Mode.TRANSLATION, {"R"})]:
        intent, _ = plan(replace(off, mode=mode), TWO_AXIS_B1, P, combine_axes=False)
        assert str(intent.goal) == "reach cube 1: descend" and set(intent.deflection) == functions, mode
    intent, _ = plan(off, Memory(), P, combine_axes=False)
    assert set(intent.deflection) == {"Lr"}  # 3-axis: the largest error, z, in translation mode


def test_two_axis_combined_axes_stay_within_the_current_mode():
    v = view(hand=(0.0, -0.42, 0.22))
    intent, _ = plan(v, Memory(controls=Controls(TWO_AXIS)), P, combine_axes=True)
    assert intent.deflection["R"] == P.coarse and intent.deflection["B"] == pytest.approx(0.5 * 0.03 / (0.20 * 0.08))
    # descending with x and z wanted: each mode moves its own axis only, however large the other
    descend = view(hand=(-0.14 + 0.014, -0.39, 0.15))
    for mode, functions in [(Mode.HEIGHT, {"B"}), (Mode.TRANSLATION, {"R"})]:
        intent, _ = plan(replace(descend, mode=mode), Memory(controls=Controls(TWO_AXIS)), P, combine_axes=True)
        assert set(intent.deflection) == functions, mode
    intent, _ = plan(descend, Memory(), P, combine_axes=True)
    assert set(intent.deflection) == {"R", "Lr"}  # a 3-axis stick combines them


def test_two_axis_turns_about_the_vertical_in_height_mode_and_levels_in_wrist_mode():
    turned = view(hand=(-0.14, -0.39, 0.15), yaw=(math.radians(30.0), 0.0))
    intent, _ = plan(turned, TWO_AXIS_B1, P, combine_axes=False)
    assert intent.button == "B1" and str(intent.goal) == "turn to cube 1: height mode"
    intent, _ = plan(replace(turned, mode=Mode.HEIGHT), TWO_AXIS_B1, P, combine_axes=False)
    assert set(intent.deflection) == {"R"}  # R turns about z+ in height mode
    tilted = replace(view(mode=Mode.HEIGHT), hand_tilt=np.array([0.05, -math.radians(20.0)]))
    intent, _ = plan(tilted, TWO_AXIS_B1, P, combine_axes=False)
    assert intent.button == "B1" and str(intent.goal) == "level the hand: wrist mode"
    intent, _ = plan(replace(tilted, mode=Mode.WRIST), TWO_AXIS_B1, P, combine_axes=False)
    assert set(intent.deflection) == {"L"}  # about world y-, as in the 3-axis wrist mode


def test_reach_single_axis_takes_the_largest_error_with_the_right_function():
    # hand at (0, -0.42), cube 1 at (-0.14, -0.39): x error -0.14 (R = x-), y error +0.03 (B = y+)
    intent, memory = plan(view(), Memory(), P, combine_axes=False)
    assert str(intent.goal) == "reach cube 1: travel"
    assert dict(intent.deflection) == {"R": P.coarse}
    assert memory.axis == 0


def test_reach_joystick_combines_axes_each_as_fast_as_its_distance_allows():
    intent, _ = plan(view(), Memory(), P, combine_axes=True)
    # x is 0.14 m away: 0.5 x 0.14 / (0.20 m/s x 0.08 s) > 1, coarse; y 0.03 m: 0.5 x 0.03 / 0.016
    assert intent.deflection["R"] == P.coarse
    assert intent.deflection["B"] == pytest.approx(0.5 * 0.03 / (0.20 * 0.08))


def test_low_hand_far_from_goal_rises_first():
    intent, _ = plan(view(hand=(0.10, -0.45, 0.03)), Memory(), P, combine_axes=True)
    # travel height: hover above the grasp point (0.025 + 0.07) or clear of one cube (0.1): 0.07 m up
    assert P.hover == 0.07 and P.carry_clearance == 0.05
    assert str(intent.goal) == "reach cube 1: rise" and dict(intent.deflection) == {"Rr": P.coarse}


def test_over_the_cube_it_descends_then_switches_to_fingers_and_closes():
    above = view(hand=(-0.14, -0.39, 0.15))
    intent, _ = plan(above, Memory(), P, combine_axes=False)
    assert str(intent.goal) == "reach cube 1: descend" and set(intent.deflection) == {"Lr"}
    at_grasp = view(hand=(-0.14, -0.39, HALF + P.grasp_offset))
    intent, _ = plan(at_grasp, Memory(), P, combine_axes=False)
    assert intent.button == "B2" and not intent.deflection  # translation -> fingers: one press back
    intent, _ = plan(replace(at_grasp, mode=Mode.FINGERS), Memory(), P, combine_axes=False)
    assert dict(intent.deflection) == {"F": P.coarse}  # F closes in finger mode


def test_a_cube_counts_as_held_only_after_the_squeeze_time():
    grasping = view(hand=(-0.14, -0.39, HALF), mode=Mode.FINGERS, closure=0.6, touching=(True, False), t=10.0)
    intent, memory = plan(grasping, Memory(), P, combine_axes=False)
    assert str(intent.goal) == "grasp cube 1"  # still squeezing
    later = replace(grasping, t=10.0 + P.squeeze_time + 0.01, mode=Mode.TRANSLATION)
    intent, _ = plan(later, memory, P, combine_axes=False)
    assert str(intent.goal) == "carry cube 1: rise" and set(intent.deflection) == {"Rr"}


def test_carrying_aims_the_cube_not_the_hand_at_b():
    # the hand holds cube 1 13 mm off its centre (along x); the cube must end over B
    grip = np.array([0.013, 0.0, 0.0])
    cube = np.array([0.10, -0.45, 0.12])
    v = view(hand=tuple(cube + grip), cubes=((cube[0], cube[1]), (-0.14, -0.51)), cube_z=(cube[2], HALF),
             closure=0.7, touching=(True, False), t=5.0)
    memory = Memory(touch_since=0.0)
    intent, _ = plan(v, memory, P, combine_axes=False)
    assert str(intent.goal) == "carry cube 1: travel" and set(intent.deflection) == {"L"}  # x+ toward B
    over_b = replace(v, hand_pos=np.r_[B + grip[:2], cube[2]], cube_pos=(np.r_[B, cube[2]], v.cube_pos[1]))
    intent, _ = plan(over_b, memory, P, combine_axes=False)
    assert str(intent.goal) == "carry cube 1: descend"


def test_stacked_cubes_are_recognised_and_the_user_rests_after_retreating():
    stacked = view(hand=(0.14, -0.45, 0.30), cubes=(tuple(B), tuple(B + 0.004)), cube_z=(HALF, 3 * HALF))
    assert placed_cubes(stacked, P) == (0, 1)
    intent, _ = plan(stacked, Memory(), P, combine_axes=False)
    assert intent.is_rest and str(intent.goal) == "done"
    off = replace(stacked, cube_pos=(stacked.cube_pos[0], stacked.cube_pos[1] + [0.03, 0, 0]))
    assert placed_cubes(off, P) == (0, None)


def test_a_cube_turned_past_the_tolerance_gets_a_wrist_turn_toward_it():
    turned = view(hand=(-0.14, -0.39, 0.15), yaw=(math.radians(30.0), 0.0), mode=Mode.WRIST)
    intent, _ = plan(turned, Memory(), P, combine_axes=False)
    assert str(intent.goal) == "turn to cube 1" and set(intent.deflection) == {"Rr"}  # Rr turns about z+
    # 30 deg off and 60 deg off are the same cube face seen the other way: turn back instead
    intent, _ = plan(replace(turned, cube_yaw=(math.radians(60.0), 0.0)), Memory(), P, combine_axes=False)
    assert set(intent.deflection) == {"Lr"}


def test_scripted_user_reacts_late_to_new_moves_and_stops_at_once():
    user = ScriptedUser(P, combine_axes=False)
    first = user.stick_intent(view(t=0.0))
    assert first.is_rest  # reaction time not over
    assert user.stick_intent(view(t=P.reaction_time / 2)).is_rest
    moving = user.stick_intent(view(t=P.reaction_time + 1e-6))
    assert dict(moving.deflection) == {"R": P.coarse}
    # the hand arrives over the cube: the user lets go in the same tick
    arrived = user.stick_intent(view(hand=(-0.14, -0.39, 0.22), t=P.reaction_time + 0.1))
    assert not arrived.deflection


def test_a_tilted_hand_is_levelled_in_wrist_mode_about_the_largest_axis():
    tilted = replace(view(mode=Mode.WRIST), hand_tilt=np.array([0.05, -math.radians(20.0)]))
    intent, _ = plan(tilted, Memory(), P, combine_axes=False)
    # rotate about world y-: WRIST_AXES gives L = (0, -1, 0)
    assert str(intent.goal) == "level the hand" and set(intent.deflection) == {"L"}
    intent, _ = plan(replace(tilted, mode=Mode.TRANSLATION), Memory(), P, combine_axes=False)
    assert intent.button == "B1"


def test_the_speed_lets_the_hand_coast_only_part_of_the_way_between_fine_and_coarse():
    # 0.20 m to go, 1 s of coasting: 0.5 x 0.20 m / (0.20 m/s x 1 s) = 0.5
    assert deflection_for(0.20, P, anticipation=1.0) == pytest.approx(0.5)
    assert deflection_for(0.03, P, anticipation=1.0) == pytest.approx(0.075)  # a small correction goes slowly
    assert deflection_for(0.01, P, anticipation=1.0) == P.fine  # floor: never slower than fine
    assert deflection_for(0.09, P, anticipation=0.08) == P.coarse  # a joystick stops at once: full speed


def test_the_cube_lying_on_the_other_is_taken_first_and_the_touched_cube_nearest_the_pinch_is_held():
    flat = view()
    assert cube_to_take(flat, bottom=None) == 0
    assert cube_to_take(flat, bottom=0) == 1
    piled = view(cubes=((0.10, -0.45), (0.11, -0.45)), cube_z=(HALF, 3 * HALF))
    assert cube_to_take(piled, bottom=None) == 1
    both = replace(piled, hand_pos=np.array([0.11, -0.45, 3 * HALF]), touching=(True, True), closure=0.6, t=5.0)
    assert held_cube(both, Memory(touch_since=0.0), P) == 1
    assert held_cube(replace(both, closure=0.1), Memory(touch_since=0.0), P) is None  # open fingers hold nothing


def _run_until_moving(user: ScriptedUser, hand, t: float) -> float:
    while not user.stick_intent(view(hand=tuple(hand), t=t)).deflection:
        t += 1 / 60
    return t


def test_scripted_user_learns_to_let_a_late_arm_settle_before_the_next_move():
    user = ScriptedUser(P, combine_axes=False)
    over_cube = np.array([-0.14, -0.39, 0.22])
    t = _run_until_moving(user, (0.0, -0.42, 0.22), 0.0)  # reaction time, then R toward cube 1
    stopped = t + 0.1
    assert not user.stick_intent(view(hand=tuple(over_cube), t=stopped)).deflection  # over the cube: let go
    # like a BoMI, the arm answers late: the hand goes on for 1.0 s after letting go (past the cube)
    hand, k = over_cube.copy(), 1
    while k / 60 <= 1.0:
        hand = hand + [-0.05 / 60, 0.0, 0.0]
        assert not user.stick_intent(view(hand=tuple(hand), t=stopped + k / 60)).deflection  # watches it go on
        k += 1
    restart = _run_until_moving(user, hand, stopped + k / 60)  # back toward the cube once at rest
    assert user.settle == pytest.approx(0.5, abs=0.03)  # half of the 1.0 s seen, learnt from 0
    # next time the hand looks still right after letting go, the user waits the learnt settle time
    stopped_again = restart + 0.1
    assert not user.stick_intent(view(hand=tuple(over_cube), t=stopped_again)).deflection  # back over the cube
    learnt = user.settle
    descend = _run_until_moving(user, over_cube, stopped_again + 1 / 60)
    assert str(user.current.goal) == "reach cube 1: descend"
    assert descend >= stopped_again + learnt - 1e-9 > stopped_again + max(P.reaction_time, P.pause_between_moves)
    assert user.settle == pytest.approx(learnt / 2)  # this time the hand stayed put: learnt back down


def test_a_descent_that_stalls_counts_as_arrived_and_the_fingers_close_slightly_off_centre():
    above = (-0.14 + 0.02, -0.39, HALF + 0.03)  # 2 cm off in x (within twice align), 3 cm too high
    moving = Memory(descending=True)
    intent, _ = plan(view(hand=above), moving, P, combine_axes=False)
    assert str(intent.goal) == "reach cube 1: descend"
    intent, memory = plan(view(hand=above), replace(moving, stalled=True), P, combine_axes=False)
    assert str(intent.goal) == "grasp cube 1: fingers mode" and memory.stalled
    intent, _ = plan(view(hand=above, mode=Mode.FINGERS, closure=0.3), memory, P, combine_axes=False)
    assert str(intent.goal) == "grasp cube 1"  # keeps closing there
    at_height = (-0.14 + 0.02, -0.39, HALF)
    intent, _ = plan(view(hand=at_height, mode=Mode.FINGERS), moving, P, combine_axes=False)
    assert str(intent.goal) == "grasp cube 1"  # arrived at the bottom of a descent 2 cm off: close
    intent, _ = plan(view(hand=at_height, mode=Mode.FINGERS, closure=0.3), Memory(), P, combine_axes=False)
    assert str(intent.goal) == "grasp cube 1"  # and keep closing


def test_scripted_user_takes_a_descent_that_does_not_go_lower_as_stalled():
    user = ScriptedUser(P, combine_axes=False)
    over = (-0.14, -0.39, 0.15)
    t = _run_until_moving(user, over, 0.0)
    assert str(user.current.goal) == "reach cube 1: descend"
    while t < 4.9:
        t += 1 / 60
        user.stick_intent(view(hand=over, t=t))
    assert not user.memory.stalled
    while t < 5.5:
        t += 1 / 60
        intent = user.stick_intent(view(hand=over, t=t))
    assert user.memory.stalled and str(intent.goal).startswith("grasp cube 1")


def test_a_descent_that_corrects_upward_is_never_taken_as_stalled():
    user = ScriptedUser(P, combine_axes=False)
    below = (-0.14, -0.39, HALF - 0.03)  # overshot 3 cm below the grasp height: the descent goes up
    t = _run_until_moving(user, below, 0.0)
    assert str(user.current.goal) == "reach cube 1: descend" and set(user.current.deflection) == {"Rr"}
    while t < 8.0:  # the hand does not answer for far longer than the stall time
        t += 1 / 60
        user.stick_intent(view(hand=below, t=t))
    assert not user.memory.stalled and str(user.current.goal) == "reach cube 1: descend"


def test_a_grasp_is_judged_missed_only_miss_time_after_the_interface_answers_the_push():
    """Through a BoMI that answers a push 1.5 s late (learnt: ``answered_hold``), fingers closing on nothing
    are taken as a miss miss_time after the answer, not after the push: the fingers may not have reached the
    cube yet (the miss-then-open cycles of P1's development seed 129)."""
    high = (-0.14, -0.39, HALF + 0.03)
    lagging = Memory(descending=True, stalled=True, answered_hold=1.5)
    intent, memory = plan(view(hand=high, mode=Mode.FINGERS, closure=0.0, t=10.0), lagging, P, combine_axes=False)
    assert memory.closing_since == 10.0
    for t in (10.1 + P.miss_time, 10.0 + P.miss_time + 1.5):
        intent, memory = plan(view(hand=high, mode=Mode.FINGERS, closure=0.3, t=t), memory, P, combine_axes=False)
        assert str(intent.goal) == "grasp cube 1"                        # not yet: the fingers are still closing
    intent, memory = plan(view(hand=high, mode=Mode.FINGERS, closure=0.7, t=10.1 + P.miss_time + 1.5), memory, P,
                          combine_axes=False)
    assert str(intent.goal) == "missed cube 1: open hand"


def test_fingers_closed_on_nothing_open_again_and_forget_the_stall():
    high = (-0.14, -0.39, HALF + 0.03)  # a stalled descent closed 3 cm too high
    stalled = Memory(descending=True, stalled=True)
    intent, memory = plan(view(hand=high, mode=Mode.FINGERS, closure=0.5, t=10.0), stalled, P, combine_axes=False)
    assert str(intent.goal) == "grasp cube 1" and memory.stalled and memory.closing_since == 10.0
    intent, memory = plan(view(hand=high, mode=Mode.FINGERS, closure=0.7, t=10.0 + P.miss_time), memory, P,
                          combine_axes=False)
    assert str(intent.goal) == "grasp cube 1" and memory.closing_since == 10.0  # not yet a miss
    intent, memory = plan(view(hand=high, mode=Mode.FINGERS, closure=0.7, t=10.1 + P.miss_time), memory, P,
                          combine_axes=False)
    assert str(intent.goal) == "missed cube 1: open hand" and set(intent.deflection) == {"B"}
    assert not memory.stalled and memory.closing_since is None
    intent, _ = plan(view(hand=high, mode=Mode.FINGERS, closure=0.0), memory, P, combine_axes=False)
    # open again: not the same pose again, a new try on the other pair of faces, turned above the cube
    assert str(intent.goal) == "reach cube 1: rise to turn: translation mode"


def test_closing_is_timed_only_in_the_finger_mode_and_while_nothing_is_touched():
    at_grasp = (-0.14, -0.39, HALF)
    _, memory = plan(view(hand=at_grasp, mode=Mode.TRANSLATION, closure=0.3, t=1.0), Memory(), P, combine_axes=False)
    assert memory.closing_since is None  # still switching to the finger mode
    _, memory = plan(view(hand=at_grasp, mode=Mode.FINGERS, closure=0.3, t=2.0), memory, P, combine_axes=False)
    assert memory.closing_since == 2.0
    _, memory = plan(view(hand=at_grasp, mode=Mode.FINGERS, closure=0.6, touching=(True, False), t=9.0), memory, P,
                     combine_axes=False)
    assert memory.closing_since is None


def test_a_wrist_turn_slows_down_near_its_goal_by_the_same_coasting_rule():
    # 0.1 rad to go, 1 s of coasting seen: 0.5 x 0.1 rad / (0.6 rad/s x 1 s) = 0.083
    assert turn_deflection_for(0.1, P, anticipation=1.0) == pytest.approx(0.5 * 0.1 / 0.6)
    assert turn_deflection_for(0.5, P, anticipation=1.0) == P.turn  # far: no faster than the turn deflection
    assert turn_deflection_for(0.01, P, anticipation=1.0) == P.fine
    assert turn_deflection_for(0.1, P, anticipation=0.08) == P.turn  # a joystick user turns at the usual rate


def test_a_turn_near_the_cube_at_grasp_height_rises_first():
    low = view(hand=(-0.14, -0.39, HALF + 0.01), yaw=(0.5, 0.0))  # cube 1 turned 29 deg, the hand at its side
    intent, _ = plan(low, Memory(), P, combine_axes=False)
    assert str(intent.goal) == "reach cube 1: rise to turn" and set(intent.deflection) == {"Rr"}
    intent, _ = plan(replace(low, hand_pos=np.array([-0.14, -0.39, HALF + P.hover])), Memory(), P, combine_axes=False)
    assert str(intent.goal) == "turn to cube 1: wrist mode"


def test_with_one_button_each_press_is_let_go_once_the_mode_changes_then_made_again():
    user = ScriptedUser(P, combine_axes=False, memory=TWO_AXIS_B1)
    at_grasp = (-0.14, -0.39, HALF)  # wants the finger mode: three presses of B1 from translation
    t, mode, presses, held = 0.0, Mode.TRANSLATION, [], None
    while t < 6.0 and mode is not Mode.FINGERS:
        intent = user.stick_intent(view(hand=at_grasp, mode=mode, t=t))
        if intent.button == "B1" and held is None:  # a press is the button going down
            presses.append((t, mode))
            mode = TWO_AXIS.after(mode, "B1")  # the arm answers the press at once
        held = intent.button
        t += 1 / 60
    assert [m for _, m in presses] == [Mode.TRANSLATION, Mode.HEIGHT, Mode.WRIST] and mode is Mode.FINGERS
    gaps = np.diff([t for t, _ in presses])  # let go, then press again after the reaction time
    assert np.all(gaps >= P.reaction_time) and np.all(gaps < P.button_patience)


def test_a_release_is_not_taken_back_when_the_touch_flickers_half_way():
    on_top = view(hand=(0.11, -0.45, 3 * HALF), cubes=((0.11, -0.45), (0.11, -0.45)), cube_z=(HALF, 3 * HALF),
                  mode=Mode.FINGERS, closure=0.5, touching=(False, False), t=30.0)
    intent, memory = plan(on_top, Memory(), P, combine_axes=False)
    assert str(intent.goal) == "grasp cube 2"  # half-closed at a cube it does not hold: it would close
    intent, memory = plan(on_top, Memory(opening=True), P, combine_axes=False, holding={"B": 1.0})
    assert str(intent.goal) == "open hand" and set(intent.deflection) == {"B"} and memory.opening
    _, memory = plan(replace(on_top, closure=0.0), memory, P, combine_axes=False, holding={"B": 1.0})
    assert not memory.opening  # open: done
    held = replace(on_top, touching=(False, True), closure=0.6)
    _, memory = plan(held, Memory(touch_since=0.0), P, combine_axes=False)
    assert not memory.opening  # a release only wanted, not yet begun on the stick, commits to nothing


def test_a_goal_reads_as_words_and_only_a_descent_under_way_counts_as_descending():
    descend = Goal("reach cube 1", Phase.DESCEND)
    assert str(descend) == "reach cube 1: descend" and descend.descending
    pressing = Goal("reach cube 1", Phase.DESCEND, Mode.HEIGHT)  # a press on the way down is not the descent
    assert str(pressing) == "reach cube 1: descend: height mode" and not pressing.descending
    assert str(Goal("grasp cube 2")) == "grasp cube 2" and not Goal("grasp cube 2").descending
    assert str(Goal()) == "rest"


def test_after_a_missed_grasp_the_hand_opens_fully_before_trying_again():
    off = (-0.14 + 0.01, -0.39, HALF)  # at grasp height, 1 cm beside the cube
    intent, memory = plan(view(hand=off, mode=Mode.FINGERS, closure=0.3), Memory(), P, combine_axes=False)
    assert str(intent.goal) == "grasp cube 1"  # closing there
    missed = replace(memory, closing_since=0.0)
    intent, memory = plan(view(hand=off, mode=Mode.FINGERS, closure=0.7, t=P.miss_time + 0.1), missed, P,
                          combine_axes=False)
    assert str(intent.goal) == "missed cube 1: open hand" and memory.missed
    # the next look, the fingers still closed (they have not started opening): open on, not close again
    intent, memory = plan(view(hand=off, mode=Mode.FINGERS, closure=0.7, t=P.miss_time + 0.2), memory, P,
                          combine_axes=False)
    assert str(intent.goal) == "open hand" and set(intent.deflection) == {"B"} and memory.missed
    _, memory = plan(view(hand=off, mode=Mode.FINGERS, closure=0.1, t=P.miss_time + 2), memory, P, combine_axes=False)
    assert not memory.missed  # open: the grasp is tried anew


def test_fingers_that_stop_opening_are_lifted_clear_then_opened():
    user = ScriptedUser(P, combine_axes=False)
    low = (0.14, -0.45, 0.06)
    t = 0.0
    while t < 1.0 or not user.current.deflection:  # a half-closed hand over B, nothing held: open it
        t += 1 / 60
        user.stick_intent(view(hand=low, mode=Mode.FINGERS, closure=0.33, t=t, cubes=((0.14, -0.45), (0.3, -0.3))))
    assert str(user.current.goal) == "open hand" and set(user.current.deflection) == {"B"}
    start = t
    while t < start + P.miss_time + 0.2:  # the fingers do not open any further
        t += 1 / 60
        intent = user.stick_intent(view(hand=low, mode=Mode.FINGERS, closure=0.33, t=t, cubes=((0.14, -0.45), (0.3, -0.3))))
    assert user.memory.fingers_blocked == pytest.approx(0.06)
    assert str(intent.goal) == "free the fingers: rise: translation mode"
    _, memory = plan(view(hand=(0.14, -0.45, 0.06 + P.hover), closure=0.33), user.memory, P, combine_axes=False)
    assert memory.fingers_blocked is None  # lifted clear: opening goes on from there


def test_a_top_cube_touched_by_an_open_hand_is_placed_but_not_by_a_closed_one():
    stacked = dict(cubes=((0.14, -0.45), (0.14, -0.45)), cube_z=(HALF, 3 * HALF), touching=(False, True))
    assert placed_cubes(view(closure=0.05, **stacked), P) == (0, 1)
    assert placed_cubes(view(closure=0.6, **stacked), P) == (0, None)


def test_a_held_cube_down_beside_its_place_is_slid_over_it_not_let_go_of_again_and_again():
    # cube 2 rests on cube 1 at B, 15 mm off its centre: within the approach's align tolerance, outside placed
    offset = np.array([0.011, 0.010])
    assert P.placed < np.linalg.norm(offset) < P.align
    top = np.r_[B + offset, 3 * HALF]
    v = view(hand=tuple(top), cubes=(tuple(B), tuple(top[:2])), cube_z=(HALF, top[2]), closure=0.7,
             touching=(False, True), t=5.0)
    intent, _ = plan(v, Memory(touch_since=0.0), P, combine_axes=False)
    assert intent.button is None and str(intent.goal) == "carry cube 2: travel"  # not "release cube 2"
    moving = THREE_AXIS.axes(Mode.TRANSLATION, Kind.LINEAR)
    (function, _), = intent.deflection.items()
    assert np.dot(moving[function][:2], -offset) > 0  # toward the place
    on_place = replace(v, hand_pos=np.r_[B + 0.004, top[2]], cube_pos=(v.cube_pos[0], np.r_[B + 0.004, top[2]]))
    intent, _ = plan(on_place, Memory(touch_since=0.0), P, combine_axes=False)
    assert str(intent.goal).startswith("release cube 2")



def test_after_a_grasp_beside_a_cube_lying_against_it_misses_the_hand_takes_the_other_pair_of_faces():
    # cube 2 lies against cube 1 along x (centres 51 mm apart); the hand at yaw 0 closes along x, so one finger
    # would have to go between the cubes (dev seed 977: nine close-miss-open cycles in one such pose)
    beside = dict(cubes=((-0.14, -0.45), (-0.14 + 0.051, -0.45)))
    at_grasp, above = (-0.14, -0.45, HALF), (-0.14, -0.45, HALF + P.hover)

    def after_miss(hand_yaw: float, hand: tuple) -> tuple:
        """Close at the grasp with the hand at ``hand_yaw`` for longer than miss_time, then open at ``hand``."""
        closed = replace(view(hand=at_grasp, mode=Mode.FINGERS, closure=0.6, t=10.0 + P.miss_time + 0.1, **beside),
                         hand_yaw=hand_yaw)
        intent, memory = plan(closed, Memory(closing_since=10.0), P, combine_axes=False)
        assert str(intent.goal) == "missed cube 1: open hand"
        opened = replace(closed, closure=0.0, hand_pos=np.array(hand), t=closed.t + 2.0)
        return opened, *plan(opened, memory, P, combine_axes=False)

    opened, intent, _ = after_miss(0.0, at_grasp)
    assert str(intent.goal) == "reach cube 1: rise to turn: translation mode"  # not "grasp cube 1" there again
    for missed_yaw in (0.0, math.pi, 0.15):  # the faces toward cube 2 (the same pair either way round, or 9 deg off)
        opened, intent, memory = after_miss(missed_yaw, above)
        assert str(intent.goal) == "turn to cube 1: wrist mode"
        for yaw, lined_up in ((missed_yaw + 0.1, False), (math.pi / 2, True), (-math.pi / 2 + 0.1, True), (0.0, False)):
            intent, _ = plan(replace(opened, hand_yaw=yaw), memory, P, combine_axes=False)
            assert str(intent.goal) == ("reach cube 1: descend: translation mode" if lined_up else
                                        "turn to cube 1: wrist mode"), (missed_yaw, yaw)
    opened, intent, memory = after_miss(math.pi / 2, above)  # a miss on the faces across x: back to those toward it
    intent, _ = plan(replace(opened, hand_yaw=0.0), memory, P, combine_axes=False)
    assert str(intent.goal) == "reach cube 1: descend: translation mode"
    grasped = replace(opened, touching=(True, False), closure=0.6)  # a grasp that holds: the memory is spent
    _, memory = plan(grasped, memory, P, combine_axes=False)
    intent, _ = plan(replace(opened, hand_yaw=math.pi / 2), memory, P, combine_axes=False)
    assert str(intent.goal) == "reach cube 1: descend: translation mode"


def test_a_hand_judged_at_the_grasp_of_a_cube_on_a_misplaced_stack_closes_where_a_late_arm_coasts_it():
    # dev seed 401, P1 BoMI: cube 1 set down 32 mm from B (outside the zone), cube 2 on top of it; nothing stops
    # the open hand going down beside the stack, and each correction of a late arm coasts past the grasp height
    bottom = B + (0.0, -0.032)
    top = bottom + (-0.0054, -0.0044)
    stack = dict(cubes=(tuple(bottom), tuple(top)), cube_z=(HALF, 3 * HALF))
    assert placed_cubes(view(**stack), P) == (None, None) and cube_to_take(view(**stack), None) == 1
    over = (top[0] + 0.004, top[1] - 0.002)
    intent, memory = plan(view(hand=(*over, 3 * HALF + 0.9 * P.stop), **stack), Memory(descending=True), P,
                          combine_axes=False)
    assert str(intent.goal) == "grasp cube 2: fingers mode" and intent.button == "B2"
    # while the press waits for the arm to settle, the hand coasts on down past the grasp height, then further
    goals, t = [], 0.0
    for dz, mode in ((-P.stop - 0.001, Mode.TRANSLATION), (-3.5 * P.stop, Mode.TRANSLATION), (-3.5 * P.stop, Mode.FINGERS)):
        t += 0.2
        intent, memory = plan(view(hand=(*over, 3 * HALF + dz), mode=mode, t=t, **stack), memory, P, combine_axes=False)
        goals.append(str(intent.goal))
    assert goals == ["grasp cube 2: fingers mode"] * 2 + ["grasp cube 2"]  # not back to "reach cube 2: descend"
    assert dict(intent.deflection) == {"F": P.coarse}  # the fingers close there


class _PulsesOf:
    """The scripted user's fixed timing, but every move of the hand is a pulse held ``seconds``, through
    an interface seen to answer pushes once held ``answered_hold``."""

    def __init__(self, seconds: float, answered_hold: float = 0.0):
        self.fixed, self.seconds, self.answered_hold = FixedTiming(P), seconds, answered_hold

    def __getattr__(self, name):
        return getattr(self.fixed, name)

    def hold(self, wanted, settle):
        return self.seconds


def test_a_descent_blocked_and_pushed_in_pulses_shorter_than_the_stall_time_stalls_too():
    """3 s pulses down onto something that does not let the hand go lower: the first pushes 3 s,
    the second 2 s more, and then the descent has been pushed the stall time (5 s): arrived."""
    user = ScriptedUser(P, combine_axes=False, timing=_PulsesOf(3.0))
    over = (-0.14, -0.39, 0.15)
    first = _run_until_moving(user, over, 0.0)
    assert str(user.current.goal) == "reach cube 1: descend"
    t = first
    while user.current.deflection:
        t += 1 / 60
        user.stick_intent(view(hand=over, t=t))
    assert t == pytest.approx(first + 3.0, abs=1.5 / 60) and not user.memory.stalled  # let go after 3 s
    second = _run_until_moving(user, over, t)
    assert str(user.current.goal) == "reach cube 1: descend"
    t = second
    while not user.memory.stalled and t < second + 10:
        t += 1 / 60
        intent = user.stick_intent(view(hand=over, t=t))
    assert t == pytest.approx(second + 2.0, abs=1.5 / 60)  # 3 + 2 s pushed
    assert str(intent.goal).startswith("grasp cube 1")


def test_pulses_down_that_move_the_hand_lower_never_stall():
    """The same 3 s pulses, each answered with 1 cm down: pushing does not add up across them."""
    user = ScriptedUser(P, combine_axes=False, timing=_PulsesOf(3.0))
    hand = np.array([-0.14, -0.39, 0.15])
    t = 0.0
    for _ in range(4):
        t = _run_until_moving(user, hand, t)
        while user.current.deflection:
            t += 1 / 60
            user.stick_intent(view(hand=tuple(hand), t=t))
        hand = hand - [0.0, 0.0, 0.01]  # it went 1 cm lower during the pulse
        assert not user.memory.stalled


def test_an_error_no_push_could_make_smaller_is_left_where_the_grasp_tolerates_it():
    """Having seen the shortest pushes move the hand 3 cm, the person leaves an error of less than
    half of that (1.5 cm) if the grasp tolerates it (z: reach x stop = 1.2 cm, xy: reach x align =
    3.2 cm); with a stick that goes as little as wanted (0) it corrects to the stop and align
    tolerances (6 mm, 1.6 cm)."""
    high = (-0.14, -0.39, HALF + 0.009)  # 9 mm above the grasp height
    assert str(plan(view(hand=high), Memory(descending=True), P, combine_axes=False)[0].goal) == "reach cube 1: descend"
    coarse = Memory(descending=True, pulse_step=0.03)
    assert str(plan(view(hand=high), coarse, P, combine_axes=False)[0].goal) == "grasp cube 1: fingers mode"
    too_high = (-0.14, -0.39, HALF + 0.014)  # 1.4 cm: more than the grasp tolerates, corrected whatever the step
    assert str(plan(view(hand=too_high), coarse, P, combine_axes=False)[0].goal) == "reach cube 1: descend"
    beside = (-0.14 + 0.02, -0.39, HALF)  # 2 cm off in x at the grasp height, not yet descending
    assert str(plan(view(hand=beside), Memory(), P, combine_axes=False)[0].goal) == "reach cube 1: travel"
    assert str(plan(view(hand=beside), Memory(pulse_step=0.03), P, combine_axes=False)[0].goal) == \
        "reach cube 1: travel"  # 2 cm is more than half of 3 cm
    assert str(plan(view(hand=beside), Memory(pulse_step=0.05), P, combine_axes=False)[0].goal) == \
        "grasp cube 1: fingers mode"


def test_a_carried_cube_is_set_down_off_its_place_where_the_place_tolerates_it_and_no_push_would_help():
    """Cube 1 carried 2 cm beside B (within target_zone, 2.5 cm, outside align, 1.6 cm): corrected with
    a stick that goes as little as wanted, set down where it is once the shortest pushes have been
    seen to go 5 cm.  Cube 2 2 cm beside cube 1 is outside placed (1.2 cm): corrected either way."""
    off = np.array([0.02, 0.0])
    held = np.r_[B + off, 0.12]
    v = view(hand=tuple(held), cubes=(tuple(held[:2]), (-0.14, -0.51)), cube_z=(held[2], HALF), closure=0.7,
             touching=(True, False), t=5.0)
    assert str(plan(v, Memory(touch_since=0.0), P, combine_axes=False)[0].goal) == "carry cube 1: travel"
    coarse = Memory(touch_since=0.0, pulse_step=0.05)
    assert str(plan(v, coarse, P, combine_axes=False)[0].goal) == "carry cube 1: descend"
    top = np.r_[B + off, 0.15]
    second = view(hand=tuple(top), cubes=(tuple(B), tuple(top[:2])), cube_z=(HALF, top[2]), closure=0.7,
                  touching=(False, True), t=5.0)
    assert str(plan(second, coarse, P, combine_axes=False)[0].goal) == "carry cube 2: travel"


def test_pulses_down_shorter_than_the_interface_needs_to_answer_say_nothing_of_a_blocked_hand():
    """Through an interface that has needed pushes of 2 s to answer, unanswered pulses of 1.5 s may be
    too short rather than blocked: 30 s of them never stall; pulses of 3 s (longer than it needs)
    stall after 5 s pushed, as through a stick that answers at once."""
    over = (-0.14, -0.39, 0.15)
    for pulse, stalls_after in ((1.5, None), (3.0, 5.0)):
        user = ScriptedUser(P, combine_axes=False, timing=_PulsesOf(pulse, answered_hold=2.0))
        t, pushed = 0.0, 0.0
        while t < 30.0 and not user.memory.stalled:
            t += 1 / 60
            user.stick_intent(view(hand=over, t=t))
            pushed += user.current.deflection.get("Lr", 0.0) > 0 and str(user.current.goal) == "reach cube 1: descend"
        if stalls_after is None:
            assert not user.memory.stalled and pushed / 60 > 15  # pushed down more than 15 s in all
        else:
            assert user.memory.stalled and pushed / 60 == pytest.approx(stalls_after, abs=2 / 60)


def test_a_cube_is_lined_up_with_the_other_within_the_place_tolerance_before_it_is_lowered_onto_it():
    """Cube 2 carried 1.4 cm beside cube 1 at B, above it: more than placed (1.2 cm), less than align
    (1.6 cm).  It is lined up in the air first; lowered there, the error would be slid away at the
    bottom, dragging cube 1 off B (dev seeds 187, 189, P1 BoMI).  On the table (B tolerates 2.5 cm)
    the same error goes down as before; a descent under way onto the cube goes on up to twice placed."""
    off = np.array([0.0, 0.014])
    above = np.r_[B + off, 0.15]
    second = view(hand=tuple(above), cubes=(tuple(B), tuple(above[:2])), cube_z=(HALF, above[2]), closure=0.7,
                  touching=(False, True), t=5.0)
    intent, _ = plan(second, Memory(touch_since=0.0), P, combine_axes=False)
    assert str(intent.goal) == "carry cube 2: travel"
    assert str(plan(second, Memory(touch_since=0.0, descending=True), P, combine_axes=False)[0].goal) == \
        "carry cube 2: descend"
    first = view(hand=tuple(above), cubes=(tuple(above[:2]), (-0.14, -0.51)), cube_z=(above[2], HALF), closure=0.7,
                 touching=(True, False), t=5.0)
    assert str(plan(first, Memory(touch_since=0.0), P, combine_axes=False)[0].goal) == "carry cube 1: descend"


def test_xy_distance_agrees_with_norm_of_the_xy_difference():
    """xy_distance (a speed-up) gives norm(a[:2] - b[:2]) to 2 ulps (a sum of two squares and a root,
    which the CPU may fuse), zeros and tiny values included."""
    rng = np.random.default_rng(3)
    for _ in range(3000):
        a, b = rng.normal(size=3) * 10.0 ** rng.integers(-8, 2), rng.normal(size=3)
        if rng.integers(4) == 0:
            b[:2] = a[:2]  # a zero difference now and then
        assert_agree(xy_distance(a, b), norm(a[:2] - b[:2]), ulps=2)


def test_norm_of_floats_and_arrays_agrees_with_numpys():
    """norm (the planner's lengths and speeds, on Python floats or small arrays) gives np.linalg.norm's
    value to 2 ulps (numpy's is a BLAS dot product, fused or not by the CPU), over many scales, zeros included."""
    rng = np.random.default_rng(5)
    for _ in range(3000):
        v = rng.normal(size=rng.integers(2, 4)) * 10.0 ** rng.integers(-8, 3)
        if rng.integers(5) == 0:
            v[rng.integers(len(v))] = 0.0
        expected = np.linalg.norm(v)
        for form in (v, v.tolist(), tuple(v.tolist())):
            assert_agree(norm(form), expected, ulps=2)


def test_hand_velocity_on_floats_is_bit_for_bit_the_array_form():
    """The seen hand velocity (on Python floats) is the array difference over the time between glances, to the bit."""
    rng = np.random.default_rng(6)
    for _ in range(2000):
        before, after = rng.normal(size=3) * 0.3, rng.normal(size=3) * 0.3
        t0 = float(rng.uniform(0, 100))
        t1 = t0 + float(rng.choice([1 / 60, 1 / 62.5, rng.uniform(0, 1)]))
        seen = view(hand=tuple(after), t=t1)
        expected = (seen.hand_pos - before) / (t1 - t0)
        assert np.array_equal(hand_velocity(seen, Memory(last_seen=(t0, before))), expected)
    assert hand_velocity(view(t=2.0), Memory()) == (0.0, 0.0, 0.0)
    assert hand_velocity(view(t=2.0), Memory(last_seen=(2.0, np.ones(3)))) == (0.0, 0.0, 0.0)  # no time has passed


def test_updated_memory_is_dataclasses_replace():
    """_updated (Memory's fields set at once) gives what dataclasses.replace gives: equal, frozen, the
    others' fields untouched."""
    memory = Memory(axis=2, touch_since=1.5, missed_faces=(1, 0.5), controls=Controls(TWO_AXIS, ("B1",)))
    changes = dict(axis=0, descending=True, last_seen=(3.0, np.zeros(3)), stalled=True)
    updated = _updated(memory, **changes)
    assert type(updated) is Memory and vars(updated) == vars(replace(memory, **changes))
    assert updated.axis == 0 and memory.axis == 2 and updated.controls is memory.controls
    with pytest.raises(AttributeError):
        updated.axis = 1
