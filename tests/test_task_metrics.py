"""Episode metrics on hand-made logs whose answers are worked out by hand."""
import numpy as np
import pytest

from tasks import metrics

# intended: neutral x3, class 2 x6, neutral x3 ; decided lags by 2 and has one error to class 5
# and one error to neutral in the settled part
INTENDED = np.array([0, 0, 0, 2, 2, 2, 2, 2, 2, 0, 0, 0])
DECIDED = np.array([0, 5, 0, 0, 0, 2, 0, 2, 2, 2, 2, 0])


def test_runs_finds_every_stretch():
    assert metrics.runs(np.array([1, 1, 0, 1, 0, 0, 1, 1, 1], bool)) == [(0, 2), (3, 1), (6, 3)]
    assert metrics.runs(np.zeros(4, bool)) == []


def test_transition_mask_covers_allowance_after_each_change():
    mask = metrics.in_transition(INTENDED, allowance=2)
    assert np.flatnonzero(mask).tolist() == [3, 4, 9, 10]


def test_accuracy_and_errors_outside_transitions():
    errors = metrics.misclassified(INTENDED, DECIDED, allowance=2)
    assert np.flatnonzero(errors).tolist() == [1, 6]
    # 8 settled decisions (12 minus 4 in transition), 2 wrong
    assert metrics.realtime_accuracy(INTENDED, DECIDED, allowance=2) == pytest.approx(6 / 8)
    assert metrics.error_destinations(DECIDED, errors, neutral=0) == {"to_neutral": 1, "to_other_class": 1}


def test_longest_error_run_in_ms():
    errors = np.array([0, 1, 1, 1, 0, 1], bool)
    assert metrics.longest_error_run_ms(errors, 0.016) == pytest.approx(48.0)
    assert metrics.longest_error_run_ms(np.zeros(3, bool), 0.016) == 0.0


def test_latency_counts_samples_from_onset_to_first_correct_decision():
    assert metrics.decision_latencies(INTENDED, DECIDED, neutral=0).tolist() == [2]
    # an onset the chain never followed is left out, not counted as zero
    assert metrics.decision_latencies(np.array([0, 3, 3, 0]), np.array([0, 0, 0, 0]), 0).size == 0


def test_unintended_displacement():
    hand = np.array([[0, 0, 0], [0.010, 0.003, 0], [0.010, 0.003, 0.004], [0.005, 0.003, 0.004]])
    wanted = np.array([[1, 0, 0], [1, 0, 0], [1, 0, 0]])
    # step 1: 3 mm sideways; step 2: 4 mm sideways; step 3: 5 mm backwards
    assert metrics.unintended_displacement_mm(hand, wanted) == pytest.approx(12.0)
    # resting: every millimetre is unintended
    assert metrics.unintended_displacement_mm(hand, np.zeros((3, 3))) == pytest.approx(
        1000 * (np.hypot(0.010, 0.003) + 0.004 + 0.005))


def test_count_changes():
    assert metrics.count_changes(["t", "t", "w", "f", "f", "t"]) == 3


def test_cube_drops_tell_a_fall_from_a_placement():
    z = np.full((100, 2), 0.025)
    touching = np.zeros((100, 2), bool)
    # cube 0 carried at 0.10 m, let go at tick 20 and falls to the table: a drop
    z[10:21, 0] = 0.10
    touching[10:20, 0] = True
    # cube 1 set down 4 mm above its support at tick 60: a placement
    z[40:61, 1] = 0.079
    z[61:, 1] = 0.075
    touching[40:60, 1] = True
    assert metrics.cube_drops(z, touching) == 1
