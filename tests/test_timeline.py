"""The timeline figure's pieces by hand: task phases from the user's goals, which decisions are
right, excused or misclassified; and the figure itself from a short real BoMI episode."""
from __future__ import annotations

import numpy as np
import pytest

from tasks.stacking.metrics import task_phase, task_phases
from tasks.stacking.timeline import AMPLITUDE_LABELS, decision_kinds

GOALS = ["rest", "reach cube 1: rise", "reach cube 1: travel", "open hand", "grasp cube 1", "carry cube 1: rise",
         "release cube 1", "level the hand", "turn to cube 2", "grasp cube 2", "carry cube 2: descend",
         "release cube 2", "release", "retreat", "done"]


def test_goals_fall_into_reach_carry_and_finish_phases():
    assert [task_phase(g) for g in GOALS[:3]] == [None, "reach 1", "reach 1"]
    assert task_phase("missed cube 2: open hand") == "reach 2" and task_phase("open hand") is None
    # interruptions (rest, open hand, level the hand) stay in the phase they interrupt
    assert task_phases(GOALS) == [(0, 5, "reach 1"), (5, 8, "carry 1"), (8, 10, "reach 2"), (10, 12, "carry 2"),
                                  (12, 15, "finish")]


def test_decisions_are_right_excused_or_misclassified():
    intended = np.array([0, 0, 0, 1, 1, 1, 1, 1, 0, 0])
    decided = np.array([0, 2, 0, 0, 0, 1, 0, 1, 1, 0])
    right, excused, misclassified = decision_kinds(intended, decided, allowance=2, neutral=0)
    # a change at 3 excuses 3 and 4 (neutral, the previous class), a change at 8 excuses 8 (class 1, the previous)
    assert right.tolist() == [True, False, True, False, False, True, False, True, False, True]
    assert np.flatnonzero(excused).tolist() == [3, 4, 8]
    assert np.flatnonzero(misclassified).tolist() == [1, 6]
    assert not (right & excused).any() and not (excused & misclassified).any()


@pytest.mark.parametrize("kind", ["gamma", "along_class"])
def test_the_amplitude_axis_says_which_amplitude(kind):
    assert ("gamma" in AMPLITUDE_LABELS[kind]) == (kind == "gamma")
