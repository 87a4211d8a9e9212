"""The virtual participant's feel for proportional control: how far to lean for how fast."""
import pytest

from tasks.episode import BODY_RANGE, LEARNING_RATE, LeanFeel


def test_a_wanted_deflection_maps_linearly_from_the_zero_lean_never_below_the_calibrated_floor():
    feel = LeanFeel(zero=0.4, floor=0.5)
    assert feel.lean_for(1.0) == pytest.approx(1.0)
    assert feel.lean_for(0.5) == pytest.approx(0.4 + 0.6 * 0.5)
    assert feel.lean_for(0.1) == pytest.approx(0.5)  # 0.46 would be below the least lean calibrated
    assert LeanFeel().lean_for(0.2) == pytest.approx(BODY_RANGE[0] + (1 - BODY_RANGE[0]) * 0.2)


def test_the_zero_lean_moves_against_the_speed_error_and_full_speed_moves_teach_nothing():
    feel = LeanFeel(zero=0.5)
    feel.learn(wanted=0.2, seen=0.6)  # the arm went three times too fast: lean less next time
    assert feel.zero == pytest.approx(0.5 - LEARNING_RATE * 0.4)
    feel.learn(wanted=0.2, seen=0.0)  # it barely moved: lean more
    assert feel.zero == pytest.approx(0.5 - LEARNING_RATE * 0.4 + LEARNING_RATE * 0.2)
    before = feel.zero
    feel.learn(wanted=1.0, seen=0.3)
    assert feel.zero == before
    feel.learn(wanted=0.0, seen=5.0)
    assert feel.zero == 0.0  # clipped: a lean is never negative
