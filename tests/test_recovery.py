"""The recovery a session has (tasks/operators/recovery.py): the choice of action, the stuck clock, and the
supervisor on hand-built traces (a fake person and channel, views built by hand)."""
from __future__ import annotations

import argparse

import numpy as np
import pytest

from bomi.errors import BomiError
from sim.joystick import JoystickState, Mode
from tasks.experiments.jobs import EpisodeJob, run_job
from tasks.experiments.summary import aggregate, comparison
from tasks.cli.task import recovery_option
from tasks.experiments.tables import terminal_table
from tasks.stacking.summary import summarize
from tasks.stacking.failures import mechanism_rows
from tasks.operators.params import RecoveryParams, load_operator
from tasks.stacking.vocabulary import Goal, RecoveryAction, StickIntent, View
from tasks.operators.recovery import StuckClock, Supervisor, choose

REZERO, BACKOFF, PAUSE = RecoveryAction.REZERO, RecoveryAction.BACKOFF, RecoveryAction.PAUSE
ALL = frozenset(RecoveryAction)
DT = 0.5  # s a tick of the hand-built traces


def test_choose_by_what_the_arm_answered():
    assert choose(ALL, obeyed=0.9, obeyed_share=0.5, retry=False) == (BACKOFF,)
    assert choose(ALL, obeyed=0.2, obeyed_share=0.5, retry=False) == (REZERO,)
    assert choose(ALL, obeyed=None, obeyed_share=0.5, retry=False) == (BACKOFF,)  # nothing asked: not the interface
    assert choose(ALL, obeyed=0.2, obeyed_share=0.5, retry=True) == (PAUSE, REZERO)
    assert choose(frozenset({REZERO}), obeyed=0.9, obeyed_share=0.5, retry=False) == ()  # the fix is off
    assert choose(frozenset({PAUSE}), obeyed=0.9, obeyed_share=0.5, retry=False) == (PAUSE,)  # pause stands in
    assert choose(frozenset({PAUSE, BACKOFF}), obeyed=0.9, obeyed_share=0.5, retry=True) == (PAUSE, BACKOFF)


def test_stuck_clock_counts_from_the_last_progress_and_the_moves_answered():
    clock = StuckClock(stuck_s=60.0)
    forward, right = StickIntent({"F": 1.0}), StickIntent({"R": 0.5})
    ticks = [(forward, {"L": 0.5}), (forward, {"F": 0.5}), (forward, {}),  # answered late: answered
             (StickIntent(button="B1"), {}),  # a press is no stick move asked
             (right, {}), (right, {"L": 1.0}),  # never answered
             (forward, {}), (forward, {}), (forward, {"F": 1.0})]  # a new move of F, answered at its end
    for intent, deflection in ticks:
        clock.saw(intent, JoystickState(deflection))
    assert (clock.asked, clock.answered) == (3, 2)
    clock.progress(10.0)
    assert clock.obeyed is None and not clock.due(69.5) and clock.due(70.0) and not clock.retry
    clock.recovered(80.0)
    assert clock.retry and not clock.due(139.5) and clock.due(140.0)


def _view(t: float, hand_x: float) -> View:
    """The hand at (hand_x, 0, 0.2), cube 1 at the origin on a table at z 0 (a 4 cm cube)."""
    return View(t=t, hand_pos=np.array([hand_x, 0.0, 0.2]), hand_yaw=0.0, hand_tilt=np.zeros(2), closure=0.0,
                mode=Mode.TRANSLATION, cube_pos=(np.array([0.0, 0.0, 0.02]), np.array([0.3, 0.3, 0.02])),
                cube_yaw=(0.0, 0.0), touching=(False, False), target_xy=np.array([-0.3, 0.0]), table_z=0.0,
                cube_size=0.04)


class FakeUser:
    """Always pushes F toward cube 1; records what the supervisor asked of it."""

    def __init__(self):
        self.calls: list[tuple[str, float]] = []

    def stick_intent(self, view: View) -> StickIntent:
        return StickIntent({"F": 1.0}, goal=Goal("reach cube 1"))

    def resume(self, view: View) -> None:
        self.calls.append(("resume", view.t))

    def back_off(self, view: View) -> None:
        self.calls.append(("back off", view.t))


class FakeChannel:
    """A neutral posture taken over ``takes`` s of samples."""

    def __init__(self, takes: float):
        self.takes, self.asked_at, self.now = takes, None, 0.0

    def begin_rezero(self) -> None:
        self.asked_at = self.now

    @property
    def rezeroing(self) -> bool:
        return self.now < self.asked_at + self.takes


def _run(actions, hand_x, answered: bool, seconds: float, channel: FakeChannel | None = None):
    """The supervisor over a trace with the hand at ``hand_x(t)``; the stick answers F, or L instead."""
    user, channel = FakeUser(), channel or FakeChannel(takes=1.0)
    params = RecoveryParams(frozenset(actions), stuck_s=60.0, settle_s=2.0, pause_s=30.0)
    supervisor = Supervisor(params, user, channel, target_pos=np.array([-0.3, 0.0, 0.0]))
    stopped = []
    for k in range(int(seconds / DT)):
        t = k * DT
        channel.now = t
        intent = supervisor.intent(_view(t, hand_x(t)))
        state = supervisor.state(intent, JoystickState({"F" if answered else "L": 1.0}))
        if not state.deflection:
            stopped.append(t)
    return supervisor, user, stopped


