"""Episode metrics on hand-made logs whose answers are worked out by hand."""
import numpy as np
import pytest

from tasks.stacking import metrics
from tasks.statistics import mean_interval, wilson_interval

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
    # every decision counts: 6 right, 4 late in transitions (3, 4 neutral = the previous class; 9, 10 the
    # previous class 2), 2 wrong outside them
    assert metrics.accuracy_excused_transitions(INTENDED, DECIDED, allowance=2) == pytest.approx(10 / 12)
    assert metrics.excused_share(INTENDED, DECIDED, allowance=2) == pytest.approx(4 / 12)
    # another class in a transition is not late but wrong: class 5 at 3 is not excused
    other = DECIDED.copy()
    other[3] = 5
    assert np.flatnonzero(metrics.misclassified(INTENDED, other, allowance=2)).tolist() == [1, 3, 6]
    assert metrics.accuracy_excused_transitions(INTENDED, other, allowance=2) == pytest.approx(9 / 12)
    assert metrics.error_destinations(DECIDED, errors, neutral=0) == {"to_neutral": 1, "to_other_class": 1}


def test_longest_error_run_in_ms():
    errors = np.array([0, 1, 1, 1, 0, 1], bool)
    assert metrics.longest_error_run_ms(errors, 0.016) == pytest.approx(48.0)
    assert metrics.longest_error_run_ms(np.zeros(3, bool), 0.016) == 0.0


def test_latency_counts_samples_from_onset_to_first_correct_decision():
    assert metrics.decision_latencies(INTENDED, DECIDED, neutral=0).tolist() == [2]
    # an onset the chain never followed is left out, not counted as zero
    assert metrics.decision_latencies(np.array([0, 3, 3, 0]), np.array([0, 0, 0, 0]), 0).size == 0


def test_every_onset_is_counted_with_its_latency_or_as_never_recognised():
    intended = np.array([0, 3, 3, 3, 0, 5, 5, 2, 2, 2, 2])
    decided = np.array([0, 0, 0, 3, 3, 0, 0, 0, 0, 4, 2])
    # onsets: c3 at 1 (output at 3: 2 samples), c5 at 5 (never), c2 at 7 (output at 10: 3 samples)
    assert metrics.onset_latencies(intended, decided, neutral=0) == [2, None, 3]


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


def test_cube_drops_count_a_stack_that_slides_off_long_after_the_release():
    """P17406 at seed 17404: cube 2 let go on the stack at 7.9 cm, sliding off 4 s later (240 ticks at
    60 Hz) to the table; picked up and let go again on the table: one drop, not two, and not none."""
    z = np.full((1000, 2), 0.025)
    touching = np.zeros((1000, 2), bool)
    z[:100, 1], touching[:100, 1] = 0.079, True         # held on the stack, let go at tick 100
    z[100:340, 1] = 0.076                               # rests on cube 1 for 4 s
    z[340:400, 1] = np.linspace(0.076, 0.025, 60)       # slides off to the table
    touching[600:700, 1] = True                         # picked up again (the window ends at the touch)
    z[600:700, 1] = 0.029                               # and let go 4 mm up: a placement
    assert metrics.cube_drops(z, touching) == 1  # by hand: falls of 5.4 cm, then 0.4 cm


def test_accuracy_over_all_decisions_excuses_nothing():
    # wrong at 1, 3, 4, 6, 9, 10: 6 of 12
    assert metrics.accuracy_all_decisions(INTENDED, DECIDED) == pytest.approx(6 / 12)
    assert np.isnan(metrics.accuracy_all_decisions(np.array([]), np.array([])))


def test_accuracy_grows_with_the_allowance_and_never_reads_below_all_decisions():
    curve = metrics.accuracy_vs_allowance(INTENDED, DECIDED, np.array([0, 1, 2, 3]))
    # over all 12 decisions, 6 right; allowance 1 excuses 3 and 9 (late), 2 also 4 and 10, 3 adds only right ones
    assert curve == pytest.approx([6 / 12, 8 / 12, 10 / 12, 10 / 12])
    rng = np.random.default_rng(0)
    for _ in range(50):   # random streams: the excused figure is never below the all-decisions one
        intended, decided = rng.integers(0, 4, 200).repeat(3), rng.integers(0, 4, 600)
        assert metrics.accuracy_excused_transitions(intended, decided, 5) >= metrics.accuracy_all_decisions(intended,
                                                                                                              decided)


def test_previous_intended_is_the_class_before_the_last_change():
    intended = np.array([1, 1, 0, 0, 3, 3, 3])
    assert metrics.previous_intended(intended).tolist() == [1, 1, 1, 1, 0, 0, 0]


def test_irrelevant_outputs_fit_neither_the_previous_nor_the_new_intent():
    # F(1) -> neutral(0) -> R(3); outputs: a late F during neutral (transition, not irrelevant), a B(2)
    # during neutral (irrelevant), an F during R (irrelevant: two intents ago), neutral during R (a miss,
    # never irrelevant), B twice in a row during R (irrelevant, a run of 2)
    intended = np.array([1, 1, 0, 0, 0, 3, 3, 3, 3, 3, 3])
    decided = np.array([1, 1, 1, 2, 0, 1, 0, 3, 2, 2, 3])
    wild = metrics.irrelevant(intended, decided, neutral=0)
    assert np.flatnonzero(wild).tolist() == [3, 5, 8, 9]
    assert metrics.runs(wild) == [(3, 1), (5, 1), (8, 2)]
    assert metrics.longest_error_run_ms(wild, 0.016) == pytest.approx(32.0)
    # 3 runs over 11 decisions of 16 ms = 0.176 s
    assert metrics.per_minute(3, 11, 0.016) == pytest.approx(3 / (11 * 0.016 / 60))


def test_success_interval_is_wilson():
    # Wilson score interval for 20/20 at 95 %: [n / (n + z^2), 1] with z = 1.959964
    low, high = wilson_interval(20, 20)
    assert low == pytest.approx(20 / (20 + 1.959964 ** 2), abs=1e-6) and high == pytest.approx(1.0)
    # 5/10: centre 0.5, half width z sqrt(p(1-p)/n + z^2/4n^2) / (1 + z^2/n)
    z, n = 1.959964, 10
    half = z * np.sqrt(0.25 / n + z ** 2 / (4 * n ** 2)) / (1 + z ** 2 / n)
    assert wilson_interval(5, 10) == pytest.approx((0.5 - half, 0.5 + half), abs=1e-6)


def test_completion_time_interval_is_student_t():
    # mean 2, sample sd 1, n = 3: 2 +- t(0.975, 2) x 1 / sqrt(3) with t = 4.302653
    assert mean_interval([1.0, 2.0, 3.0]) == pytest.approx((2 - 4.302653 / np.sqrt(3), 2 + 4.302653 / np.sqrt(3)),
                                                                abs=1e-5)
    assert mean_interval([4.0]) is None
    assert mean_interval([4.0, 4.0]) == (4.0, 4.0)
