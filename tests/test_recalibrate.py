"""Recalibration as a recovery (tasks/operators/recovery.py, ``BomiChannel.begin_recalibration``): the
action parses, is chosen by its rule on hand-made spans, and in a BoMI episode runs with the arm at
rest, its time counted, and a retrained classifier in the chain afterwards."""
from __future__ import annotations

import numpy as np
import pytest

from bomi.classifier import NEUTRAL_LABEL
from bomi.frames import SAMPLE_PERIOD_S
from bomi.fusion import WARMUP_S
from sim.joystick import JoystickState, Mode
from tasks.experiments.jobs import EpisodeJob, run_job
from tasks.operators.params import RecoveryParams, parse_recovery_actions
from tasks.operators.recovery import Supervisor, choose
from tasks.stacking.channels import calibrated_channel, calibration_order
from tasks.stacking.summary import summarize
from tasks.stacking.vocabulary import Goal, RecoveryAction, StickIntent, View

REZERO, BACKOFF, PAUSE, RECALIBRATE = (RecoveryAction.REZERO, RecoveryAction.BACKOFF, RecoveryAction.PAUSE,
                                       RecoveryAction.RECALIBRATE)
DT = 0.5  # s a tick of the hand-built traces


def test_the_action_parses():
    assert parse_recovery_actions("recalibrate", "--recovery") == frozenset({RECALIBRATE})
    assert parse_recovery_actions("rezero, recalibrate", "") == frozenset({REZERO, RECALIBRATE})
    assert RecoveryParams(frozenset({RECALIBRATE, PAUSE})).label == "pause+recalibrate"
    known = "rezero, backoff, pause, recalibrate"
    with pytest.raises(ValueError, match=f"--recovery: recalibrat is not none or a comma list of {known}"):
        parse_recovery_actions("recalibrat,", "--recovery")


def test_chosen_when_the_interface_is_at_fault_and_a_rezero_did_not_help():
    both, alone = frozenset({REZERO, RECALIBRATE, PAUSE}), frozenset({RECALIBRATE})
    assert choose(both, obeyed=0.2, obeyed_share=0.5, retry=False) == (REZERO,)  # the cheap fix first
    assert choose(both, obeyed=0.2, obeyed_share=0.5, retry=True, made=frozenset({REZERO})) == (PAUSE, RECALIBRATE)
    assert choose(both, obeyed=0.2, obeyed_share=0.5, retry=True, made=frozenset({BACKOFF})) == (PAUSE, REZERO)
    assert choose(alone, obeyed=0.2, obeyed_share=0.5, retry=False) == (RECALIBRATE,)  # no rezero: the fix
    assert choose(alone, obeyed=0.9, obeyed_share=0.5, retry=False) == ()  # the arm answered: not the interface
    assert choose(alone, obeyed=None, obeyed_share=0.5, retry=False) == ()  # nothing asked: not the interface
    # once per span: a fresh classifier that did not help is not retrained again
    assert choose(alone, obeyed=0.2, obeyed_share=0.5, retry=True, made=frozenset({RECALIBRATE})) == ()
    assert choose(frozenset({REZERO, PAUSE}), obeyed=0.2, obeyed_share=0.5, retry=True,
                  made=frozenset({REZERO})) == (PAUSE, REZERO)  # without recalibrate: as before


class FakeUser:
    def __init__(self):
        self.calls: list[tuple[str, float]] = []

    def stick_intent(self, view: View) -> StickIntent:
        return StickIntent({"F": 1.0}, goal=Goal("reach cube 1"))

    def resume(self, view: View) -> None:
        self.calls.append(("resume", view.t))

    def back_off(self, view: View) -> None:
        self.calls.append(("back off", view.t))


class FakeChannel:
    """A neutral posture taken over 1 s; a recalibration over ``takes`` s."""

    def __init__(self, takes: float):
        self.takes, self.now, self.rezeroed_at, self.recalibrated_at = takes, 0.0, None, None

    def begin_rezero(self) -> None:
        self.rezeroed_at = self.now

    @property
    def rezeroing(self) -> bool:
        return self.now < self.rezeroed_at + 1.0

    def begin_recalibration(self, t: float) -> None:
        self.recalibrated_at = t

    @property
    def recalibrating(self) -> bool:
        return self.now < self.recalibrated_at + self.takes


def _view(t: float) -> View:
    """The hand still at (0.5, 0, 0.2), cube 1 at the origin: no progress."""
    return View(t=t, hand_pos=np.array([0.5, 0.0, 0.2]), hand_yaw=0.0, hand_tilt=np.zeros(2), closure=0.0,
                mode=Mode.TRANSLATION, cube_pos=(np.array([0.0, 0.0, 0.02]), np.array([0.3, 0.3, 0.02])),
                cube_yaw=(0.0, 0.0), touching=(False, False), target_xy=np.array([-0.3, 0.0]), table_z=0.0,
                cube_size=0.04)


