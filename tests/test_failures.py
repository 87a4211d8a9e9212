"""The failure mechanisms' rules on small hand-built records (tasks/stacking/failures.py): progress, the
stuck span, blocked ticks, each rule and its order, which episodes need a mechanism."""
from __future__ import annotations

import numpy as np
import pytest

from tasks.stacking.record import DecisionTrace, EpisodeLog
from tasks.stacking.failures import (Mechanism, Rules, blocked_ticks, classify, longest_gap, mechanism_rows, needs_mechanism,
                            phase_distance, progress_ticks, stuck_period)

DT = 0.1  # s a tick in these records (the rules read the tick from the record)
TARGET = np.array([0.0, -0.5, 0.0])  # B on the table
REST_Z = 0.025  # a cube's centre resting on the table


def test_reach_is_the_hand_to_its_cube_and_carry_the_cube_to_its_place():
    cubes = np.array([[0.3, -0.5, REST_Z], [0.0, -0.5, REST_Z]])  # cube 2 already at B
    hand = np.array([0.3, -0.5, 0.125])
    assert phase_distance("reach 1", hand, cubes, TARGET, REST_Z) == pytest.approx(0.1)
    # carried cube 1 goes on cube 2: its centre a cube's height (0.05) above cube 2's, over B
    assert phase_distance("carry 1", hand, cubes, TARGET, REST_Z) == pytest.approx(np.hypot(0.3, 0.05))
    # nothing at B: cube 2 is carried down to the table at B
    away = np.array([[0.3, -0.5, REST_Z], [0.35, -0.5, REST_Z]])
    assert phase_distance("carry 2", hand, away, TARGET, REST_Z) == pytest.approx(0.35)
    assert phase_distance("finish", hand, cubes, TARGET, REST_Z) is None


def test_progress_is_a_new_phase_or_a_new_best_distance_by_the_step():
    goals = ["reach cube 1"] * 6 + ["carry cube 1"] * 2
    cube = np.array([0.0, 0.0, REST_Z])
    # the hand's height above cube 1: 10 cm, 9.5 (not 2 cm better), 7.9 (progress), 8.5, 5.8 (progress), 5.5
    heights = [0.10, 0.095, 0.079, 0.085, 0.058, 0.055, 0.0, 0.0]
    hand = np.array([[0.0, 0.0, REST_Z + h] for h in heights])
    cubes = np.repeat(np.array([[cube, [0.3, -0.5, REST_Z]]]), len(goals), axis=0)
    assert progress_ticks(goals, hand, cubes, TARGET, 0.02).tolist() == [0, 2, 4, 6]


def test_the_stuck_span_is_the_longest_between_progress_and_the_end():
    assert longest_gap(np.array([0, 3, 10]), 12) == (3, 10)
    assert longest_gap(np.array([0, 3]), 12) == (3, 12)  # no progress after tick 3: stuck until the end


def test_a_tick_is_blocked_when_the_hand_moves_under_a_quarter_of_its_command():
    command = np.array([[0.1, 0.0, 0.0]] * 4 + [[0.0, 0.0, 0.0]])  # 0.1 m/s along x: 1 cm a tick of 0.1 s
    hand = np.cumsum([[0.0, 0, 0], [0.01, 0, 0], [0.002, 0, 0], [0.001, 0.01, 0], [0.0, 0, 0]], axis=0)
    commanded, blocked = blocked_ticks(hand, command, DT, 0.25)
    # steps: 1 cm along (free), 0.2 cm (blocked), 0.1 cm along with 1 cm sideways (blocked), none (blocked)
    assert commanded.tolist() == [True, True, True, True]
    assert blocked.tolist() == [False, True, True, True]


def evidence(**changes) -> dict:
    """A span in which nothing went wrong; ``changes`` set what did."""
    base = dict(drops=0, blocked_share=0.0, blocked_s=0.0, neutral_run_s=0.0, neutral_share=0.0,
                switches_per_min=2.0, accuracy=0.95)
    return {**base, **changes}


