"""The twin's timing: measured from the moves found in a continuous recording, refused outside plausible bounds."""
from __future__ import annotations

import dataclasses

import pytest

from bomi.profiles import load_profile
from tasks.participants.participant import calibration_session, load_participant, session_recording
from tasks.participants.twin import ONSET_BOUNDS_S, REACTION_BOUNDS_S, fit_twin, implausible_timing


def test_the_bounds_say_which_figure_is_out():
    assert implausible_timing(0.8, 0.4) is None
    assert implausible_timing(*ONSET_BOUNDS_S[:1], REACTION_BOUNDS_S[1]) is None   # the bounds are inside
    assert implausible_timing(2.9, 0.02) == "onset 2.90 s outside 0.2-2 s; reaction 0.02 s outside 0.1-1 s"
    assert implausible_timing(0.5, 1.2) == "reaction 1.20 s outside 0.1-1 s"


@pytest.fixture(scope="module")
def continuous():
    """A P4 of known timing (onset 0.6 s, reaction 0.25 s) performing the protocol once, every row kept."""
    known = dataclasses.replace(load_participant("P4"), onset_s=0.6, reaction_s=0.25, reaction_sd_s=0.0, spasm=None,
                                evoked_spasm=None)
    profile = load_profile("P4")
    session = calibration_session(known, profile, seed=5, repetitions=1, hold_s=3.0, neutral_s=3.0)
    return known, profile, session_recording(session, profile, holds_only=False)


def test_a_plausible_timing_is_measured_and_a_stretched_clock_falls_back_to_the_prior(continuous):
    known, profile, rec = continuous
    prior = load_participant("P1")
    twin = fit_twin([rec], profile, prior, "me")
    assert twin.provenance["onset_s"].startswith("measured")
    assert twin.onset_s == pytest.approx(known.onset_s, abs=0.15) and twin.reaction_s == pytest.approx(0.25, abs=0.1)
    # the same moves on a clock running 4x: onset 2.4 s, beyond any voluntary move of the protocol
    slow = fit_twin([dataclasses.replace(rec, time=rec.time * 4.0)], profile, prior, "me")
    assert (slow.onset_s, slow.reaction_s) == (prior.onset_s, prior.reaction_s)
    line, = [f for f in slow.fallbacks if f.startswith("onset_s, reaction_s")]
    assert "the timing measured from the moves found in the signals is not plausible (onset 2." in line
