"""A derived profile reaches every function the stacking task needs, for any number of motions (bomi/derived.py)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bomi.derived import (button_motions, derive_profile, derived_layout, describe, motion_postures, path_clearance,
                          whitened, within_class_covariance)
from bomi.errors import BomiError
from bomi.recording import NodeData, Recording
from tasks.stacking.channels import profile_controls


def motions(count: int) -> Recording:
    """Neutral, then each of ``count`` motions held 150 samples (a tilt of its own), neutral between."""
    labels = np.concatenate([np.zeros(150, int)] + [np.repeat([k, 0], 150) for k in range(1, count + 1)])
    angles = np.zeros((len(labels), 3))
    for k in range(1, count + 1):
        angles[labels == k] = 20.0 * np.array([np.cos(k), np.sin(k), 0.0])
    return Recording({1: NodeData(angles=angles)}, labels, source="person")


# motions -> (layout, its directions then buttons, assistances): docs/sim.md's layout table
EXPECTED = {
    8: ("3-axis", ("F", "B", "R", "L", "Rr", "Lr", "B1", "B2"), ()),
    7: ("3-axis", ("F", "B", "R", "L", "Rr", "Lr", "B1"), ()),
    6: ("2-axis", ("F", "B", "R", "L", "B1", "B2"), ()),      # issue 41's person
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
    # the buttons on the motions of most path clearance, the directions on the others in label order
    buttons = layout.functions[len(layout.functions) - sum(f in ("B1", "B2") for f in layout.functions):]
    recording = motions(count)
    pressing = button_motions(whitened(motion_postures([recording], [1], range(1, count + 1)),
                                       within_class_covariance([recording], [1])), len(buttons))
    functions = {c.label: c.function for c in profile.classes[1:]}
    assert [functions[k] for k in pressing] == list(buttons)
    assert [functions[k] for k in range(1, count + 1) if k not in pressing] == list(layout.functions[:-len(buttons) or None])
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


def test_path_clearance_by_hand():
    # tests/test_design.py's six head motions (pitch, roll): each one's distance to the nearest segment
    # from neutral to another's posture, by hand: c1 to c5's (at 2/3 of it: (10, 10) away) 14.14; c2
    # likewise 14.14; c3 to c6's (at 0.7035) 20.13; c4 to c6's (at 0.6062) 12.61; c5 to c1's (at 0.75)
    # 15.00; c6 to c4's (at 0.8431) 14.87
    postures = {1: (20, 0), 2: (0, 20), 3: (-25, 2), 4: (1, -18), 5: (15, 15), 6: (-14, -16)}
    clearance = path_clearance({k: np.array([[p, r, 0.0]]) for k, (p, r) in postures.items()})
    assert clearance == pytest.approx({1: 14.142, 2: 14.142, 3: 20.13, 4: 12.61, 5: 15.00, 6: 14.87}, abs=0.01)
    assert button_motions({k: np.array([[p, r, 0.0]]) for k, (p, r) in postures.items()}, 2) == (3, 5)


def test_a_motion_on_the_way_to_another_is_not_made_a_button():
    # issue 41's kind of person: c5 a small motion on c4's way (0.4 of it), the buttons in label
    # order would have been c5 and c6: the path clearance gives them to the two farthest from every path
    rec = motions(6)
    angles = rec.nodes[1].angles.copy()
    angles[rec.labels == 5] = 0.4 * angles[rec.labels == 4][0]
    profile = derive_profile([Recording({1: NodeData(angles=angles)}, rec.labels, source="person")])
    functions = {c.label: c.function for c in profile.classes[1:]}
    assert functions[5] not in ("B1", "B2")
    assert "buttons on the motions farthest from the others' paths from neutral" in describe(profile)


def test_whitening_measures_in_standard_deviations_of_a_held_posture():
    # pitch varies with sd 2 deg, roll and yaw 1 deg: a posture (2, 2, 0) deg is (1, 2, 0) sd; the ridge
    # adds 0.1 % of the mean variance (2) to each: 2 / sqrt(4.002) and 2 / sqrt(1.002)
    (spread,) = whitened({1: np.array([[2.0, 2.0, 0.0]])}, np.diag([4.0, 1.0, 1.0])).values()
    assert spread == pytest.approx([2 / 4.002 ** 0.5, 2 / 1.002 ** 0.5, 0.0], abs=1e-6)
    # the pooled covariance: two classes, each +-1 deg in pitch around its own mean: variance 1
    labels = np.repeat([0, 1], 4)
    angles = np.zeros((8, 3))
    angles[:, 0] = [-1, 1, -1, 1, 9, 11, 9, 11]
    covariance = within_class_covariance([Recording({1: NodeData(angles=angles)}, labels, source="r")], [1])
    assert covariance == pytest.approx(np.diag([1.0, 0.0, 0.0]))
