"""A person with no class left for a mode button (four motions: the 2-axis layout's directions): the
scripted user rests and waits for the automatic mode switching, which reads a rest held on as a
refusal of the arm's mode (docs/task.md, "Without a mode button"); with three motions, the 1-axis
layout (F/B) and B1."""
import numpy as np
import pytest

from bomi.derived import derive_profile
from bomi.errors import BomiError
from sim.joystick import ONE_AXIS, TWO_AXIS, JoystickState, Mode
from tasks.operators.assist import Assist, Assistance, load_assist, presses
from tasks.experiments.jobs import EpisodeJob, job_assist
from tasks.stacking.channels import JoystickChannel, profile_controls
from tasks.stacking.episode import process_arm, run_episode
from tasks.stacking.vocabulary import Controls
from tasks.operators.planner import ScriptedUser
from tasks.stacking.task import TaskConfig
from tasks.operators.stick import arm_profile
from test_assist import A1, FakeArm, view
from test_derived_layout import motions

AUTO = frozenset({Assist.AUTO_MODE})
REST_REFUSAL = load_assist().auto_mode.rest_refusal


def test_a_derived_four_motion_profile_gives_the_scripted_user_controls_without_a_button():
    controls = profile_controls(derive_profile([motions(4)]))
    assert controls == Controls(TWO_AXIS, ())
    assert controls.label == "2-axis, no button"


def test_controls_without_a_button_and_without_the_automatic_switching_are_a_one_line_error():
    with pytest.raises(BomiError, match="needs --assist auto-mode") as info:
        run_episode(JoystickChannel(Controls(TWO_AXIS, ())), operator="joystick", participant="any", seed=0)
    assert "\n" not in str(info.value)


def test_the_joystick_baseline_on_controls_without_a_button_gets_the_automatic_switching_too():
    joystick = EpisodeJob("joystick", "any", 0)
    assert job_assist(joystick, derive_profile([motions(4)])) == AUTO
    assert job_assist(joystick, arm_profile("P4")) == frozenset()   # a button: none, as always


def test_without_a_button_a_mode_is_one_automatic_switch_away():
    assert presses(TWO_AXIS, (), Mode.HEIGHT, Mode.HEIGHT) == 0
    assert presses(TWO_AXIS, (), Mode.TRANSLATION, Mode.FINGERS) == 1


def test_a_rest_held_on_refuses_each_offered_mode_in_turn_and_the_round_starts_again():
    assist = Assistance(AUTO, TWO_AXIS, ())
    arm = FakeArm(Mode.TRANSLATION)
    above = A1 + [0, 0, 0.08]   # over cube 1: the descent (height mode) is the likely next step
    ticks = round((4 * REST_REFUSAL + 1.0) * 60)
    for tick in range(ticks):
        assist.step(view(above, mode=arm.mode, t=tick / 60), JoystickState(), arm)
    offers = [(round(s.t, 2), s.after, s.refused) for s in assist.switches]
    assert offers[0][1] is Mode.HEIGHT   # the automation's best guess first, at once
    # then one mode every rest_refusal, none twice until every other one has been refused
    assert [round(b - a, 2) for (a, _, _), (b, _, _) in zip(offers, offers[1:])] == \
        [pytest.approx(REST_REFUSAL, abs=0.02)] * (len(offers) - 1)
    assert len(offers) == 5 and {mode for _, mode, _ in offers[:4]} == set(TWO_AXIS.modes)
    assert offers[4][1] is Mode.HEIGHT   # every mode refused: the round starts again with the best
    assert all(refused for _, _, refused in offers[:-1])
    assist.step(view(above, mode=arm.mode, t=ticks / 60), JoystickState({"F": 0.5}), arm)  # the user moves: kept
    assert not assist.switches[-1].refused


def test_without_a_button_the_user_rests_until_the_automation_gives_the_mode_the_plan_needs(monkeypatch):
    waits = []   # (t, the arm's mode, the mode the user waits for)
    wanted = ScriptedUser.stick_intent

    def watched(user, seen):
        intent = wanted(user, seen)
        if intent.goal.mode is not None:
            assert intent.is_rest   # no button to press: the user rests
            waits.append((seen.t, seen.mode, intent.goal.mode))
        return intent

    monkeypatch.setattr(ScriptedUser, "stick_intent", watched)
    controls = profile_controls(derive_profile([motions(4)]))
    log = run_episode(JoystickChannel(controls), operator="joystick", participant="any", seed=5,
                      task_config=TaskConfig(time_limit=12.0), assist=AUTO)
    arm = process_arm(TWO_AXIS)
    assert log.presses == arm.button_presses == 0
    assert arm.automatic_switches == len(log.automatic) >= 2
    assert waits, "the plan never needed another mode"
    bound = (len(TWO_AXIS.modes) - 1) * REST_REFUSAL + 0.2   # a round of refusals
    for t, mode, need in waits:
        if t < log.t[-1] - bound:   # each wait ends with the arm in the mode waited for, within a round
            given = next(s for s in log.automatic if s.t > t and s.after is need)
            assert given.t - t <= bound and not given.refused
    ends = [s.tick for s in log.automatic[1:]] + [len(log.t)]
    for s, end in zip(log.automatic, ends):   # refused: the user rested on in its mode, waiting for another
        pushed = log.pushing[s.tick + 1:end].any()
        waited = {need for t, _, need in waits if s.t < t < log.t[end - 1]}
        assert s.refused == (not pushed and s.after not in waited and end - s.tick > REST_REFUSAL * 60)
    # the user pushes in the modes the automation gave them: the hand was moved with no press at all
    moved = np.linalg.norm(log.hand_pos[-1] - log.hand_pos[0])
    assert moved > 0.02 and log.pushing.any()


def test_with_three_motions_the_user_presses_b1_round_the_one_axis_layouts_five_modes():
    controls = profile_controls(derive_profile([motions(3)]))
    assert controls == Controls(ONE_AXIS, ("B1",))
    log = run_episode(JoystickChannel(controls), operator="joystick", participant="any", seed=5,
                      task_config=TaskConfig(time_limit=10.0))
    assert log.presses >= 2 and not log.automatic
    seen = set(log.mode)
    assert {Mode.TRANSLATION.value, Mode.SIDEWAYS.value} <= seen   # the x moves have a mode of their own
    assert np.ptp(log.hand_pos[:, 0]) > 0.01 and np.ptp(log.hand_pos[:, 1]) > 0.01
