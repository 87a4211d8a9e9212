"""The virtual participant's feel for proportional control: how far to lean for how fast."""
import pytest

from tasks.episode import BODY_RANGE, MAX_ZERO, LeanFeel


def test_a_wanted_deflection_maps_linearly_from_the_zero_lean_never_below_the_calibrated_floor():
    feel = LeanFeel(zero=0.4)
    assert feel.lean_for(1.0) == pytest.approx(1.0)
    assert feel.lean_for(0.5) == pytest.approx(0.4 + 0.6 * 0.5)
    assert feel.lean_for(0.1) == pytest.approx(BODY_RANGE[0])  # 0.46 would be below the least lean calibrated
    assert LeanFeel().lean_for(0.2) == pytest.approx(BODY_RANGE[0] + (1 - BODY_RANGE[0]) * 0.2)


def test_a_lean_that_worked_is_where_the_next_move_of_that_class_starts():
    feel = LeanFeel()
    feel.learn(lean=0.75, deflection=0.2)  # had to lean to 0.75 for 0.2: zero = (0.75 - 0.2) / 0.8
    assert feel.zero == pytest.approx(0.6875)
    assert feel.lean_for(0.2) == pytest.approx(0.75)
    feel.learn(lean=1.0, deflection=0.0)
    assert feel.zero == MAX_ZERO  # never so far that the least deflection needs more than full range
    before = feel.zero
    feel.learn(lean=0.6, deflection=1.0)  # a full-speed move says nothing about the zero lean
    assert feel.zero == before