@pytest.mark.parametrize("changes, failure, expected", [
    ({}, "cube 2 knocked off the table", Mechanism.CUBE_LOST),
    ({"drops": 1, "neutral_run_s": 60.0}, None, Mechanism.CUBE_LOST),  # the first rule that holds
    ({"blocked_share": 0.6, "blocked_s": 6.0}, None, Mechanism.ARM_AT_LIMIT),
    ({"blocked_share": 0.6, "blocked_s": 4.0}, None, Mechanism.PLANNER_STUCK),  # blocked too briefly
    ({"neutral_run_s": 10.0, "switches_per_min": 30.0}, None, Mechanism.CLASSIFIER_STUCK),
    ({"neutral_share": 0.5, "accuracy": 0.4}, None, Mechanism.CLASSIFIER_STUCK),
    ({"switches_per_min": 20.0}, None, Mechanism.MODE_SWITCH_STORM),
    ({"switches_per_min": 19.0}, None, Mechanism.PLANNER_STUCK),  # P4 switches up to 17 a minute working
    ({"accuracy": None}, None, Mechanism.PLANNER_STUCK),  # no classifier: the joystick
    ({"accuracy": 0.79}, None, Mechanism.MISREAD_MOTION),
])
def test_each_rule_and_their_order(changes, failure, expected):
    assert classify(evidence(**changes), failure, Rules()) is expected


def record(ticks: int, intended: np.ndarray, decided: np.ndarray, success: bool = False) -> EpisodeLog:
    """A BoMI record of ``ticks`` ticks of 0.1 s reaching for cube 1, the hand still 10 cm above it
    after the first second, with one decision a tick."""
    t = np.arange(ticks) * DT
    hand = np.array([[0.3, -0.5, 0.3 if k < 10 else REST_Z + 0.1] for k in range(ticks)])
    cubes = np.repeat(np.array([[[0.3, -0.5, REST_Z], [0.35, -0.5, REST_Z]]]), ticks, axis=0)
    body = np.where(intended != 0, 12.0, 3.0)  # 12 deg from the calibrated neutral moving, 3 at rest
    trace = DecisionTrace(t=t, intended=intended, decided=decided, gamma=np.zeros(ticks), nu=np.zeros(ticks),
                          lean=np.where(intended != 0, 0.6, 0.0), body_deg=body)
    return EpisodeLog(operator="bomi", participant="P9", seed=0, controls="x", t=t, hand_pos=hand,
                      intended_dir=np.zeros((ticks, 3)), mode=["translation"] * ticks, presses=0, cube_pos=cubes,
                      touching=np.zeros((ticks, 2), bool), target_pos=TARGET, success=success,
                      completion_time=None, failure=None if success else "time limit 60 s", wall_time=1.0,
                      cpu_time=1.0, decisions=trace, goals=("reach cube 1",) * ticks, allowance=2, sample_period=DT,
                      commanded=np.zeros((ticks, 3)))


def test_a_motion_read_as_neutral_for_long_is_the_classifier_stuck_with_its_evidence():
    ticks = 600  # 60 s
    intended = np.r_[np.zeros(100, int), np.ones(500, int)]  # rest 10 s, then a motion for 50 s
    decided = np.r_[np.zeros(100, int), np.ones(100, int), np.zeros(400, int)]  # read for 10 s, then neutral
    period = stuck_period(record(ticks, intended, decided))
    assert (period.start_s, period.end_s) == pytest.approx((1.0, 60.0))  # the hand stopped improving at 1 s
    assert period.mechanism is Mechanism.CLASSIFIER_STUCK
    assert period.neutral_run_s == pytest.approx(40.0)
    assert period.neutral_share == pytest.approx(400 / 500)
    assert (period.lean, period.body_deg, period.neutral_drift_deg) == pytest.approx((0.6, 12.0, 3.0))
    # the span's decisions: 90 at rest, right; of the motion's 500 the first 2 excused, 98 right, 400 wrong
    assert period.accuracy == pytest.approx((90 + 98) / (90 + 498))


