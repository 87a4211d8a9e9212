"""The shipped profiles and profile validation errors."""
from __future__ import annotations

import pytest

from bomi.errors import BomiError
from bomi.fusion import NodeCalibration
from bomi.profiles import PROFILE_DIR, load_profile
from sim.joystick import THREE_AXIS, TWO_AXIS
from tasks.operators.stick import arm_profile, profile_layout
from helpers import edited_copy


def test_p1_matches_the_dataset_readme():
    p1 = load_profile("P1")
    assert p1.node_indices == (1, 2, 3) and [n.node_id for n in p1.nodes] == [10, 11, 12]
    assert [c.function for c in p1.classes] == ["neutral", "F", "B", "R", "L", "Rr", "Lr", "B1", "B2"]
    assert [c.label for c in p1.classes] == list(range(9))
    assert p1.class_nodes == {1: 1, 2: 1, 3: 1, 4: 1, 5: 1, 6: 1, 7: 2, 8: 3}
    assert p1.nodes[0].calibration == NodeCalibration()            # headset constants of hardware.md
    assert p1.nodes[1].calibration == NodeCalibration.uncalibrated()
    assert p1.spec.kind == "FV3" and p1.spec.window == 8 and p1.spec.stride == 1
    assert p1.post.rejection_threshold is None and p1.post.vote_length == 1   # off by default
    assert p1.amplitude == "along_class"


@pytest.mark.parametrize("name, sites", [("P4", ["head (headband)", "right foot"]),
                                         ("P5", ["head (headband)", "left thumb"])])
def test_p4_p5_have_two_nodes_and_six_classes(name, sites):
    profile = load_profile(name)
    assert [n.site for n in profile.nodes] == sites and len(profile.classes) == 6
    assert load_profile(PROFILE_DIR / f"{name}.toml") == profile


@pytest.mark.parametrize("old, new, message", [
    ("label = 2", "label = 1", "duplicate label"),
    ('function = "neutral"', 'function = "B2"\nnode = 1', "must have function \"neutral\""),
    ('function = "neutral"', 'function = "B2"', "[classes[0]] node: a motion class needs 'node'"),
    ("node = 3", "node = 4", "[classes[8]] node: 4 is not one of the profile's nodes [1, 2, 3]"),
    ('vector = "FV3"', 'vector = "FV7"', "[features] vector: must be one of FV1, FV2, FV3, got 'FV7'"),
    ("window = 8", "window = 7", "even window"),
    ("window = 8", 'window = "8"', "[features] window: expected an integer, got '8'"),
    ("shrinkage = 0.001", "shrinkage = 2.0", "[classifier] shrinkage: must be in [0, 1], got 2.0"),
    ("shrinkage = 0.001", "shrinkage = true", "[classifier] shrinkage: expected a number or a string, got True"),
    ("vote_length = 1", "vote_length = 1\nrejection_threshold = 1.2", "rejection threshold must be in (0, 1)"),
    ("vote_length = 1", "vote_lenght = 1", "[post_processing] unknown key(s) ['vote_lenght']"),
    ("vote_length = 1", "vote_length = 99999999999999999999999", "[post_processing] vote_length: 99999999999999999999999 is not a finite number"),
    ('amplitude = "along_class"', 'amplitude = "norm"', "[proportional] amplitude: must be one of gamma, along_class"),
    ("samples = 100 ", "samples = 1000000 ", "[neutral] samples: must be in [1, 3750]"),
    ("direction_spread = 30", "direction_spread = 90", "[classifier] direction_spread: must be in [0, 89] degrees, got 90.0"),
    ("index = 3", "index = 7", "[nodes[2]] index: must be in 1..6, got 7"),
    ("node_id = 12", "node_id = 11", "distinct index and node_id"),
    ('site = "left shoulder"', 'site = "left shoulder"\ncalibration = { mounting = [[1, 0, 0], [0, 1, 0], [0, 0, 2]] }',
     "[nodes[2].calibration] mounting must be a rotation matrix"),
    ('site = "left shoulder"', 'site = "left shoulder"\ncalibration = { hard_iron = [1, 2] }',
     "[nodes[2].calibration] hard_iron: expected 3 values, got 2"),
    ('name = "P1"', 'name = "P1', "not valid TOML"),
    ('layout = "3-axis"', "layout = 2", "[joystick] layout: expected a string, got 2"),
    ('layout = "3-axis"', 'layuot = "3-axis"', "[joystick] unknown key(s) ['layuot']"),
    ('layout = "3-axis"', 'layout = "3-axis"\n[live]\nrezero_hold_s = 0.3',
     "[live] rezero_hold_s: 0.3 s must be longer than button_hold_s (0.35 s), or 0 (off)"),
    ('layout = "3-axis"', 'layout = "3-axis"\n[live]\nrezero_hold_s = -1', "[live] rezero_hold_s: must be in [0, 60] s, got -1.0"),
    ('layout = "3-axis"', 'layout = "3-axis"\n[live]\nrecalibrate_hold_s = 2',
     "[live] recalibrate_hold_s: 2 s must be longer than rezero_hold_s (3 s) and button_hold_s (0.35 s), or 0 (off)"),
    ('layout = "3-axis"', 'layout = "3-axis"\n[live]\nrecalibrate_hold_s = 61',
     "[live] recalibrate_hold_s: must be in [0, 60] s, got 61.0"),
    ("shrinkage = 0.001", 'shrinkage = 0.001\nrest_offsets = "yes"', "[classifier] rest_offsets: expected true/false, got 'yes'"),
    ('name = "P1"', 'name = "P1"\ncolour = "red"', "unknown key(s) ['colour']"),
    ("[[nodes]]", "[[nodez]]", "unknown key(s) ['nodez']"),
])
def test_invalid_profiles_name_file_and_problem(tmp_path, old, new, message):
    path = edited_copy(PROFILE_DIR / "P1.toml", tmp_path / "bad.toml", old, new)
    with pytest.raises(BomiError) as info:
        load_profile(path)
    assert str(path) in str(info.value) and message in str(info.value) and "\n" not in str(info.value)


def test_unknown_profile_name():
    with pytest.raises(BomiError, match="no such profile file .*P1, P4, P5"):
        load_profile("P9")


def test_joystick_layout_is_3_axis_unless_the_profile_says_2_axis(tmp_path):
    assert [profile_layout(arm_profile(name)) for name in ("P1", "P4", "P5")] == [THREE_AXIS, TWO_AXIS, TWO_AXIS]
    unset = edited_copy(PROFILE_DIR / "P4.toml", tmp_path / "p4.toml", 'layout = "2-axis"', "")
    assert load_profile(unset).joystick_layout is None and profile_layout(arm_profile(unset)) is THREE_AXIS


@pytest.mark.parametrize("old, new, message", [
    ('function = "F"', 'function = "Up"', "class c1 (head pitch up (+29 deg)): function must be one of F, B, R, L, Rr, Lr, B1, B2 "
                                          "or \"neutral\", got 'Up'"),
    ('layout = "3-axis"', 'layout = "4-axis"', "joystick: layout must be one of '3-axis', '2-axis', '1-axis', got '4-axis'"),
])
def test_a_profile_for_the_arm_names_only_the_arms_functions_and_layouts(tmp_path, old, new, message):
    """The chain passes function names through (bomi's loader accepts them); the arm's vocabulary checks them."""
    path = edited_copy(PROFILE_DIR / "P1.toml", tmp_path / "bad.toml", old, new)
    assert load_profile(path).name == "P1"
    with pytest.raises(BomiError) as info:
        arm_profile(path)
    assert str(info.value) == f"{path}: {message}"
