"""The virtual participant's feel for proportional control: how far to lean for how fast, how the
lean is corrected while watching the arm, and the calibration order that makes nu span the leans."""
import dataclasses

import numpy as np
import pytest

from bomi.chain import OnlineChain, train
from bomi.classifier import PostProcessing
from sim.joystick import Mode
from tasks.stacking.channels import BomiChannel, LeanFeel, calibration_order
from tasks.participants.participant import VirtualParticipant, calibration_session, load_participant, session_recording
from tasks.stacking.vocabulary import StickIntent
from tasks.operators.stick import arm_profile

SEED = 4
TICK = 1 / 60
FEEL = load_participant("P1").feel


def test_the_feel_asks_more_lean_for_more_speed_within_the_calibrated_range():
    feel = LeanFeel(FEEL)
    leans = [feel.lean_for(d) for d in np.linspace(0.0, 1.0, 11)]
    assert all(b >= a for a, b in zip(leans, leans[1:]))  # faster never asks less lean
    assert leans[-1] == pytest.approx(FEEL.most_lean)  # full speed: the furthest lean
    assert min(leans) >= FEEL.least_lean  # never below the least lean the classifier was calibrated on
    assert leans[5] > leans[0]  # the lean does depend on the speed wanted


def test_a_lean_that_worked_is_where_the_next_move_of_that_class_starts():
    feel = LeanFeel(FEEL)
    feel.learn(lean=0.9, deflection=0.3)
    assert feel.lean_for(0.3) == pytest.approx(0.9)  # the next move for 0.3 starts from 0.9
    assert feel.lean_for(0.6) > 0.9 and feel.lean_for(1.0) == pytest.approx(FEEL.most_lean)
    feel.learn(lean=FEEL.most_lean, deflection=0.0)  # had to lean fully even for the least speed
    assert feel.lean_for(0.05) < FEEL.most_lean  # the least deflection never needs the whole range
    before = feel.lean_for(0.3)
    feel.learn(lean=0.6, deflection=1.0)  # a full-speed move says nothing about slower ones
    assert feel.lean_for(0.3) == before


@pytest.fixture(scope="module")
def p1_model():
    params = load_participant("P1")
    profile = arm_profile(params.profile)
    session = calibration_session(params, profile, SEED, order=calibration_order(params, profile))
    return params, profile, session, train([session_recording(session, profile)], profile,
                                           post=PostProcessing(vote_length=5))


def test_calibration_holds_proportional_classes_at_both_ends_of_the_leans_and_buttons_at_full(p1_model):
    params, profile, session, _ = p1_model
    functions = {cls.label: cls.function for cls in profile.classes}
    held = session.holding & session.recorded & (session.cue != 0)
    for label in params.classes:
        amplitudes = set(np.round(session.truth.amplitude[held & (session.cue == label)], 3))
        if functions[label] in ("B1", "B2"):
            assert amplitudes == {1.0}, functions[label]  # pressed at full range only
        else:
            assert amplitudes == {FEEL.least_lean, FEEL.most_lean}, functions[label]


def test_nu_spans_the_leans_the_task_uses(p1_model):
    """Trained on that order, the least lean (asked for the slowest moves) gives a small but non-zero
    nu and a full lean a nu near 1: the leans the participant uses cover the proportional range."""
    params, profile, _, model = p1_model
    channel = BomiChannel(VirtualParticipant(params, profile, SEED + 2), OnlineChain(model, profile), profile)
    t = 0.0
    for deflection, hold in ((0.0, 2.5), (None, 3.0), (1.0, 2.5), (None, 3.0)):  # no lean correction within 2.5 s
        for _ in range(int(hold / TICK)):
            channel.command(StickIntent() if deflection is None else StickIntent({"F": deflection}), t, t + TICK)
            t += TICK
    trace = channel.log_fields()["decisions"]
    forward = next(cls.label for cls in profile.classes if cls.function == "F")
    held = (trace.intended == forward) & (trace.decided == forward)
    half, full = held & (trace.t < 3.0), held & (trace.t > 5.5)
    assert half.sum() > 30 and full.sum() > 30  # both leans are recognised as F
    assert 0.05 < np.median(trace.nu[half]) < 0.6 and np.median(trace.nu[full]) > 0.8


# what the person sees of the hand (move, then turn about the vertical: sources.seen_velocity) when it
# answers F in translation (-y, the layout's table) and Rr in the wrist mode (a turn about +z)
SEEN_ALONG = {("F", Mode.TRANSLATION): np.array([0.0, -1.0, 0.0, 0.0, 0.0, 0.0]),
              ("Rr", Mode.WRIST): np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0])}


