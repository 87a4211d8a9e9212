"""The human operator model: perception noise, choice and movement times, wrong-mode slips."""
import math
from dataclasses import replace

import numpy as np
import pytest

from bomi.errors import BomiError
from sim.joystick import THREE_AXIS, TRANSLATION_AXES, TWO_AXIS, Mode
from tasks.operators.human import (DEFAULT_HUMAN_FILE, Eyes, HumanOperator, HumanTiming, InterfaceModel, alternatives,
                         choice_time, fitts_time, judgement_error, load_human)
from helpers import assert_one_line_error, benchmark_script
from tasks.stacking.vocabulary import REST, Controls, StickIntent, View
from tasks.operators.judgement import deflection_for, placed_cubes
from tasks.operators.params import load_operator

H = load_human()
P = load_operator()
HALF = 0.025
INTERFACE = InterfaceModel(P.learning_rate, P.full_speed, P.still_speed, P.max_wait)


def view(hand=(-0.14, -0.39, 0.025), mode=Mode.TRANSLATION, t=0.0, closure=0.0) -> View:
    return View(t=t, hand_pos=np.array(hand, float), hand_yaw=0.0, hand_tilt=np.zeros(2), closure=closure, mode=mode,
                cube_pos=(np.array([-0.14, -0.39, HALF]), np.array([-0.14, -0.51, HALF])), cube_yaw=(0.0, 0.0),
                touching=(False, False), target_xy=np.array([0.14, -0.45]), table_z=0.0, cube_size=2 * HALF)


def test_judged_position_is_worse_in_depth_than_across_by_the_configured_ratio():
    rng = np.random.default_rng(0)
    hand, distance = np.array([0.1, -0.45, 0.1]), 0.2
    errors = np.array([judgement_error(H, hand, distance, rng) for _ in range(20000)])
    sight = (hand - H.eye) / np.linalg.norm(hand - H.eye)
    depth = errors @ sight
    across = errors - np.outer(depth, sight)
    lateral_std = math.sqrt(np.mean(np.sum(across ** 2, axis=1)) / 2)  # two axes across the line of sight
    expected = H.lateral_floor + H.lateral_weber * distance  # hand-computed: 2 mm + 3 % of 20 cm = 8 mm
    assert lateral_std == pytest.approx(expected, rel=0.03)
    assert np.std(depth) / lateral_std == pytest.approx(H.depth_ratio, rel=0.03)


def test_a_cube_resting_on_the_table_at_b_is_seen_resting_there_from_afar():
    # dev seed 105, P1 BoMI: cube 1 on the table at B, the hand 30 cm away over cube 2; the table was seen where it
    # is while the cubes and B carried the judgement error (its height too), so a third of the looks from there
    # saw cube 1 floating or sunk (not placed) and the person set off back to it, 20 s there and back.  The table
    # is a landmark like B, which lies on it: it shares the error, and resting on it is seen as it is.
    b = np.array([0.14, -0.45])
    scene = replace(view(hand=(-0.14, -0.51, 0.17)), cube_pos=(np.r_[b + 0.01, HALF], np.array([-0.14, -0.51, HALF])))
    assert placed_cubes(scene, P) == (0, None)
    eyes = Eyes(H, np.random.default_rng(0))
    heights = []
    for k in range(200):
        eyes.rejudge()
        seen = eyes.see(replace(scene, t=k * 1.0))
        heights.append(seen.cube_pos[0][2] - scene.cube_pos[0][2])
        assert placed_cubes(seen, P) == (0, None)
        assert seen.cube_pos[0][2] - seen.table_z == pytest.approx(HALF)
    assert np.mean(np.abs(heights) > P.placed) > 0.05  # the judged heights are off by more than `placed` often


def test_choice_time_grows_with_alternatives_as_hick_hyman():
    rng = np.random.default_rng(1)
    mean = {n: np.mean([choice_time(H, n, rng) for _ in range(20000)]) for n in (1, 3, 7)}
    # ex-Gaussian mean = mu + tau; Hick-Hyman adds slope x log2(n + 1): 1, 2 and 3 bits
    for n, bits in ((1, 1), (3, 2), (7, 3)):
        assert mean[n] == pytest.approx(H.rt_mu + H.rt_tau + H.hick_slope * bits, abs=0.004)
    assert mean[1] < mean[3] < mean[7]


