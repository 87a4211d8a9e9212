"""Latency regression (issue #4, item 6) on a fixed seed, through the BoMI operator's real path.

The virtual P1 moves briskly into each posture (a 4-sample minimum-jerk move instead of the
fitted 0.8 s), so that the delay from motion onset is the body's move plus the chain's own:
once the body holds the posture, a full window and the vote must be enough.  The wall-clock
measurements themselves live in benchmarks/.
"""
from dataclasses import replace

import pytest

from bomi.fusion import DT
from tasks.stacking import metrics
from tasks.stacking.channels import calibrated_channel
from tasks.participants.participant import load_participant
from tasks.stacking.vocabulary import StickIntent

SEED = 3
MOVE_SAMPLES = 4
MOVES = [StickIntent({fn: 1.0}) for fn in ("F", "B", "R", "L", "Rr", "Lr")] + \
        [StickIntent(button=b) for b in ("B1", "B2")]


@pytest.fixture(scope="module")
def stepping_p1():
    return replace(load_participant("P1"), onset_s=MOVE_SAMPLES * DT)


@pytest.fixture(scope="module")
def channel(stepping_p1):
    return calibrated_channel(stepping_p1, SEED)


def perform(channel, hold_s: float = 1.5):
    """Every move of MOVES held ``hold_s``, then neutral as long; the decision trace."""
    t, tick = 0.0, 1 / 60
    for move in MOVES:
        for intent, hold in ((move, hold_s), (StickIntent(), hold_s)):
            for _ in range(int(hold / tick)):
                channel.command(intent, t, t + tick)
                t += tick
    return channel.log_fields()["decisions"]


def test_decision_latency_from_motion_onset_is_within_window_plus_vote(channel):
    trace = perform(channel)
    latency = metrics.decision_latencies(trace.intended, trace.decided, neutral=0)
    model = channel.chain.model
    bound = model.spec.window + model.post.vote_length
    assert len(latency) == len(MOVES)  # every motion was recognised
    algorithmic = latency - MOVE_SAMPLES
    assert algorithmic.max() <= bound, f"latencies {latency.tolist()} exceed move + window + vote = {bound} samples"


def test_the_excused_transition_covers_the_fitted_participants_real_moves():
    """With P1's fitted 0.8 s move, every motion is recognised within ``transition_samples`` of its
    onset: the allowance the excused accuracy leaves out is not shorter than a real transition.
    (It is longer: on this seed the latencies are 9..37 samples against an allowance of 63.)"""
    channel = calibrated_channel("P1", SEED)
    trace = perform(channel, hold_s=2.5)
    latency = metrics.decision_latencies(trace.intended, trace.decided, neutral=0)
    assert len(latency) == len(MOVES) and latency.min() > 0
    assert latency.max() <= channel.transition_samples, (latency.tolist(), channel.transition_samples)
