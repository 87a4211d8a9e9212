"""bomi.onsets: each cue's move found in the signals; on stand-ins of known timing, the twin recovers it."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bomi.onsets import Move, MoveKind, find_moves, keeps_moves
from bomi.profiles import load_profile
from tasks.participants.holds import stacked_angles
from tasks.participants.participant import calibration_session, load_participant, session_recording
from tasks.participants.twin import fit_twin, speed_share_time

RATE = 62.5
# where a minimum-jerk move's speed 30 s^2 (1 - s)^2 first reaches 10 % of its peak 1.875: s (1 - s) =
# sqrt(0.1 / 16) = 0.0790569, s = (1 - sqrt(1 - 0.3162278)) / 2 (solved by hand)
SHARE_TIME = 0.0865476


def cued_move(start_s: float, duration_s: float, size: float = 20.0, before: int = 300, after_s: float = 6.0):
    """A still signal for ``before`` rows, then the cue, then a minimum-jerk move ``start_s`` after it."""
    t = np.arange(int(after_s * RATE)) / RATE
    s = np.clip((t - start_s) / duration_s, 0, 1)
    moving = (10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5) * size
    x = np.r_[np.zeros(before), moving][:, None] * np.array([[1.0, 0.5]])
    labels = np.r_[np.zeros(before, int), np.ones(len(t), int)]
    return x, np.arange(len(x)) / RATE, labels


def test_the_speed_share_time_is_the_hand_solved_one():
    assert speed_share_time() == pytest.approx(SHARE_TIME, abs=1e-6)


def test_a_minimum_jerk_move_is_found_where_its_speed_crosses_a_tenth_of_its_peak():
    x, time, labels = cued_move(0.5, 1.0)
    move, = find_moves(x, time, labels)
    assert move.kind is MoveKind.TIMED
    # the 4 Hz low-pass moves a 1 s move's crossings by less than two rows
    assert move.onset_s == pytest.approx(0.5 + SHARE_TIME, abs=2 / RATE)
    assert move.offset_s == pytest.approx(0.5 + 1.0 - SHARE_TIME, abs=2 / RATE)
    assert abs(move.onset_row - (300 + (0.5 + SHARE_TIME) * RATE)) <= 2


def test_jumps_small_changes_and_early_moves_are_not_timed():
    still = np.zeros(600)
    jump = np.r_[still[:300], np.full(300, 20.0)][:, None]
    labels = np.r_[np.zeros(300, int), np.ones(300, int)]
    time = np.arange(600) / RATE
    assert find_moves(jump, time, labels)[0].kind is MoveKind.JUMP          # a stitched file
    assert find_moves(jump / 10, time, labels)[0].kind is MoveKind.TOO_SMALL  # 2 deg: below MIN_MOVE_DEG
    x, time, labels = cued_move(-0.3, 1.0)                                   # moving 0.3 s before the cue
    assert find_moves(x, time, labels)[0].kind is MoveKind.ANTICIPATED
    timed, jumped = Move(1, 1, MoveKind.TIMED, 0.5, 1.2), Move(2, 0, MoveKind.JUMP)
    assert keeps_moves([timed, timed, jumped]) and not keeps_moves([timed, jumped, jumped])


SLOW = {"onset_s": 1.6, "reaction_s": 0.8, "onset_sd_s": 0.3, "reaction_sd_s": 0.25}


@pytest.fixture(scope="module")
def slow_person():
    """A stand-in whose movement times are known: P1's body with slow and variable onsets, every row kept."""
    params = dataclasses.replace(load_participant("P1"), **SLOW)
    profile = load_profile("P1")
    session = calibration_session(params, profile, seed=5)
    return session, session_recording(session, profile, holds_only=False), profile


def test_the_moves_found_are_the_true_moves(slow_person):
    session, rec, _ = slow_person
    moves = [m for m in find_moves(stacked_angles(rec), rec.time, rec.labels) if m.kind is MoveKind.TIMED]
    assert len(moves) == len(session.moves)   # every cue that moved the body, and no other
    cue_s, start_s, end_s = session.moves.T
    duration = end_s - start_s
    onset_error = np.array([rec.time[m.cue_row] + m.onset_s for m in moves]) - (start_s + SHARE_TIME * duration)
    offset_error = np.array([rec.time[m.cue_row] + m.offset_s for m in moves]) - (end_s - SHARE_TIME * duration)
    assert np.median(np.abs(onset_error)) < 0.05 and np.abs(onset_error).max() < 0.15
    assert np.median(np.abs(offset_error)) < 0.06


def test_the_twin_fits_the_true_timing_and_its_spread(slow_person):
    session, rec, profile = slow_person
    twin = fit_twin([rec], profile, load_participant("P1"), "slow")
    cue_s, start_s, end_s = session.moves.T
    reaction, duration = start_s - cue_s, end_s - start_s
    assert twin.provenance["reaction_s"].startswith("measured") and twin.provenance["reaction_sd_s"].startswith("measured")
    assert twin.reaction_s == pytest.approx(np.median(reaction), abs=0.06)
    assert twin.onset_s == pytest.approx(np.median(duration), abs=0.1)
    assert twin.reaction_sd_s == pytest.approx(reaction.std(), rel=0.3)
    assert twin.onset_sd_s == pytest.approx(duration.std(), rel=0.3)
    # and the drawn timing is what the file asked for (gamma draws of that mean and SD)
    assert reaction.mean() == pytest.approx(SLOW["reaction_s"], abs=0.1)
    assert reaction.std() == pytest.approx(SLOW["reaction_sd_s"], rel=0.35)


def test_a_participant_without_timing_spread_moves_after_the_same_delay_every_time():
    params = dataclasses.replace(load_participant("P1"), onset_sd_s=0.0, reaction_sd_s=0.0)   # P1 ships a spread
    session = calibration_session(params, load_profile("P1"), seed=3, repetitions=1)
    cue_s, start_s, end_s = session.moves.T
    assert np.allclose(start_s - cue_s, params.reaction_s) and np.allclose(end_s - start_s, params.onset_s)