def test_alternatives_are_the_commands_of_the_interface_in_the_mode():
    assert alternatives(Controls(THREE_AXIS), Mode.TRANSLATION) == 8  # six directions, two buttons
    assert alternatives(Controls(THREE_AXIS), Mode.FINGERS) == 4  # close, open, two buttons
    assert alternatives(Controls(TWO_AXIS, ("B1",)), Mode.TRANSLATION) == 5


def test_body_reaction_is_not_counted_twice():
    """A channel whose body adds reaction_s after the intent gets the person's reaction minus that."""
    draws = {}
    for body in (0.0, 0.4):
        timing = HumanTiming(replace(H, rt_sigma=1e-6, rt_tau=1e-6), np.random.default_rng(2), INTERFACE,
                             body_reaction=body)
        draws[body] = timing.reaction(view(), REST, frozenset(), Controls())
    assert draws[0.0] - draws[0.4] == pytest.approx(0.4, abs=1e-4)


def test_an_approach_paced_by_the_human_takes_fitts_time():
    """Speed = remaining distance / (fitts_slope / ln 2), stepped at 60 Hz, from D to within W/2."""
    timing = HumanTiming(H, np.random.default_rng(3), INTERFACE)
    fine = replace(P, fine=1e-4)
    for distance in (0.05, 0.2):
        d, t, dt = distance, 0.0, 1 / 60
        while d > P.stop:
            d -= deflection_for(d, fine, anticipation=1e-3, pace=timing.pace) * P.full_speed * dt
            t += dt
        # hand-computed: (b / ln 2) ln(D / (W/2)) = b log2(2D / W), W = 2 stop
        assert t == pytest.approx(H.fitts_slope * math.log2(distance / P.stop), rel=0.03)
        assert t == pytest.approx(fitts_time(H, distance, 2 * P.stop), rel=0.03)


def _slipping_operator(**changes) -> HumanOperator:
    human = replace(H, wrong_mode_rate=1.0, visual_delay=0.0, lateral_floor=0.0, lateral_weber=0.0, **changes)
    return HumanOperator(human, P, combine_axes=True, controls=Controls(), seed=0)


def test_a_wrong_mode_command_is_noticed_and_corrected():
    """At the grasp point in translation mode the person wants the finger mode; the press is
    forgotten, so they push 'close' (F), which in translation mode moves the hand along y-.  Once
    they see the hand move they stop, bring it back and make the press."""
    person = _slipping_operator()
    start = np.array([-0.14, -0.39, 0.025])
    hand, pushed, pressed = start.copy(), [], []
    for tick in range(900):
        t = tick / 60
        intent = person.stick_intent(view(hand=tuple(hand), t=t))
        for fn, deflection in intent.deflection.items():  # the arm obeys its true mode: translation
            hand = hand + np.array(TRANSLATION_AXES[fn]) * P.full_speed * deflection / 60
        if "F" in intent.deflection and not pressed:
            pushed.append((t, np.linalg.norm(hand - start)))
        if intent.button is not None:
            pressed.append(t)
            break
    assert pushed, "the forgotten press is followed by a push as if in the finger mode"
    assert len(person.slips) == 1 and person.slips[0][1] > person.slips[0][0]
    assert max(d for _, d in pushed) < 0.03  # noticed within a few centimetres ...
    assert pressed and pressed[0] > person.slips[0][1]  # ... and the press made after noticing
    assert np.linalg.norm(hand[:2] - start[:2]) <= 2 * P.align  # back over the cube


def test_a_wrong_mode_command_the_arm_ignores_is_noticed_after_the_timeout():
    person = _slipping_operator()
    pushed, pressed = [], []
    for tick in range(600):
        t = tick / 60
        intent = person.stick_intent(view(t=t))  # the arm never moves
        if intent.deflection:
            pushed.append(t)
        if intent.button is not None:
            pressed.append(t)
            break
    assert pushed and pressed and pressed[0] - pushed[0] >= H.notice_timeout


