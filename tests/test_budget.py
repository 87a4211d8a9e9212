"""tasks.stacking.budget on hand-made records whose budget and contexts are worked out by hand."""
import numpy as np
import pytest

from tasks.stacking import metrics
from tasks.stacking.budget import (Context, IrrelevantRun, Part, decision_contexts, irrelevant_by_context,
                                   irrelevant_runs, task_ticks, time_budget, vote_effect)
from tasks.stacking.record import DecisionTrace, EpisodeLog

NAMES = ("neutral", "F", "B", "R", "L", "Rr", "Lr", "B1", "B2")  # P1's classes: 7 and 8 are the buttons
STILL = 0.005  # m/s


def record(t, hand, intended_dir, pushing, commanded, mode, completion_time=None, decisions=None, allowance=0,
           sample_period=0.016) -> EpisodeLog:
    n = len(t)
    return EpisodeLog(operator="bomi" if decisions is not None else "joystick", participant="P9", seed=0,
                      controls="x", t=np.asarray(t, float), hand_pos=np.asarray(hand, float),
                      intended_dir=np.asarray(intended_dir, float), mode=list(mode), presses=0,
                      cube_pos=np.zeros((n, 2, 3)), touching=np.zeros((n, 2), bool), target_pos=np.zeros(3),
                      success=completion_time is not None, completion_time=completion_time, failure=None,
                      wall_time=1.0, cpu_time=1.0, pushing=np.asarray(pushing, bool), decisions=decisions,
                      class_names=NAMES, neutral=0, allowance=allowance, sample_period=sample_period,
                      commanded=np.asarray(commanded, float))


def steps_to_positions(steps: np.ndarray) -> np.ndarray:
    """Hand positions whose step i -> i + 1 is ``steps[i]``."""
    return np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])[:len(steps)]


def two_pushes(with_decisions: bool) -> EpisodeLog:
    """26 ticks of 0.5 s, completed at 12 s (ticks 24 and 25 come after it and do not count):
    0-1 still; 2-7 a push F (+x), read (one decision a tick) at 4-6 only, the hand commanded then
    (5 cm a tick); 8-9 let go, the hand coasting 1 cm a tick; the mode changes at tick 12; 14-17 a
    push B (-x), read at 15-17 and commanded then; 18 let go, coasting; 19 on still."""
    n, dt = 26, 0.5
    t = np.arange(n) * dt
    steps = np.zeros((n, 3))
    steps[4:7, 0], steps[8:10, 0], steps[15:18, 0], steps[18, 0] = 0.05, 0.01, -0.05, -0.01
    pushing = np.zeros(n, bool)
    pushing[2:8] = pushing[14:18] = True
    direction = np.zeros((n, 3))
    direction[2:8, 0], direction[14:18, 0] = 1.0, -1.0
    commanded = np.zeros((n, 3))
    commanded[4:7, 0], commanded[15:18, 0] = 0.1, -0.1
    intended, decided = np.zeros(n, int), np.zeros(n, int)
    intended[2:8], decided[4:7], intended[14:18], decided[15:18] = 1, 1, 2, 2
    trace = DecisionTrace(t=t, intended=intended, decided=decided, gamma=np.zeros(n), nu=np.zeros(n))
    mode = ["translation"] * 12 + ["wrist"] * 14
    return record(t, steps_to_positions(steps), direction, pushing, commanded, mode, completion_time=12.0,
                  decisions=trace if with_decisions else None, allowance=2, sample_period=dt)


def test_a_bomi_record_splits_into_its_parts_by_hand():
    log, dt = two_pushes(with_decisions=True), 0.5
    assert task_ticks(log) == 24
    budget = time_budget(log, STILL)
    # the switch's span: from the tick after the last push before the change (8) to the next push (14)
    assert budget == pytest.approx({Part.RECOVERY: 0.0, Part.MISREAD: 0.0, Part.CORRECTION: 0.0,
                                    Part.MODE_SWITCH: 6 * dt, Part.REACTION: 3 * dt, Part.MOVEMENT: 6 * dt,
                                    Part.LAPSE: 1 * dt, Part.WAIT: 1 * dt, Part.REST: 7 * dt})
    assert sum(budget.values()) == pytest.approx(12.0)
    spans = metrics.mode_switch_ticks(log.mode, log.pushing)
    assert spans.sum() * dt == pytest.approx(metrics.mode_switch_time(log.mode, log.pushing, dt))


def test_a_stick_answers_every_push_at_once():
    budget, dt = time_budget(two_pushes(with_decisions=False), STILL), 0.5
    assert budget == pytest.approx({Part.RECOVERY: 0.0, Part.MISREAD: 0.0, Part.CORRECTION: 0.0,
                                    Part.MODE_SWITCH: 6 * dt, Part.REACTION: 0.0, Part.MOVEMENT: 10 * dt,
                                    Part.LAPSE: 0.0, Part.WAIT: 1 * dt, Part.REST: 7 * dt})


