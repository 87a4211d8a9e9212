"""Latency regression (issue #4, item 6) on a fixed seed, through the BoMI operator's real path.

The virtual P1 steps into each posture (a one-sample move instead of the fitted 0.8 s
minimum-jerk), so the motion onset is a single sample and every sample of delay after it is the
chain's: window, vote.  The wall-clock measurements themselves live in benchmarks/.
"""
import time
from dataclasses import replace

import pytest

from bomi.chain import OnlineChain
from bomi.frames import FrameParser, imu_index
from bomi.fusion import DT
from tasks import metrics
from tasks.episode import calibrated_channel
from tasks.participant import VirtualParticipant, load_participant
from tasks.planner import StickIntent

SEED = 3
MOVES = [StickIntent({fn: 1.0}) for fn in ("F", "B", "R", "L", "Rr", "Lr")] + \
        [StickIntent(button=b) for b in ("B1", "B2")]


@pytest.fixture(scope="module")
def stepping_p1():
    return replace(load_participant("P1"), onset_s=DT)


@pytest.fixture(scope="module")
def channel(stepping_p1):
    return calibrated_channel(stepping_p1, SEED)


def test_decision_latency_from_motion_onset_is_within_window_plus_vote(channel):
    t, tick = 0.0, 1 / 60
    for move in MOVES:
        for intent, hold in ((move, 1.5), (StickIntent(), 1.5)):
            for _ in range(int(hold / tick)):
                channel.command(intent, t, t + tick)
                t += tick
    trace = channel.log_fields()["decisions"]
    latency = metrics.decision_latencies(trace.intended, trace.decided, neutral=0)
    model = channel.chain.model
    bound = model.spec.window + model.post.vote_length
    assert len(latency) == len(MOVES)  # every motion was recognised
    assert latency.max() <= bound, f"latencies {latency.tolist()} exceed window + vote = {bound} samples"


def test_per_sample_cost_of_the_whole_chain_is_under_a_millisecond(channel, stepping_p1):
    participant = VirtualParticipant(stepping_p1, channel.profile, SEED + 1)
    participant.set_intent(1, 1.0, 5.0)
    data = participant.advance(20.0)
    chain = OnlineChain(channel.chain.model, channel.profile)
    started = time.perf_counter()
    samples = 0
    for frame in FrameParser().feed(data):
        node = imu_index(frame.node_id)
        chain.push(node, frame.acc, frame.gyro, frame.mag)
        samples += node == 1
    per_sample = (time.perf_counter() - started) / samples
    # parser + fusion of three nodes + window + FV3 + LDA + vote, per node-1 sample
    assert samples > 1000 and per_sample < 1e-3, f"{1e3 * per_sample:.3f} ms per sample"
