"""Cues and movement told apart (bomi.chain.holds): the holds accuracy beside the all-window one, and
training that reads the rows before a person's measured onset as the posture still held."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bomi.chain import (MAX_MOVE_END_S, MoveAllowances, as_held, evaluate, held_labels, leave_one_pass_out,
                        recording_moves, train, training_windows)
from bomi.onsets import Move, MoveKind
from bomi.profiles import load_profile
from tasks.experiments.training import misread_classes, misread_warning
from tasks.participants.participant import calibration_session, load_participant, session_recording

# P1's body with slow, variable reactions: the person moves 0.5-1.3 s after each cue (tests/test_onsets.py)
SLOW = {"onset_s": 1.0, "reaction_s": 0.8, "onset_sd_s": 0.2, "reaction_sd_s": 0.25}


@pytest.fixture(scope="module")
def slow_person():
    """Two sessions (two days) of a stand-in whose true movement times are known, every row kept."""
    params = dataclasses.replace(load_participant("P1"), **SLOW)
    profile = load_profile("P1")
    sessions = [calibration_session(params, profile, seed=seed, repetitions=1, hold_s=4.0, neutral_s=4.0)
                for seed in (5, 6)]
    return sessions, [session_recording(s, profile, holds_only=False) for s in sessions], profile


def test_held_labels_move_each_cue_to_its_measured_onset_by_hand():
    labels = np.array([0] * 5 + [3] * 5 + [0] * 5)
    moves = [Move(5, 3, MoveKind.TIMED, 0.1, 0.2, 7, 8), Move(10, 0, MoveKind.JUMP)]   # the second not timed
    assert held_labels(labels, moves).tolist() == [0] * 7 + [3] * 3 + [0] * 5
    late = [Move(5, 3, MoveKind.TIMED, MAX_MOVE_END_S + 0.5, MAX_MOVE_END_S + 1, 7, 8)]   # beyond the bound
    assert held_labels(labels, late).tolist() == labels.tolist()


def test_p1_published_days_keep_only_their_holds(p1_days, p1_profile):
    """Nothing to tell apart in P1's five days: the holds are every window, training reads them as they are."""
    nodes = p1_profile.spec.nodes
    for rec in p1_days.values():
        assert MoveAllowances.of(rec, nodes) is None
        assert as_held(rec, nodes) is rec


def test_the_holds_accuracy_equals_the_all_window_one_on_p1(p1_days, day1_fv3_model, p1_profile):
    ev = evaluate(day1_fv3_model, p1_days[3], p1_profile.neutral_samples)
    assert ev.on_hold is None and ev.holds.all() and ev.holds_accuracy == ev.accuracy


def test_the_transitions_left_out_are_the_true_moves(slow_person):
    sessions, recs, profile = slow_person
    session, rec = sessions[0], recs[0]
    allowances = MoveAllowances.of(rec, profile.spec.nodes)
    assert allowances is not None and allowances.timed == len(session.moves)
    cue_s, start_s, end_s = session.moves.T
    # each transition ends at its move's offset: 10 % of the peak speed before the true end (a minimum-jerk
    # move's 8.7 % of its duration), as closely as bomi.onsets finds it (tests/test_onsets.py's bounds)
    share = 0.0865476
    error = rec.time[allowances.cue_rows] + allowances.seconds - (end_s - share * (end_s - start_s))
    assert np.median(np.abs(error)) < 0.06 and np.abs(error).max() < 0.2
    hold = allowances.on_hold(len(rec))
    for cue, end in zip(cue_s, end_s):   # no row of a move counted as a hold
        moving = (rec.time >= cue) & (rec.time < end - share * (end - cue) - 0.2)
        assert not hold[moving].any()