def test_a_misread_is_counted_and_its_undoing_is_the_correction():
    # 12 ticks of 0.5 s, one decision a tick, allowance 2. The person pushes F (+x) at ticks 0-3 and
    # is read right; rests from 4; the chain reads R at 6-7 and the arm goes 2 cm +y a tick (D = 4 cm);
    # at 9-11 the person pushes B (-y), read right, the hand back 2 cm a tick: undone after tick 10.
    n, dt = 12, 0.5
    t = np.arange(n) * dt
    intended = np.array([1, 1, 1, 1, 0, 0, 0, 0, 0, 2, 2, 2])
    decided = np.array([1, 1, 1, 1, 0, 0, 3, 3, 0, 2, 2, 2])
    steps = np.zeros((n, 3))
    steps[0:4, 0], steps[6:8, 1], steps[9:12, 1] = 0.05, 0.02, -0.02
    pushing = np.array([1, 1, 1, 1, 0, 0, 0, 0, 0, 1, 1, 1], bool)
    direction = np.zeros((n, 3))
    direction[0:4, 0], direction[9:12, 1] = 1.0, -1.0
    commanded = np.zeros((n, 3))
    commanded[0:4, 0], commanded[6:8, 1], commanded[9:12, 1] = 0.1, 0.04, -0.04
    trace = DecisionTrace(t=t, intended=intended, decided=decided, gamma=np.zeros(n), nu=np.zeros(n))
    log = record(t, steps_to_positions(steps), direction, pushing, commanded, ["translation"] * n,
                 completion_time=6.0, decisions=trace, allowance=2, sample_period=dt)
    budget = time_budget(log, STILL)
    assert budget == pytest.approx({Part.RECOVERY: 0.0, Part.MISREAD: 2 * dt, Part.CORRECTION: 2 * dt,
                                    Part.MODE_SWITCH: 0.0, Part.REACTION: 0.0, Part.MOVEMENT: 5 * dt,
                                    Part.LAPSE: 0.0, Part.WAIT: 0.0, Part.REST: 3 * dt})
    # the read R comes 2 and 3 decisions into a rest that followed F: past the allowance, a drift
    assert irrelevant_by_context(log)[Context.REST_DRIFT] == 2
    assert sum(irrelevant_by_context(log).values()) == 2


def context_record() -> EpisodeLog:
    """45 decisions, one a tick of 16 ms, allowance 3: rest 5, F 6, R 5 (straight from F), a short rest 2,
    B1 4, a short rest 2, B 5, rest 6, L 4, a short rest 2, F 4; the pushes are the stick classes'
    runs; the mode changes at 33."""
    runs = [(0, 5), (1, 6), (3, 5), (0, 2), (7, 4), (0, 2), (2, 5), (0, 6), (4, 4), (0, 2), (1, 4)]
    intended = np.concatenate([[label] * length for label, length in runs])
    n = len(intended)
    t = np.arange(n) * 0.016
    decided = intended.copy()
    decided[6] = 4          # in the onset of F from rest
    decided[12] = 2         # in the move straight from F to R (F itself, 1, would be late, not irrelevant)
    decided[24:26] = 7      # B1 read on after it was left, across the short rest, into B
    decided[33] = 5         # late in the rest, in the mode change's span
    decided[41] = 3         # F's onset across the short rest from L
    trace = DecisionTrace(t=t, intended=intended, decided=decided, gamma=np.zeros(n), nu=np.zeros(n))
    pushing = np.isin(intended, (1, 2, 3, 4))
    mode = ["translation"] * 33 + ["wrist"] * (n - 33)
    return record(t, np.zeros((n, 3)), np.zeros((n, 3)), pushing, np.zeros((n, 3)), mode, decisions=trace,
                  allowance=3)


def test_every_decision_gets_its_context_by_hand():
    C = Context
    expected = ([C.REST_DRIFT] * 5 + [C.ONSET] * 3 + [C.HOLD_DRIFT] * 3 + [C.MOTION_TO_MOTION] * 3
                + [C.HOLD_DRIFT] * 2 + [C.OFFSET] * 2 + [C.BUTTON_HOLD] * 4 + [C.BUTTON_EXIT] * 2
                + [C.BUTTON_EXIT] * 3 + [C.HOLD_DRIFT] * 2 + [C.OFFSET] * 3 + [C.MODE_CHANGE] * 3
                + [C.ONSET] * 3 + [C.HOLD_DRIFT] + [C.OFFSET] * 2 + [C.MOTION_TO_MOTION] * 3 + [C.HOLD_DRIFT])
    assert decision_contexts(context_record()) == expected


def test_irrelevant_decisions_are_counted_by_context_and_their_runs_ranked():
    log = context_record()
    counts = irrelevant_by_context(log)
    assert counts == {**{c: 0 for c in Context}, Context.ONSET: 1, Context.MOTION_TO_MOTION: 2,
                      Context.BUTTON_EXIT: 2, Context.MODE_CHANGE: 1}
    runs = irrelevant_runs(log)
    assert len(runs) == 5
    assert runs[0] == IrrelevantRun(t=pytest.approx(24 * 0.016), duration_ms=pytest.approx(32.0),
                                    context=Context.BUTTON_EXIT, intended=(2,), decided=(7,))
    assert all(run.duration_ms == pytest.approx(16.0) for run in runs[1:])


def test_the_vote_effect_compares_the_labels_before_and_after_it():
    log = context_record()
    raw = log.decisions.decided.copy()
    raw[24] = 2   # the window read B: the vote made the first B1 output
    raw[8] = 5    # the window read Rr in the F hold: the vote removed it
    effect = vote_effect(log, raw)
    assert (effect.made, effect.removed, effect.before, effect.after) == (1, 1, 6, 6)


def test_a_record_without_decisions_has_no_misread():
    n = 4
    log = record(np.arange(n) * 0.5, np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)),
                 ["translation"] * n)
    budget = time_budget(log, STILL)
    assert budget[Part.MISREAD] == 0.0 and budget[Part.REST] == pytest.approx(2.0)
