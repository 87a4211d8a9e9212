"""The synthetic population of new people (tasks/participants/population.py)."""
from __future__ import annotations

import numpy as np

from bomi.derived import derive_profile
from tasks.participants.population import MOTION_COUNTS, NODE_COUNTS, draw_person, pass_recording


def test_people_vary_within_the_stated_ranges_and_a_seed_is_one_person():
    people = [draw_person(seed) for seed in range(40)]
    assert {len(p.profile.nodes) for p in people} == set(NODE_COUNTS)
    assert {p.n_classes - 1 for p in people} <= set(MOTION_COUNTS) and len({p.n_classes for p in people}) >= 4
    assert any(p.glitch for p in people) and any(p.params.spasm for p in people)
    assert any(p.mounting_error_deg > 0 for p in people) and any(np.any(p.yaw_drift_deg_per_min) for p in people)
    again = draw_person(7)
    assert again.profile == people[7].profile and np.array_equal(again.neutral_drift_deg, people[7].neutral_drift_deg)
    for p in people:   # every node carries a motion, the carrying node moves most in its motions
        assert set(p.profile.class_nodes.values()) == set(p.profile.node_indices) or p.n_classes - 1 < len(p.profile.nodes)
        for label, node in p.profile.class_nodes.items():
            size = np.linalg.norm(p.params.classes[label].posture_deg, axis=1)
            assert int(np.argmax(size)) + 1 == node


def test_a_pass_is_a_recording_the_chain_reads_back_as_the_person():
    person = draw_person(1)
    first = pass_recording(person, 0)
    assert np.array_equal(first.nodes[1].angles, pass_recording(person, 0).nodes[1].angles)   # pure
    second = pass_recording(person, 1)
    assert not np.array_equal(first.nodes[1].angles[:100], second.nodes[1].angles[:100])
    derived = derive_profile([first])
    assert derived.node_indices == person.profile.node_indices
    assert derived.class_nodes == person.profile.class_nodes     # the recording shows who carries what
    # three holds of every motion, as the protocol asks
    starts = np.flatnonzero(np.diff(first.labels, prepend=-1))
    held = np.bincount(first.labels[starts])
    assert held[1:].tolist() == [3] * (person.n_classes - 1)