def test_training_reads_the_rows_before_the_onset_as_the_posture_held(slow_person):
    sessions, recs, profile = slow_person
    session, rec = sessions[0], recs[0]
    held = as_held(rec, profile.spec.nodes)
    moves = recording_moves(rec, profile.spec.nodes)
    for move in moves:   # from each cue to its measured onset: the label before the cue; from the onset on, the cue's
        assert move.kind is MoveKind.TIMED
        assert (held.labels[move.cue_row:move.onset_row] == rec.labels[move.cue_row - 1]).all()
        assert held.labels[move.onset_row] == rec.labels[move.cue_row]
    # and the measured onsets are the true ones (10 % of the peak speed: 8.7 % of a minimum-jerk move's duration
    # after its start), as closely as bomi.onsets finds them (tests/test_onsets.py)
    _, start_s, end_s = session.moves.T
    onset_error = np.array([rec.time[m.onset_row] for m in moves]) - (start_s + 0.0865476 * (end_s - start_s))
    assert len(moves) == len(session.moves) and np.median(np.abs(onset_error)) < 0.05
    windows, _ = training_windows(rec, profile.spec, profile.neutral_samples)
    first_cue = int(np.flatnonzero(np.diff(rec.labels))[0]) + 1
    first_start = int(np.searchsorted(rec.time, start_s[0]))
    before = (windows.ends >= first_cue) & (windows.ends < first_start)
    assert before.any() and (windows.labels[before] == rec.labels[first_cue - 1]).all()   # not the cued class


def test_holds_scored_apart_from_the_reaction(slow_person):
    """Day 2 read by day 1's model: the all-window figure counts the person's 0.5-1.3 s reactions as errors."""
    _, recs, profile = slow_person
    model = train([recs[0]], profile)
    ev = evaluate(model, recs[1], profile.neutral_samples)
    assert ev.allowances is not None and 0 < ev.holds.sum() < len(ev.truth)
    wrong = ev.predicted != ev.truth
    assert ev.holds_accuracy > ev.accuracy
    assert wrong[~ev.holds].mean() > wrong[ev.holds].mean()   # the errors are in the transitions
    assert ev.holds_accuracy == pytest.approx(1 - wrong[ev.holds].mean())


def test_misread_classes_by_hand():
    truth = np.array([0] * 10 + [8] * 10 + [4] * 10)
    decided = np.array([0] * 10 + [5] * 10 + [4] * 8 + [0] * 2)   # c8 read as c5 throughout; c4 80 % right
    assert misread_classes(truth, decided) == [(8, 0.0, [(5, 1.0)]), (4, 0.8, [(0, pytest.approx(0.2))])]
    line = misread_warning(truth, decided, {8: "c8 (B1)", 5: "c5 (L)"}, "day3.mat")
    assert line.startswith("warning: day3.mat: 2 class(es) below 85 % of their windows: c8 (B1) read as itself in 0 % "
                           "of its 10 windows, as c5 (L) in 100 %; c4 read as itself in 80 % of its 10 windows, as c0 in 20 %")
    assert misread_warning(truth, truth, {}, "x") is None


def test_leave_one_pass_out_judges_the_holds(slow_person):
    """`bomi train`'s headline on two continuous passes: the holds figure beside the all-window one, and
    the warning judged on it (P1's published days: the same windows, tests above)."""
    _, recs, profile = slow_person
    out = leave_one_pass_out(recs, profile, train(recs, profile))
    assert out.holds_accuracy > out.accuracy
    assert out.text().endswith(f"; on the holds {100 * out.holds_accuracy:.2f} %, each transition from its cue to "
                               "the end of its move found in the signals left out")


def test_the_amplitude_range_is_the_held_postures_also_where_the_moves_are_kept(slow_person):
    """gamma_min and gamma_max come from the postures held: a recording that keeps its moves gives the
    range of the same session's holds alone, to within a degree; were the way into each posture counted,
    every class's gamma_min would fall to the neutral's (a few degrees), and any lean would drive the arm."""
    sessions, continuous, profile = slow_person
    held = train([session_recording(sessions[0], profile)], profile).amplitude
    kept = train([continuous[0]], profile).amplitude
    assert held.keys() == kept.keys()
    for label in held:
        assert abs(kept[label].gamma_min - held[label].gamma_min) < 1.0, label
        assert abs(kept[label].gamma_max - held[label].gamma_max) < 1.0, label
    assert min(r.gamma_min for r in held.values()) > 5.0     # the check above could fail: the least lean is far from 0