def test_episodes_needing_a_mechanism_failed_or_took_over_twice_the_median():
    times = [100.0, 110.0, 120.0, 239.0, 241.0]
    records = [{"participant": "P9", "operator": "bomi", "seed": s, "success": True, "completion_time": c,
                "stuck": {"mechanism": "planner stuck"}} for s, c in enumerate(times)]
    records.append({"participant": "P9", "operator": "bomi", "seed": 5, "success": False, "completion_time": None,
                    "stuck": {"mechanism": "classifier stuck"}})
    # the successes' median is 120 s: only 241 s is slow
    assert needs_mechanism(records) == [False, False, False, False, True, True]
    row, = mechanism_rows(records)
    assert (row["failed"], row["slow"], row["episodes"]) == (1, 1, 6)
    assert row["mechanisms"]["planner stuck"] == [4] and row["mechanisms"]["classifier stuck"] == [5]
    assert row["mechanisms"]["cube lost"] == []


def test_the_timeline_hatches_the_stuck_span_and_names_its_mechanism():
    import matplotlib.pyplot as plt

    from tasks.stacking.timeline import _mark_stuck
    intended = np.r_[np.zeros(100, int), np.ones(500, int)]
    period = stuck_period(record(600, intended, np.zeros(600, int)))
    fig, ax = plt.subplots()
    _mark_stuck([ax], period)
    hatched, = [p for p in ax.patches if p.get_hatch() == "//"]
    assert hatched.get_x() == pytest.approx(1.0) and hatched.get_width() == pytest.approx(59.0)
    assert "classifier stuck" in ax.texts[0].get_text()
    plt.close(fig)


def undone_record(drop: bool) -> EpisodeLog:
    """Cube 1 reached (2 s) and carried (2 s), let go at 4 s from 10 cm up (``drop``) or set down on the
    table; then reached for again: the hand comes down 3 cm a tick for 6 s and then stays 10 cm
    above it until 60 s, so the stuck span starts 6 s after the release (past the 5 s before it)."""
    ticks = 600
    t = np.arange(ticks) * DT
    goals = ("reach cube 1",) * 20 + ("carry cube 1",) * 20 + ("reach cube 1",) * (ticks - 40)
    cube_z = np.full(ticks, REST_Z)
    cube_z[20:40] = REST_Z + 0.1  # held up
    if drop:
        cube_z[40:44] = REST_Z + np.array([0.1, 0.07, 0.03, 0.0])  # falls 10 cm once the fingers open
    cubes = np.zeros((ticks, 2, 3))
    cubes[:, 0] = np.c_[np.full(ticks, 0.3), np.full(ticks, -0.5), cube_z]
    cubes[:, 1] = [0.35, -0.5, REST_Z]
    touching = np.zeros((ticks, 2), bool)
    touching[20:40, 0] = True
    hand_z = np.r_[np.full(40, REST_Z + 0.1), REST_Z + 0.1 + 0.03 * (60 - np.arange(60)), np.full(ticks - 100, REST_Z + 0.1)]
    hand = np.c_[np.full(ticks, 0.3), np.full(ticks, -0.5), hand_z]
    return EpisodeLog(operator="joystick", participant="P9", seed=0, controls="x", t=t, hand_pos=hand,
                      intended_dir=np.zeros((ticks, 3)), mode=["translation"] * ticks, presses=0, cube_pos=cubes,
                      touching=touching, target_pos=TARGET, success=False, completion_time=None,
                      failure="time limit 60 s", wall_time=1.0, cpu_time=1.0, decisions=None, goals=goals,
                      allowance=2, sample_period=DT, commanded=np.zeros((ticks, 3)))


def test_a_drop_that_sent_the_task_back_to_a_phase_done_before_explains_its_stuck_span():
    dropped, set_down = stuck_period(undone_record(drop=True)), stuck_period(undone_record(drop=False))
    # the hand's last 3 cm step lands at 10 s; no progress after it (the repeated phase is not new)
    assert (dropped.start_s, dropped.end_s) == pytest.approx((10.0, 60.0)) and dropped.phase == "reach 1"
    assert dropped.start_s - 4.3 > Rules().drop_before_s  # the fall (4.0-4.3 s) lies before the 5 s window ...
    assert dropped.drops == 1 and dropped.mechanism is Mechanism.CUBE_LOST  # ... and still explains the span
    assert set_down.drops == 0 and set_down.mechanism is Mechanism.PLANNER_STUCK  # no drop: the span alone