def _correction(model, params, profile, seen_ratio: float | None, seconds: float = 5.0,
                function: str = "F", mode: Mode = Mode.TRANSLATION) -> list[float]:
    """The lean the participant holds while wanting ``function`` at 0.3 in ``mode`` and seeing the hand go
    ``seen_ratio`` times that speed along it (None: the arm does not move at all), sampled every tick."""
    channel = BomiChannel(VirtualParticipant(params, profile, SEED + 2), OnlineChain(model, profile), profile)
    wanted = 0.3
    seen = SEEN_ALONG[function, mode] * (0.0 if seen_ratio is None else seen_ratio * wanted)
    leans, t = [], 0.0
    for _ in range(int(seconds / TICK)):
        channel.command(StickIntent({function: wanted}), t, t + TICK, seen, mode)
        leans.append(channel.participant.intent[1])
        t += TICK
    return leans


def test_the_participant_leans_further_when_the_arm_is_too_slow_and_less_when_too_fast(p1_model):
    params, profile, _, model = p1_model
    start = LeanFeel(FEEL).lean_for(0.3)
    patience = params.reaction_s + params.onset_s + 1.0  # a correction is given time to work
    still = _correction(model, params, profile, None)
    assert still[0] == pytest.approx(start)
    assert max(still[:int(patience / TICK)]) == pytest.approx(start)  # no correction before the patience
    assert still[-1] > start  # the arm does not move: lean further
    fast = _correction(model, params, profile, 3.0)
    assert fast[-1] < start  # three times too fast: lean less
    right = _correction(model, params, profile, 1.0)
    assert np.allclose(right, start)  # the wanted speed: keep the lean


def test_a_wrist_turn_seen_crawling_is_leant_into_as_a_slow_move(p1_model):
    """The hand's turn is watched as its move is: a yaw turn answered at a tenth of the wanted speed (the
    lean short of the class's calibrated range, nu near 0) makes the participant lean further; the wanted
    speed keeps the lean; three times too fast, less (before, a turn was judged only by whether the chain
    answered at all, and a crawling turn was held for seconds on end)."""
    params, profile, _, model = p1_model
    start = LeanFeel(FEEL).lean_for(0.3)
    crawl = _correction(model, params, profile, 0.1, function="Rr", mode=Mode.WRIST)
    assert crawl[0] == pytest.approx(start) and crawl[-1] > start
    assert np.allclose(_correction(model, params, profile, 1.0, function="Rr", mode=Mode.WRIST), start)
    assert _correction(model, params, profile, 3.0, function="Rr", mode=Mode.WRIST)[-1] < start


def _let_go_while_the_arm_runs_on(model, params, profile, seen_ratio: float) -> tuple[float, float]:
    """The lean of a move of F for 0.3 that the person lets go of as soon as the chain answers it,
    the arm going on at ``seen_ratio`` times that speed for 1.5 s after (the BoMI answers late);
    then the lean of the next move of F for 0.3."""
    channel = BomiChannel(VirtualParticipant(params, profile, SEED + 2), OnlineChain(model, profile), profile)
    axis = SEEN_ALONG["F", Mode.TRANSLATION]
    wanted, t = 0.3, 0.0
    while channel.stick.function != "F":
        assert t < 5.0, "the chain never answered F"
        channel.command(StickIntent({"F": wanted}), t, t + TICK, np.zeros(6), Mode.TRANSLATION)
        t += TICK
    first = channel.participant.intent[1]
    for _ in range(int(1.5 / TICK)):  # let go; the arm still answers the posture
        channel.command(StickIntent(), t, t + TICK, axis * seen_ratio * wanted, Mode.TRANSLATION)
        t += TICK
    channel.command(StickIntent({"F": wanted}), t, t + TICK, np.zeros(6), Mode.TRANSLATION)
    return first, channel.participant.intent[1]


def test_a_move_that_ran_on_much_too_fast_after_letting_go_makes_the_next_one_lean_less(p1_model):
    params, profile, _, model = p1_model
    first, after_overshoot = _let_go_while_the_arm_runs_on(model, params, profile, 4.0)
    assert after_overshoot < first  # the arm overshot at four times the wanted speed: lean less next time
    first, after_right = _let_go_while_the_arm_runs_on(model, params, profile, 1.0)
    assert after_right == pytest.approx(first)  # it went at the wanted speed: nothing to learn