@pytest.mark.parametrize("text, fault", [
    ("", "[perception] section missing"),
    ("rate", "[slips] wrong_mode_rate: must be in [0, 1], got 1.5"),
    ("eye", "[perception] eye: expected 3 values, got 2"),
    ("unknown", "[timing] unknown key(s) ['wobble']"),
])
def test_bad_human_file_is_one_clear_error(tmp_path, text, fault):
    good = DEFAULT_HUMAN_FILE.read_text()
    content = {"rate": good.replace("wrong_mode_rate = 0.10", "wrong_mode_rate = 1.5"),
               "eye": good.replace("eye = [0.0, 0.30, 0.45]", "eye = [0.0, 0.30]"),
               "unknown": good.replace("[timing]\n", "[timing]\nwobble = 1\n")}.get(text, text)
    assert_one_line_error(load_human, tmp_path / "human.toml", content, fault)


def test_the_operator_file_names_the_human_model(tmp_path):
    from tasks.stacking.channels import JoystickChannel
    from tasks.stacking.sources import operator_user
    from tasks.operators.params import DEFAULT_OPERATOR_FILE
    from tasks.operators.planner import ScriptedUser
    assert isinstance(operator_user(P, JoystickChannel(), seed=0), ScriptedUser)  # model = "none"
    humane = load_operator(DEFAULT_OPERATOR_FILE, {"human.model": "human"})
    person = operator_user(humane, JoystickChannel(), seed=0)
    assert isinstance(person, HumanOperator) and person.params.fitts_slope == H.fitts_slope
    path = tmp_path / "op.toml"
    path.write_text(DEFAULT_OPERATOR_FILE.read_text().replace('model = "none"', "model = 3"))
    with pytest.raises(BomiError, match=r"\[human\] model: expected a string, got 3"):
        load_operator(path)


def test_phase_times_follow_the_steps():
    from tasks.stacking.metrics import phase_times
    steps = (["reach cube 1"] * 3 + ["grasp cube 1"] * 2 + ["carry cube 1"] * 5 + ["release cube 1"]
             + ["level the hand"])
    assert phase_times(steps, 0.5) == {"reach": 1.5, "grasp": 1.0, "carry": 2.5, "place": 0.0, "release": 0.5,
                                       "other": 0.5}
    assert phase_times(steps, 0.5, until=4)["grasp"] == 0.5
    stages = [""] * 5 + ["rise", "travel", "travel", "descend", "descend"] + ["", ""]
    placing = phase_times(steps, 0.5, stages=stages)
    assert placing["carry"] == 1.5 and placing["place"] == 1.0 and sum(placing.values()) == 6.0


def test_mode_switch_time_spans_from_the_last_push_to_the_next():
    from tasks.stacking.metrics import mode_switch_time
    mode = ["translation"] * 5 + ["fingers"] * 5
    pushing = [True, True, False, False, False, False, False, True, True, False]
    # last push before the change at tick 5: tick 1; first after: tick 7 -> ticks 2..6 = 5 ticks
    assert mode_switch_time(mode, pushing, 0.1) == pytest.approx(0.5)
    assert mode_switch_time(["translation"] * 10, pushing, 0.1) == 0.0


def test_the_benchmark_compares_each_bomi_with_the_joystick_on_its_own_controls():
    human_model = benchmark_script("human_model")

    def record(operator, participant, layout, seed):
        return {"operator": operator, "participant": participant, "layout": layout, "seed": seed}
    records = [record("joystick", p, layout, s) for p, layout in (("P1", "3-axis, B1+B2"), ("P4", "2-axis, B1"),
                                                                   ("P5", "2-axis, B1")) for s in (0, 1)]
    records += [record("bomi", "P4", "2-axis, B1", s) for s in (0, 1)]
    groups, reference = human_model.group_records(records)
    # P4 and P5 have the same controls: one joystick row of two episodes, not two rows under two names
    assert {name: len(rs) for name, rs in groups.items()} == {
        "joystick (3-axis, B1+B2)": 2, "joystick (2-axis, B1)": 2, "P4 BoMI": 2}
    assert reference["P4 BoMI"] == "joystick (2-axis, B1)"