def test_supervisor_rezeroes_then_recalibrates_with_the_arm_stopped():
    user, channel = FakeUser(), FakeChannel(takes=20.0)
    params = RecoveryParams(frozenset({REZERO, RECALIBRATE}), stuck_s=60.0, settle_s=2.0)
    supervisor = Supervisor(params, user, channel, target_pos=np.array([-0.3, 0.0, 0.0]))
    stopped = []
    for k in range(int(250 / DT)):
        channel.now = t = k * DT
        intent = supervisor.intent(_view(t))
        if not supervisor.state(intent, JoystickState({"L": 1.0})).deflection:  # the arm never answers F
            stopped.append(t)
    # 60 s stuck: rezero (2 s still, 1 s neutral) to 63 s; 60 s later still stuck: the rezero did not
    # help: recalibrate at 123 s, 20 s of session, done on the tick it is over (143 s); 60 s later: nothing more
    assert [(e.action, e.start_s, e.end_s) for e in supervisor.events] == [(REZERO, 60.0, 63.0),
                                                                           (RECALIBRATE, 123.0, 143.0)]
    assert channel.recalibrated_at == 123.0 and user.calls == [("resume", 63.0), ("resume", 143.0)]
    assert stopped == [60.0 + DT * k for k in range(6)] + [123.0 + DT * k for k in range(40)]


def test_the_participant_performs_the_protocol_and_the_chain_gets_a_retrained_classifier():
    channel = calibrated_channel("P4", 3)
    old, params = channel.chain.model, channel.participant.params
    rest, tick = StickIntent(goal=Goal("recalibrate")), 1 / 60
    t = 0.0
    while t < 2.0:
        channel.command(StickIntent({"F": 1.0}), t, t + tick)
        t += tick
    channel.begin_recalibration(t)
    start = t
    while channel.recalibrating:
        channel.command(rest, t, t + tick)
        t += tick
    # 12 s of the recording's settling (after at most a counter cycle of 4.1 s), 5 s of neutral, then
    # each of the 9 motions and the neutral after it reached (reaction + onset, 1.5 s) and held 5 s
    settle = params.reaction_s + params.onset_s
    least = WARMUP_S + 5.0 + 9 * 2 * (settle + 5.0)
    assert least <= t - start <= least + 256 * SAMPLE_PERIOD_S + 2 * tick
    assert channel.chain is channel.receiver.chain and channel.chain.model is not old
    assert channel.chain.model.classes.tolist() == old.classes.tolist()
    assert not np.allclose(channel.chain.model.coef, old.coef)  # trained on other samples: another LDA
    # the participant's own clock ran on through the session: it performed the protocol's classes then
    truth = channel.participant.truth()
    during = (truth.time_s >= channel.clock_offset + start) & (truth.time_s < channel.clock_offset + t)
    performed = truth.intent[during]
    changes = performed[np.r_[True, performed[1:] != performed[:-1]]]
    motions = [label for label, _ in calibration_order(params, channel.profile, repetitions=1)]
    forward = channel.intent_class(StickIntent({"F": 1.0}))[0]  # held as the session began, until its first cue
    assert [c for c in changes if c != NEUTRAL_LABEL] == [forward, *motions]
    # after it, the person's intent drives the body again and the new chain decides
    for _ in range(int(3.0 / tick)):
        channel.command(StickIntent({"F": 1.0}), t, t + tick)
        t += tick
    assert channel.participant.intent[0] == forward
    assert channel._rows[-1][0] * SAMPLE_PERIOD_S > channel.clock_offset + t - 1.0


@pytest.mark.long
def test_an_episode_recalibrates_with_the_arm_at_rest_and_the_clock_running():
    overrides = (("operator.recovery.actions", "recalibrate"), ("operator.recovery.stuck_s", 3.0),
                 ("operator.recovery.obeyed_share", 1.0))
    # P4 seed 0: its first seconds disobey (a stick move the arm does not answer), so the rule fires early
    log = run_job(EpisodeJob("bomi", "P4", 0, time_limit=150.0, overrides=overrides))
    assert summarize(log)["recovery"] == "recalibrate"
    events = [e for e in log.recoveries if e.action is RECALIBRATE]
    assert events and all(e.action is RECALIBRATE for e in log.recoveries)
    event = events[0]
    assert event.end_s - event.start_s > WARMUP_S + 5.0 + 9 * 10.0  # the session's time counted
    inside = (log.t >= event.start_s) & (log.t < event.end_s)
    assert not log.commanded[inside].any() and set(np.array(log.goals)[inside]) == {"recalibrate"}
