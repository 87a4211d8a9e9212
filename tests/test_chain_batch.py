"""The chunk-at-once forms of the streaming steps against the frame-by-frame ones they stand for:
``WindowBuffer.push_many``, ``SampleIndex.many``, ``FrameParser.feed_whole``, ``OnlineChain.push_many``
and the episode's ``Receiver``, each compared with the plain per-frame calls on the same input."""
from __future__ import annotations

import dataclasses
from collections import deque

import numpy as np
import pytest

from bomi.chain import OnlineChain, train
from bomi.classifier import MajorityVote, PostProcessing
from bomi.features import WindowBuffer, features
from bomi.frames import COUNTER_MODULO, FrameParser, SampleIndex, encode_imu_frame, ImuFrame
from bomi.profiles import load_profile
from tasks.participants.imu_synth import Delivery
from tasks.participants.participant import (VirtualParticipant, calibration_session, load_participant,
                                            session_recording)
from tasks.participants.receiver import Receiver


@pytest.mark.parametrize("length,stride,kind", [(8, 1, "FV3"), (8, 3, "FV3"), (6, 2, "FV3"), (5, 2, "FV2"),
                                               (8, 1, "FV1"), (1, 1, "FV1")])
def test_window_buffer_push_many_is_push_row_by_row(length, stride, kind):
    """The features of the windows ``push_many`` makes are those of the windows ``push`` returns, to the bit."""
    rng = np.random.default_rng(0)
    one, many = WindowBuffer(length, 4, stride), WindowBuffer(length, 4, stride)
    for size in [0, 3, 1, 12, 2, 7, 30, 5]:
        rows = rng.standard_normal((size, 4))
        expected = [(k, features(kind, w[None])[0]) for k in range(size) if (w := one.push(rows[k])) is not None]
        got, made = many.push_many(rows, kind)
        assert made.tolist() == [k for k, _ in expected] and len(got) == len(expected)
        assert all(np.array_equal(g, e) for g, (_, e) in zip(got, expected))


def test_sample_index_many_is_one_call_per_frame():
    rng = np.random.default_rng(1)
    nodes = rng.choice([10, 11, 12], 300)
    counters = np.zeros(300, dtype=int)
    for node in (10, 11, 12):   # each node's counter steps 1..3 (lost frames) and wraps at 256
        mine = np.flatnonzero(nodes == node)
        counters[mine] = (200 + np.cumsum(rng.integers(1, 4, len(mine)))) % COUNTER_MODULO
    one, many = SampleIndex(), SampleIndex()
    frames = [ImuFrame(int(n), 16, int(c), (0, 0, 0), (0, 0, 0), (0, 0, 0)) for n, c in zip(nodes, counters)]
    expected = [one(frame) for frame in frames]
    got = np.concatenate([many.many(nodes[a:b], counters[a:b]) for a, b in [(0, 1), (1, 40), (40, 41), (41, 300)]])
    assert got.tolist() == expected and max(expected) > COUNTER_MODULO   # the wrap was unwrapped


def test_majority_vote_is_the_majority_of_the_last_labels_latest_on_ties():
    rng = np.random.default_rng(2)
    labels = rng.integers(0, 4, 2000).tolist()
    for length in (1, 2, 5, 8):
        vote = MajorityVote(length)
        for k, label in enumerate(labels):
            last = labels[max(0, k + 1 - length):k + 1]
            best = max(last.count(x) for x in last)
            assert vote.push(label) == next(x for x in reversed(last) if last.count(x) == best)


def _imu(node_id: int, counter: int, value: int = 0) -> bytes:
    return encode_imu_frame(ImuFrame(node_id, 16, counter % COUNTER_MODULO, (value, 1, 2), (3, value, 5), (6, 7, value)))


def test_feed_whole_is_feed_on_a_confirmed_clean_stream_and_declines_anything_else():
    start = b"".join(_imu(node, k) for k in range(3) for node in (10, 11))
    more = b"".join(_imu(node, k, k * node) for k in (3, 4, 6, 20) for node in (10, 11))
    one, whole = FrameParser(), FrameParser()
    assert whole.feed_whole(start) is None            # nodes not confirmed yet: nothing taken
    one.feed(start)
    whole.feed(start)
    expected = one.feed(more)
    records = whole.feed_whole(more, now=1.0)
    assert records is not None and len(records) == len(expected) == 8
    for record, frame in zip(records, expected):
        assert (int(record["node_id"]), int(record["counter"]), tuple(record["mag"].tolist()),
                tuple(record["gyro"].tolist()), tuple(record["acc"].tolist())) == (
            frame.node_id, frame.counter, frame.mag, frame.gyro, frame.acc)
    assert whole.nodes[10].lost == one.nodes[10].lost == 14 and whole.frames_accepted == one.frames_accepted
    assert whole.feed_whole(_imu(10, 40)) is None       # a gap the guard holds back (20 counters)
    assert whole.feed_whole(b"\x00" + _imu(10, 21)) is None   # garbage
    assert whole.feed_whole(_imu(12, 0)) is None        # a node never confirmed
    assert whole.feed_whole(_imu(10, 21)[:20]) is None  # part of a frame
    assert [f.counter for f in whole.feed(_imu(10, 21))] == [21]   # nothing was consumed by the refusals