def test_the_pushes_benchmark_cuts_pushes_and_scores_travel_pushes_against_the_true_error():
    """Hand-made record: ticks 1-3 pushed along +x, 5-6 along +y, rest between and after; cube 1 10 cm along
    +x from the hand, level with it in y.  Pushes (1, 3) and (5, 6).  The first, scored up to the second's
    start, moved the hand 5 cm of the 10: short (under 60 %); the second pushed along y where the true error
    is 0: needless (under 12 mm); a push that is not a travel is not scored."""
    from types import SimpleNamespace
    human_model = benchmark_script("human_model")
    n = 10
    x, y = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    direction = np.zeros((n, 3))
    direction[1:4], direction[5:7] = x, y
    hand = np.zeros((n, 3))
    hand[4:, 0] = 0.05   # 5 cm along x once the first push is over
    log = SimpleNamespace(t=np.arange(n) * 0.1, completion_time=None, pushing=np.linalg.norm(direction, axis=1) > 0,
                          intended_dir=direction, hand_pos=hand, goals=("reach cube 1",) * n,
                          stages=("travel",) * n, cube_pos=np.tile([[0.1, 0.0, 0.025], [0.3, 0.3, 0.025]], (n, 1, 1)),
                          target_pos=np.array([0.5, 0.5, 0.0]))
    assert human_model.hand_pushes(log) == [(1, 3), (5, 6)]
    assert human_model.travel_outcome(log, 1, 5) == "short"
    assert human_model.travel_outcome(log, 5, 7) == "needless"
    log.stages = ("descend",) * n
    assert human_model.travel_outcome(log, 1, 5) is None


def _reach_through_a_delayed_stick(delay: float, least: float = 0.0, learns: bool = True, seed: int = 4,
                                   seconds: float = 120.0):
    """The person reaches cube 1 through a stick whose every command takes effect ``delay`` s late
    (a dead time, as the BoMI's recognition of a posture and of its release) and never goes slower
    than ``least`` of full speed (as the least lean of a BoMI posture); the hand obeys the
    translation functions at once after it.  Ends at the press for the finger mode (at the grasp).
    ``learns=False``: the person never learns the onset (the interface model's longest onset 0).
    Returns (time of the press or None, the person, the hold of every move of the hand)."""
    person = HumanOperator(replace(H, wrong_mode_rate=0.0), P, combine_axes=False, controls=Controls(), seed=seed)
    if not learns:
        person.interface.max_onset = 0.0
    hand, commands, effective, holds, started = np.array([0.05, -0.28, 0.12]), [], {}, [], None
    for tick in range(int(seconds * 60)):
        t = tick / 60
        intent = person.stick_intent(view(hand=tuple(hand), t=t))
        if intent.button is not None:
            return t, person, holds
        if intent.deflection and person.user.started != started:
            started = person.user.started
            holds.append(person.user.hold)
        commands.append((t + delay, dict(intent.deflection)))
        while commands and commands[0][0] <= t + 1e-9:
            effective = commands.pop(0)[1]
        for fn, deflection in effective.items():
            hand = hand + np.array(TRANSLATION_AXES[fn]) * P.full_speed * max(deflection, least) / 60
    return None, person, holds


def test_through_a_stick_that_answers_at_once_no_move_is_a_pulse():
    t, person, holds = _reach_through_a_delayed_stick(0.0)
    assert t is not None and len(holds) >= 3
    # what the person learns as the onset: the visual delay, a glance and no more
    assert 0 < person.interface.onset < 2 * (H.visual_delay + H.glance_interval)
    assert all(math.isinf(h) for h in holds)


