"""A derived profile reaches every function the stacking task needs, for any number of motions (bomi/derived.py)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bomi.derived import derive_profile, derived_layout, describe
from bomi.errors import BomiError
from bomi.recording import NodeData, Recording
from tasks.episode import profile_controls


def motions(count: int) -> Recording:
    """Neutral, then each of ``count`` motions held 150 samples (a tilt of its own), neutral between."""
    labels = np.concatenate([np.zeros(150, int)] + [np.repeat([k, 0], 150) for k in range(1, count + 1)])
    angles = np.zeros((len(labels), 3))
    for k in range(1, count + 1):
        angles[labels == k] = 20.0 * np.array([np.cos(k), np.sin(k), 0.0])
    return Recording({1: NodeData(angles=angles)}, labels, source="person")


# motions -> (layout, the motions' functions in label order, assistances): docs/sim.md's layout table
EXPECTED = {
    8: ("3-axis", ("F", "B", "R", "L", "Rr", "Lr", "B1", "B2"), ()),
    7: ("3-axis", ("F", "B", "R", "L", "Rr", "Lr", "B1"), ()),
    6: ("2-axis", ("F", "B", "R", "L", "B1", "B2"), ()),      # issue 41's person: c5 -> B1, c6 -> B2
    5: ("2-axis", ("F", "B", "R", "L", "B1"), ()),
    4: ("2-axis", ("F", "B", "R", "L"), ("auto-mode",)),
    3: ("1-axis", ("F", "B", "B1"), ()),
    2: ("1-axis", ("F", "B"), ("auto-mode",)),
}


@pytest.mark.parametrize("count", sorted(EXPECTED))
def test_the_layout_follows_the_number_of_motions_and_says_why(count):
    layout = derived_layout(count)
    assert (layout.layout, layout.functions, layout.assist) == EXPECTED[count]
    profile = derive_profile([motions(count)])
    assert profile.joystick_layout == layout.layout and profile.assist == layout.assist
    assert [c.function for c in profile.classes[1:]] == list(layout.functions)
    assert layout.reason in profile.description and layout.reason in describe(profile)


@pytest.mark.parametrize("count", [3, 5, 6, 7, 8])
def test_with_five_motions_or_more_the_stacking_user_has_every_function_and_a_mode_button(count):
    controls = profile_controls(derive_profile([motions(count)]))
    assert controls.layout.name == EXPECTED[count][0]
    assert controls.buttons == tuple(f for f in ("B1", "B2") if f in EXPECTED[count][1])


@pytest.mark.parametrize("count", [2, 4])
def test_with_no_motion_left_for_a_button_the_stacking_user_has_every_direction_and_no_button(count):
    # the modes change automatically: the scripted user rests and waits for them (tests/test_no_button.py)
    controls = profile_controls(derive_profile([motions(count)]))
    assert controls.layout.name == EXPECTED[count][0] and controls.buttons == ()


def test_a_profile_without_a_button_or_the_automatic_switching_is_refused_naming_b1():
    profile = derive_profile([motions(4)])
    with pytest.raises(BomiError, match="has no class for B1;"):
        profile_controls(replace(profile, assist=()))