@pytest.fixture(scope="module")
def p1_chain_model():
    params, profile = load_participant("P1"), load_profile("P1")
    session = calibration_session(params, profile, 1, repetitions=1, hold_s=2.0, neutral_s=2.0)
    model = train([session_recording(session, profile)], profile)
    # a vote and a rejection, so that the batch's posteriors, confidences and vote all count
    return params, profile, dataclasses.replace(model, post=PostProcessing(rejection_threshold=0.9, vote_length=5))


def _with_gap(delivery: Delivery, node: int) -> Delivery:
    """``delivery`` with 18 samples in a row of node ``node`` lost: a counter step the guard holds back."""
    first = delivery.sample_index[delivery.node_index == node].min() + 2
    keep = ~((delivery.node_index == node) & (delivery.sample_index >= first) & (delivery.sample_index < first + 18))
    return Delivery(delivery.arrival_s[keep], delivery.node_index[keep], delivery.sample_index[keep],
                    [f for f, k in zip(delivery.frames, keep) if k])


def test_receiver_gives_the_decisions_and_ticks_of_feeding_frame_by_frame(p1_chain_model):
    """A virtual participant's chunks (warm-up, neutral calibration, then 0.38 s chunks with intents,
    one with an 18-sample gap of node 2) through the ``Receiver`` and, tick by tick, through the
    parser and ``push_frame``: the same decisions, to the bit, at the same ticks and samples."""
    params, profile, model = p1_chain_model
    vp = VirtualParticipant(params, profile, 5)
    bounds = [12.0 + 0.1 * k for k in range(16)] + [13.5 + 0.38 * k for k in range(1, 60)]
    chunks = []
    for k, bound in enumerate(bounds):
        if bound > 14.0 and k % 6 == 0:
            vp.set_intent(sorted(params.classes)[k % len(params.classes)], 0.5 + 0.5 * (k % 2), bounds[k - 1])
        chunk = vp.deliveries(bound)
        chunks.append(_with_gap(chunk, 2) if bound > 20.5 and bounds[k - 1] <= 20.5 else chunk)

    def per_frame() -> list[tuple]:
        chain, parser, index, out = OnlineChain(model, profile), FrameParser(), SampleIndex(), []
        pending = deque(zip(np.concatenate([c.arrival_s for c in chunks]).tolist(), [f for c in chunks for f in c.frames]))
        for tick in range(1, int(bounds[-1] * 60) + 2):   # past the last arrival
            t_end = tick / 60
            data = b""
            while pending and pending[0][0] <= t_end:
                data += pending.popleft()[1]
            out += [(tick, index(f), dataclasses.astuple(d)) for f in parser.feed(data)
                    if (d := chain.push_frame(f)) is not None]
            if tick == 720:
                chain.begin_neutral_calibration()
        return out, parser, chain.calibrating

    def by_receiver() -> list[tuple]:
        receiver, out, taken = Receiver(OnlineChain(model, profile)), [], 0
        for tick in range(1, int(bounds[-1] * 60) + 2):   # past the last arrival
            t_end = tick / 60
            while taken < len(chunks) and (taken == 0 or bounds[taken - 1] < t_end - 1e-12):
                receiver.take(chunks[taken])
                taken += 1
            out += [(tick, sample, dataclasses.astuple(d)) for sample, d in receiver.until(t_end)]
            if tick == 720:
                receiver.chain.begin_neutral_calibration()
        return out, receiver.parser, receiver.chain.calibrating

    expected, parser, calibrating = per_frame()
    got, got_parser, got_calibrating = by_receiver()
    assert len(expected) > 1000 and not calibrating and parser.nodes[11].lost >= 18
    assert got == expected and got_parser.summary() == parser.summary() and got_calibrating == calibrating
    assert len({d[2][0] for d in expected}) >= 4   # several classes decided