def test_through_a_laggy_stick_the_person_learns_the_lag_and_corrects_by_pulses():
    """A 1 s dead time and a least speed of 30 % (as a BoMI's recognition delay and least lean): the
    hand is seen moving about 1 s after a push, goes on 1 s after letting go, and never slower than
    6 cm/s, so a correction steered by watching overshoots its goal every time.  The person learns
    the onset and the speeds from what they see and makes the small corrections as pulses of the
    length their model predicts, then waits (move-and-wait): they reach the grasp; a person who
    never learns the onset hunts around it for the two minutes."""
    t, person, holds = _reach_through_a_delayed_stick(1.0, least=0.3)
    assert person.interface.onset == pytest.approx(1.0 + H.visual_delay, abs=H.glance_interval + 0.05)
    assert max(person.interface.gain.values()) > 3  # a fine deflection (5 %) went at 30 %: seen as 6x
    assert sum(math.isfinite(h) for h in holds) >= 3
    assert t is not None
    watched, _, watched_holds = _reach_through_a_delayed_stick(1.0, least=0.3, learns=False)
    assert watched is None and len(watched_holds) > len(holds)
    assert all(math.isinf(h) for h in watched_holds)


def test_the_interface_model_learns_how_far_the_answered_pulses_went():
    """``step``: how far the hand went for a pulse it answered, learnt at the learning rate (0.5)
    from 0; a pulse never answered and a move steered by watching teach it nothing."""
    model = InterfaceModel(P.learning_rate, P.full_speed, P.still_speed, P.max_wait)
    down = StickIntent({"Lr": 0.05}, remaining=0.004)  # Lr: the hand down in the 3-axis translation mode
    rest = (-0.14, -0.39, 0.05)

    def glances(start, hold, positions):  # one move begun at ``start``, then the hand at 10 glances a second
        for k, z in enumerate(positions):
            model.observe(view(hand=(rest[0], rest[1], z), t=start + k / 10), down, start, hold, THREE_AXIS)

    glances(0.0, 0.3, [0.05] * 10 + [0.045, 0.04, 0.035, 0.03] + [0.03] * 6)  # answered after 1 s: 2 cm down
    glances(2.0, 0.3, [0.03] * 20)  # begins at rest 2 cm lower: learns from the first; never answered
    assert model.pulse_step == pytest.approx(0.5 * 0.02)
    assert model.answered_hold == pytest.approx(0.5 * 0.3)  # the pulse was over (0.3 s) before it was seen answered
    glances(4.0, math.inf, [0.03, 0.02, 0.01, 0.0] + [0.0] * 16)  # the unanswered pulse teaches no step
    assert model.pulse_step == pytest.approx(0.5 * 0.02)
    assert model.answered_hold == pytest.approx(0.5 * 0.3)  # nor how long a push must be held
    glances(6.0, 0.3, [0.0] * 5)  # the watched move (3 cm) teaches no step either
    assert model.pulse_step == pytest.approx(0.5 * 0.02)
    assert model.answered_hold == pytest.approx(0.5 * 0.15 + 0.5 * 0.1)  # but was seen answered 0.1 s after its start


def test_the_interface_model_learns_the_speed_along_the_push_not_a_misread_motion():
    """A push L (x+ in the 3-axis translation mode) at deflection 0.5, watched: when the hand goes 5 cm/s
    along x, the gain seen is 0.05 / (0.2 x 0.5) = 0.5, learnt at the rate 0.5 from 1: 0.75.  When the
    hand goes as fast along y instead (another class read, a forgotten mode press), the push was not
    answered: the gain stays 1 and no onset is learnt from it (a watched move never answered says nothing)."""
    def run(direction):
        model = InterfaceModel(P.learning_rate, P.full_speed, P.still_speed, P.max_wait)
        push = StickIntent({"L": 0.5}, remaining=0.2)
        hand = np.array([-0.14, -0.39, 0.05])
        for k in range(20):  # still for 0.5 s, then 5 cm/s along ``direction``
            at = hand + max(0, k - 5) * 0.1 * 0.05 * np.asarray(direction)
            model.observe(view(hand=at, t=k / 10), push, 0.0, math.inf, THREE_AXIS)
        model.observe(view(hand=at, t=2.0), StickIntent({"F": 0.5}, remaining=0.2), 2.0, math.inf, THREE_AXIS)
        return model

    answered, misread = run((1.0, 0.0, 0.0)), run((0.0, 1.0, 0.0))
    assert answered.gain["L"] == pytest.approx(0.75)
    assert answered.onset == pytest.approx(0.5 * 0.6)  # first seen moving at the 7th glance (0.6 s)
    assert "L" not in misread.gain and misread.onset == 0.0