def test_no_trigger_while_the_hand_keeps_getting_closer():
    # 3 cm closer every 10 s: progress (2 cm) at least every 10 s, never 60 s without
    supervisor, user, stopped = _run(ALL, lambda t: 0.5 - 0.003 * t, answered=True, seconds=150)
    assert supervisor.events == [] and user.calls == [] and stopped == []


def test_stuck_with_the_arm_answering_backs_off_at_once():
    supervisor, user, stopped = _run(ALL, lambda t: 0.5, answered=True, seconds=100)
    assert [(e.action, e.start_s, e.end_s, e.obeyed) for e in supervisor.events] == [(BACKOFF, 60.0, 60.0, 1.0)]
    assert user.calls == [("back off", 60.0)] and stopped == []  # the lift is the user's own move


def test_stuck_with_the_arm_not_answering_rezeroes_then_pauses_first():
    channel = FakeChannel(takes=1.0)
    supervisor, user, stopped = _run({REZERO, PAUSE}, lambda t: 0.5, answered=False, seconds=200, channel=channel)
    # 60 s stuck: hold still 2 s, the neutral over 1 s, done at 63 s; 60 s later still stuck: a 30 s
    # pause (123-153 s), then the re-zero again (153-156 s)
    assert [(e.action, e.start_s, e.end_s) for e in supervisor.events] == [
        (REZERO, 60.0, 63.0), (PAUSE, 123.0, 153.0), (REZERO, 153.0, 156.0)]
    assert user.calls == [("resume", 63.0), ("resume", 156.0)]  # once after the last of a queue
    assert channel.asked_at == 155.0
    assert stopped[0] == 60.0 and stopped[-1] == 155.5 and len(stopped) == (3 + 30 + 3) / DT


def test_recovery_table_and_option():
    params = load_operator(overrides={"recovery.actions": "rezero, pause", "recovery.stuck_s": 45})
    assert params.recovery.actions == {REZERO, PAUSE} and params.recovery.stuck_s == 45.0
    assert params.recovery.label == "pause+rezero" and load_operator().recovery.label == "none"
    for key, value in (("actions", "rezero,nap"), ("stuck_s", 0), ("obeyed_share", 1.5), ("wait", 1)):
        with pytest.raises(BomiError, match="recovery"):
            load_operator(overrides={f"recovery.{key}": value})
    assert recovery_option("none") == "none"
    with pytest.raises(argparse.ArgumentTypeError, match="an empty list is not none"):
        recovery_option("")


def test_benchmark_rows_and_mechanisms_are_per_recovery_and_the_paper_comparison_without():
    def record(operator, recovery, seed, time):
        return {"participant": "P4", "operator": operator, "layout": "2-axis, B1", "seed": seed,
                "success": time is not None, "completion_time": time, "failure": None if time else "time limit 600 s",
                "mode_switches": 1, "unintended_displacement_mm": 0.0, "cube_drops": 0, "realtime_factor": 10.0,
                "recovery": recovery, "stuck": {"mechanism": "planner stuck"}}
    records = [record("joystick", "none", 0, 50.0), record("bomi", "none", 0, 200.0), record("bomi", "none", 1, None),
               record("bomi", "backoff", 0, 200.0), record("bomi", "backoff", 1, 260.0)]
    rows = aggregate(records)
    assert [(r["operator"], r["recovery"], r["successes"]) for r in rows] == [
        ("bomi", "backoff", 2), ("bomi", "none", 1), ("joystick", "none", 1)]
    assert [c["time_ratio"] for c in comparison(rows)] == [4.0]  # 200 / 50: the rows without recovery
    assert "recovery" in terminal_table(rows).splitlines()[0]
    mechanisms = {r["recovery"]: (r["failed"], r["mechanisms"]["planner stuck"])
                  for r in mechanism_rows(records) if r["operator"] == "bomi"}
    assert mechanisms == {"none": (1, [1]), "backoff": (0, [])}  # 260 s is not over twice the median 230 s


def test_an_episode_pauses_with_the_arm_stopped_and_the_clock_running():
    """The one episode (joystick, 6 s of task): a pause after 1 s without progress."""
    overrides = (("operator.recovery.actions", "pause"), ("operator.recovery.stuck_s", 1.0),
                 ("operator.recovery.pause_s", 1.0))
    log = run_job(EpisodeJob("joystick", "P1", 0, time_limit=6.0, overrides=overrides))
    record = summarize(log)
    assert record["recovery"] == "pause" and len(record["recoveries"]) == len(log.recoveries) >= 1
    for event in log.recoveries:
        assert event.action is PAUSE and event.end_s - event.start_s == pytest.approx(1.0, abs=1 / 60)
        inside = (log.t >= event.start_s) & (log.t < event.end_s)
        assert not log.commanded[inside].any() and set(np.array(log.goals)[inside]) == {"pause"}
    assert log.t[-1] >= 5.9  # the pauses took task time: the episode ran to its limit