def test_a_twin_that_leans_past_its_posture_uses_its_whole_range():
    """A twin whose recording's holds reach most_lean = 1.4 of the class posture: full speed asks that
    far, corrections stop there, a learnt zero keeps lean_for(d) the lean that worked, and the
    calibration holds both ends of that range (hand values)."""
    feel = LeanFeel(dataclasses.replace(FEEL, least_lean=0.4, most_lean=1.4))
    assert feel.lean_for(0.0) == pytest.approx(0.4) and feel.lean_for(1.0) == pytest.approx(1.4)
    assert feel.lean_for(0.5) == pytest.approx(0.4 + (1.4 - 0.4) * 0.5)
    assert feel.corrected(1.35, further=True) == pytest.approx(1.4)
    feel.learn(lean=1.0, deflection=0.5)  # zero = (1.0 - 1.4 x 0.5) / 0.5 = 0.6
    assert feel.zero == pytest.approx(0.6) and feel.lean_for(0.5) == pytest.approx(1.0)


def _gone_through(channel, intents: list[tuple[StickIntent, float]]) -> None:
    t = 0.0
    for intent, hold in intents:
        for _ in range(int(hold / TICK)):
            channel.command(intent, t, t + TICK)
            t += TICK


def test_from_one_motion_into_the_next_the_body_goes_through_rest_and_dwells_there(p1_model):
    """Asked for L straight after F, the body first returns to rest; the move to L begins no earlier
    than a reaction time after the return has ended (the psychological refractory period)."""
    params, profile, _, model = p1_model
    params = dataclasses.replace(params, reaction_sd_s=0.0, onset_sd_s=0.0)
    channel = BomiChannel(VirtualParticipant(params, profile, SEED + 2), OnlineChain(model, profile), profile)
    _gone_through(channel, [(StickIntent({"F": 1.0}), 3.0), (StickIntent({"L": 1.0}), 4.0)])
    moves = channel.participant.moves
    labels = [m.label for m in moves]
    label_of = {cls.function: cls.label for cls in profile.classes}
    assert labels == [0, label_of["F"], 0, label_of["L"]]
    back, onward = moves[2], moves[3]
    assert onward.t0 >= back.t0 + back.duration + params.reaction_s - 1e-9
    assert onward.t0 == pytest.approx(back.t0 + back.duration + params.reaction_s, abs=2 * TICK)


def test_a_lean_the_arm_never_answers_is_let_go_of_and_tried_again(p1_model):
    """At its furthest lean with the chain not answering (the body's F posture is the neutral one
    today: the chain reads neutral), the participant relaxes to rest after give_up_s and leans again."""
    params, profile, _, model = p1_model
    forward = next(cls.label for cls in profile.classes if cls.function == "F")
    motion = params.classes[forward]
    numb = dataclasses.replace(motion, posture_deg=np.zeros_like(motion.posture_deg), day_gain_log_std=0.0,
                               day_std_deg=np.zeros_like(motion.day_std_deg))
    params = dataclasses.replace(params, reaction_sd_s=0.0, onset_sd_s=0.0, classes={**params.classes, forward: numb})
    channel = BomiChannel(VirtualParticipant(params, profile, SEED + 2), OnlineChain(model, profile), profile)
    _gone_through(channel, [(StickIntent({"F": 1.0}), 30.0)])
    moves = channel.participant.moves
    rests = [m for m in moves[1:] if m.label == 0]
    assert rests, "never let go of an unanswered lean"
    first_full = next(m for m in moves if m.label == forward and m.amplitude == params.feel.most_lean)
    assert rests[0].t0 >= first_full.t0 + params.feel.give_up_s  # held the full lean give_up_s first
    assert moves[-1].label == forward or moves[-2].label == forward  # and tried again


def test_a_function_decided_at_no_speed_is_no_answer_the_person_sees(p1_model):
    """The person watches the arm, not the chain: the class's function decided at nu 0 leaves the arm
    still, so a lean held at its furthest is let go of after give_up_s as if the chain read rest."""
    params, profile, _, model = p1_model
    channel = BomiChannel(VirtualParticipant(params, profile, SEED + 2), OnlineChain(model, profile), profile)
    forward = next(cls.label for cls in profile.classes if cls.function == "F")
    furthest = params.feel.most_lean
    channel.stick.function, channel.stick.nu = "F", 0.0
    assert not channel._arm_answers(forward)
    assert not channel._gives_up(forward, furthest, 10.0)                          # unanswered from now ...
    assert channel._gives_up(forward, furthest, 10.0 + params.feel.give_up_s)      # ... let go of give_up_s on
    channel.stick.nu = 0.2
    assert channel._arm_answers(forward) and not channel._gives_up(forward, furthest, 30.0)
    channel.stick.function = "B"
    assert not channel._arm_answers(forward)


def test_a_learnt_zero_stays_below_max_zero_of_the_furthest_lean():
    """A twin leaning past its posture (most_lean 1.246): the bound on the learnt zero scales with it."""
    feel = LeanFeel(FEEL)
    feel.learn(lean=FEEL.most_lean, deflection=0.0)
    assert FEEL.most_lean == 1.246 and feel.zero == pytest.approx(FEEL.max_zero * 1.246)
