"""Frame encoding/parsing against hardware.md §1, hand-computed values and a naive reference."""
from __future__ import annotations

import struct
from dataclasses import dataclass

import pytest
import numpy as np
from hypothesis import assume, given, settings, strategies as st

from bomi.compiled import interpreted
from bomi.frames import (
    FRAME_SIZE, FrameParser, ImuFrame, RowAssembler, SafetyKey, SampleIndex, counter_step, encode_imu_frame,
    encode_imu_frames, encode_safety_key_frame, imu_index, imu_node_id, parse_stream, row_positions, sample_indices,
    _assembled_rows,
)

# hardware.md §1 worked example: headset, counter 42, period 16 ms
WORKED_EXAMPLE = bytes.fromhex(
    "33 0A 10 2A 00 F9 A1 F7 7F 17 33 FF FF FF F5 00 05 FD 23 FC B1 3D 09 00 00 00 00 00 00 00 00 34")
WORKED_FRAME = ImuFrame(node_id=10, period_ms=16, counter=42, mag=(-1631, -2177, 5939),
                        gyro=(-1, -11, 5), acc=(-733, -847, 15625))

PROPERTY_SETTINGS = settings(max_examples=150, deadline=None)


def framing() -> FrameParser:
    """The framing rule of hardware.md alone: the phantom-frame guard off (tested on its own below)."""
    return FrameParser(confirm_frames=1)
int16 = st.integers(-32768, 32767)
vector3 = st.tuples(int16, int16, int16)


def reference_parse(stream: bytes) -> list[tuple]:
    """The documented rule, written the slow obvious way on the whole stream at once."""
    frames, i = [], 0
    while True:
        i = stream.find(b"\x33", i)
        if i < 0 or i + FRAME_SIZE > len(stream):
            return frames
        if stream[i + 31] != 0x34:
            i += 1
            continue
        raw = stream[i:i + FRAME_SIZE]
        if 10 <= raw[1] <= 15:
            words = [int.from_bytes(raw[k:k + 2], "big", signed=True) for k in range(5, 23, 2)]
            frames.append((raw[1], raw[2], raw[3], tuple(words[0:3]), tuple(words[3:6]), tuple(words[6:9])))
        i += FRAME_SIZE


def as_tuple(frame: ImuFrame) -> tuple:
    return (frame.node_id, frame.period_ms, frame.counter, frame.mag, frame.gyro, frame.acc)


def feed_in_chunks(parser: FrameParser, stream: bytes, cuts: list[int]) -> list[ImuFrame]:
    bounds = [0, *sorted(c % (len(stream) + 1) for c in cuts), len(stream)]
    frames = []
    for a, b in zip(bounds, bounds[1:]):
        frames += parser.feed(stream[a:b])
    return frames


def test_worked_example_decodes_to_documented_values():
    assert framing().feed(WORKED_EXAMPLE) == [WORKED_FRAME]


def test_worked_example_encodes_to_documented_bytes():
    assert encode_imu_frame(WORKED_FRAME) == WORKED_EXAMPLE


def test_worked_example_byte_by_byte_with_garbage_and_false_start():
    parser = framing()
    stream = b"\x00\x33\x12" + WORKED_EXAMPLE + b"\x33"
    frames = [f for byte in stream for f in parser.feed(bytes([byte]))]
    assert frames == [WORKED_FRAME]
    assert parser.discarded_bytes == 3  # the trailing 0x33 is kept, waiting for more bytes


def test_node_index_mapping():
    assert [imu_node_id(i) for i in range(1, 7)] == [10, 11, 12, 13, 14, 15]
    assert [imu_index(n) for n in (9, 10, 15, 16, 30, 40)] == [None, 1, 6, None, None, None]
    with pytest.raises(ValueError):
        imu_node_id(7)


def test_lost_packets_with_counter_wrap():
    parser = framing()
    for counter in (250, 253, 2, 3):
        parser.feed(encode_imu_frame(ImuFrame(11, 16, counter, (0, 0, 0), (0, 0, 0), (0, 0, 0))))
    # 250 -> 253 loses 251, 252; 253 -> 2 loses 254, 255, 0, 1
    assert parser.nodes[11].lost == 6
    assert parser.nodes[11].frames == 4


def test_rate_from_arrival_times_and_period():
    parser = framing()
    for k in range(11):
        parser.feed(encode_imu_frame(ImuFrame(10, 16, k, (0, 0, 0), (0, 0, 0), (0, 0, 0))), now=5.0 + k * 0.016)
    assert parser.nodes[10].rate_hz == pytest.approx(62.5)
    assert parser.nodes[10].nominal_rate_hz == 62.5


def test_non_imu_frames_skipped_and_safety_events_exposed():
    emg = bytearray(WORKED_EXAMPLE)
    emg[1] = 31
    stream = (bytes(emg) + encode_safety_key_frame(SafetyKey.STANDBY, counter=7) + WORKED_EXAMPLE
              + encode_safety_key_frame(SafetyKey.NONE, counter=8) + bytes(emg))
    parser = framing()
    assert parser.feed(stream) == [WORKED_FRAME]
    assert parser.skipped == {31: 2, 40: 2}
    assert [(e.event, e.counter, e.frame_number) for e in parser.safety_events] == [(SafetyKey.STANDBY, 7, 1)]


def test_false_start_whose_byte_31_is_end_byte_is_taken_as_a_frame():
    """The format has no checksum: a garbage 0x33 with 0x34 31 bytes later looks like a frame.

    The parser takes it (node id 0: skipped), goes on right after it and finds the next real frame;
    the real frame it overlapped is lost.
    """
    fake_start = b"\x33" + bytes(20)  # its byte 31 falls on byte 10 of the frame after it
    overlapped = bytearray(WORKED_EXAMPLE)
    overlapped[10] = 0x34
    parser = framing()
    assert parser.feed(fake_start + bytes(overlapped) + WORKED_EXAMPLE) == [WORKED_FRAME]
    assert parser.skipped == {0: 1}


@given(frame=st.builds(ImuFrame, st.integers(10, 15), st.integers(0, 255), st.integers(0, 255),
                       vector3, vector3, vector3))
@PROPERTY_SETTINGS
def test_encode_then_parse_gives_back_the_frame(frame):
    assert framing().feed(encode_imu_frame(frame)) == [frame]


@given(stream=st.binary(max_size=600) | st.lists(
           st.sampled_from([b"\x33", b"\x34", b"\x00", WORKED_EXAMPLE, WORKED_EXAMPLE[:20], WORKED_EXAMPLE[7:]]),
           max_size=40).map(b"".join),
       cuts=st.lists(st.integers(0, 10_000), max_size=8))
@PROPERTY_SETTINGS
def test_any_bytes_in_any_chunks_match_the_reference_and_never_raise(stream, cuts):
    parser = framing()
    frames = feed_in_chunks(parser, stream, cuts)
    assert [as_tuple(f) for f in frames] == reference_parse(stream)


@dataclass
class Piece:
    data: bytes
    intact: bool = False  # a whole frame, start and end bytes in place
    node_id: int = 0      # for intact IMU frames: the node and its unwrapped sequence number
    seq: int = 0


@st.composite
def noisy_streams(draw) -> list[Piece]:
    """Interleaved frames of 1-3 IMU nodes plus an EMG node (id 30), with drops, corruption,
    truncation, garbage and false start bytes between them."""
    node_ids = draw(st.lists(st.integers(10, 15), min_size=1, max_size=3, unique=True))
    first_seq = draw(st.integers(0, 255))
    pieces: list[Piece] = []
    for seq in range(first_seq, first_seq + draw(st.integers(1, 40))):
        for node_id in node_ids + [30]:
            fate = draw(st.sampled_from(["ok"] * 6 + ["drop", "corrupt", "truncate", "garbage", "false start"]))
            values = struct.unpack(">9h", draw(st.binary(min_size=18, max_size=18)))
            frame = encode_imu_frame(ImuFrame(node_id, 16, seq % 256, values[0:3], values[3:6], values[6:9]))
            if fate == "drop":
                continue
            if fate == "truncate":
                pieces.append(Piece(frame[:draw(st.integers(1, FRAME_SIZE - 1))]))
                continue
            if fate == "garbage":
                pieces.append(Piece(draw(st.binary(min_size=1, max_size=40))))
            if fate == "false start":
                pieces.append(Piece(b"\x33" + draw(st.binary(max_size=5))))
            if fate == "corrupt":
                # the start/end byte (frame lost) or a sensor byte (frame kept, with other values)
                where = draw(st.sampled_from([0, 31, *range(5, 23)]))
                mangled = bytearray(frame)
                mangled[where] ^= draw(st.integers(1, 255))
                frame = bytes(mangled)
            intact = frame[0] == 0x33 and frame[31] == 0x34
            pieces.append(Piece(frame, intact, node_id if intact and node_id < 30 else 0, seq))
    return pieces


def is_ambiguous(pieces: list[Piece]) -> bool:
    """True if some 0x33 outside an intact frame has 0x34 31 bytes later: the format cannot
    tell such a false start from a frame (see the test above)."""
    stream = b"".join(p.data for p in pieces)
    offset = 0
    for piece in pieces:
        if not piece.intact:
            for j, byte in enumerate(piece.data):
                end = offset + j + 31
                if byte == 0x33 and end < len(stream) and stream[end] == 0x34:
                    return True
        offset += len(piece.data)
    return False


@given(pieces=noisy_streams(), cuts=st.lists(st.integers(0, 10_000), max_size=10))
@PROPERTY_SETTINGS
def test_every_intact_frame_recovered_and_losses_counted(pieces, cuts):
    assume(not is_ambiguous(pieces))
    parser = framing()
    frames = feed_in_chunks(parser, b"".join(p.data for p in pieces), cuts)

    imu = [p for p in pieces if p.node_id]
    assert [encode_imu_frame(f) for f in frames] == [p.data for p in imu]
    for node_id in {p.node_id for p in imu}:
        seqs = [p.seq for p in imu if p.node_id == node_id]
        assert parser.nodes[node_id].frames == len(seqs)
        assert parser.nodes[node_id].lost == (seqs[-1] - seqs[0]) - (len(seqs) - 1)
    assert parser.skipped.get(30, 0) == sum(p.intact and p.data[1] == 30 for p in pieces)


# --------------------------------------------------------------------------------- phantom-frame guard
def imu_frame(node_id: int, counter: int, value: int = 0, period_ms: int = 16) -> bytes:
    return encode_imu_frame(ImuFrame(node_id, period_ms, counter % 256, (value, 1, 2), (3, value, 4), (5, 6, value)))


@given(nodes=st.lists(st.integers(10, 15), min_size=1, max_size=6, unique=True), samples=st.integers(3, 30),
       first=st.integers(0, 255), cuts=st.lists(st.integers(0, 10_000), max_size=8))
@PROPERTY_SETTINGS
def test_guard_delivers_a_clean_stream_whole_and_in_arrival_order(nodes, samples, first, cuts):
    stream = [imu_frame(node, first + k, k) for k in range(samples) for node in nodes]
    parser = FrameParser()
    assert [encode_imu_frame(f) for f in feed_in_chunks(parser, b"".join(stream), cuts)] == stream
    assert parser.unconfirmed == 0


def test_guard_drops_a_node_seen_fewer_than_three_times_in_a_row():
    real = [imu_frame(10, k, k) for k in range(100)]
    phantom_twice = imu_frame(13, 7) + imu_frame(13, 8)
    stream = b"".join(real[:50]) + phantom_twice + b"".join(real[50:])
    parser = FrameParser()
    frames = parser.feed(stream)
    assert [encode_imu_frame(f) for f in frames] == real   # node 13 never delivered, node 10 all
    assert set(parser.nodes) == {10} and parser.unconfirmed == 2


def test_guard_refuses_a_confirmed_nodes_frame_with_a_wild_counter_and_loses_no_real_frame():
    real = [imu_frame(10, k, k) for k in range(20)]
    wild = imu_frame(10, 200, 999)  # counter 190 ahead of the stream: not this node's next sample
    stream = b"".join(real[:10]) + wild + b"".join(real[10:])
    parser = FrameParser()
    assert [encode_imu_frame(f) for f in parser.feed(stream)] == real
    assert parser.nodes[10].lost == 0 and parser.unconfirmed == 1


def test_guard_needs_the_same_period_and_counters_that_follow():
    parser = FrameParser()
    # three frames of node 11 whose counters jump by more than MAX_COUNTER_GAP, or whose period changes
    assert parser.feed(imu_frame(11, 0) + imu_frame(11, 100) + imu_frame(11, 200)) == []
    assert parser.feed(imu_frame(12, 0) + imu_frame(12, 1, period_ms=20) + imu_frame(12, 2)) == []
    # a node back after a long outage (counters jumped) is delivered again once it repeats
    parser = FrameParser()
    before = [imu_frame(10, k) for k in range(5)]
    after = [imu_frame(10, 100 + k) for k in range(5)]
    assert len(parser.feed(b"".join(before + after))) == 10


def test_well_formed_random_frames_in_noise_are_all_refused():
    """2000 frames that pass the start/end check (random IMU id, period, counter) amid random bytes:
    the framing rule alone takes every one, the guard none (rates: docs/runs.md)."""
    import numpy as np
    rng = np.random.default_rng(3)
    pieces = []
    for _ in range(2000):
        pieces.append(rng.bytes(int(rng.integers(0, 64))).replace(b"\x33", b"\x00"))
        pieces.append(imu_frame(int(rng.integers(10, 16)), int(rng.integers(0, 256)), period_ms=int(rng.integers(0, 256))))
    stream = b"".join(pieces)
    assert len(framing().feed(stream)) == 2000
    assert FrameParser().feed(stream) == []


N, S, C, K = SafetyKey.NONE, SafetyKey.STANDBY, SafetyKey.CONTROL, SafetyKey.CALIBRATION


@pytest.mark.parametrize("frames, delivered, dropped", [
    # a lone key frame, nothing before it: STANDBY acts at once; what may let the arm move does not
    ([(S, 7)], [(S, 7)], 0),
    ([(C, 7)], [], 1),
    ([(K, 7)], [], 1),
    ([(9, 7)], [], 1),                                        # an unknown code is not known to be safe
    # a key streaming a frame every period: the event acts on its first frame (across the wrap)
    ([(N, 254), (N, 255), (C, 0), (N, 1)], [(C, 0)], 0),
    # a key repeating the event while held, nothing before: from its second frame
    ([(C, 50), (C, 51), (C, 52)], [(C, 51), (C, 52)], 1),
    # one frame per press, the counter counting sent frames: the previous press vouches, the first has none
    ([(K, 6), (S, 7), (C, 8)], [(S, 7), (C, 8)], 1),
    # lost key frames: up to 16 counters after the key's last frame, not 17, not the same counter
    ([(N, 0), (C, 16)], [(C, 16)], 0),
    ([(N, 0), (C, 17)], [], 1),
    ([(N, 5), (C, 5)], [], 1),
    # the period byte must be the key's
    ([(N, 5), (C, 6, 20)], [], 1),
    # a phantom key frame (wild counter) between two presses breaks the chain for the next one only
    ([(S, 7), (N, 200), (C, 8), (C, 9)], [(S, 7), (C, 9)], 1),
])
def test_key_events_that_let_the_arm_move_need_the_previous_key_frame_standby_does_not(frames, delivered, dropped):
    """IMU frames between the key frames do not matter; hand-computed from the rule in bomi.frames."""
    stream = b"".join(encode_safety_key_frame(*frame) + imu_frame(10, k) for k, frame in enumerate(frames))
    parser = FrameParser()
    parser.feed(stream)
    assert [(e.event, e.counter) for e in parser.safety_events] == delivered
    assert parser.key_events_unconfirmed == dropped
    assert ("safety-key events dropped by the guard" in parser.summary()) == (dropped > 0)
    # the framing rule alone (confirm_frames=1) takes every event, as the parser did before the guard
    unguarded = framing()
    unguarded.feed(stream)
    assert [(e.event, e.counter) for e in unguarded.safety_events] == [frame[:2] for frame in frames if frame[0] != N]


@given(events=st.lists(st.sampled_from(list(SafetyKey)), min_size=1, max_size=40), first=st.integers(0, 255),
       period=st.integers(1, 255), cuts=st.lists(st.integers(0, 2_000), max_size=6))
@PROPERTY_SETTINGS
def test_a_streaming_key_loses_no_event_to_the_guard(events, first, period, cuts):
    """A key sending a frame every period (counter +1 each) after one idle frame: every event acts, in any chunks."""
    frames = [(SafetyKey.NONE, first)] + [(event, (first + 1 + k) % 256) for k, event in enumerate(events)]
    stream = b"".join(encode_safety_key_frame(event, counter, period) for event, counter in frames)
    parser = FrameParser()
    feed_in_chunks(parser, stream, cuts)
    assert [(e.event, e.counter) for e in parser.safety_events] == [f for f in frames if f[0] != SafetyKey.NONE]
    assert parser.key_events_unconfirmed == 0


def test_sample_index_unwraps_each_nodes_counter_and_counts_lost_samples():
    """Hand-computed: node 10 starts at 254, wraps after 255 and loses counter 1; node 11 keeps its own count."""
    frames = [ImuFrame(node, 16, counter, (0, 0, 0), (0, 0, 0), (0, 0, 0))
              for node, counter in ((10, 254), (11, 7), (10, 255), (10, 0), (11, 8), (10, 2))]
    index = SampleIndex()
    assert [index(f) for f in frames] == [254, 7, 255, 256, 8, 258]
    assert [counter_step(a, b) for a, b in ((254, 255), (255, 0), (0, 2), (3, 3))] == [1, 1, 2, 0]


@settings(max_examples=50, deadline=None)
@given(node=st.integers(1, 6), values=st.lists(st.tuples(vector3, vector3, vector3, st.integers(0, 255),
                                                         st.integers(1, 6)), max_size=30),
       period=st.integers(0, 255))
def test_frames_encoded_at_once_are_the_frames_encoded_one_by_one(node, values, period):
    """One node's frames, and frames of a node each (the last field of ``values``)."""
    mag, gyro, acc = (np.array([v[k] for v in values], dtype=np.int64).reshape(len(values), 3) for k in range(3))
    counters = np.array([v[3] for v in values], dtype=np.int64)
    many = encode_imu_frames(imu_node_id(node), counters, mag, gyro, acc, period)
    one_by_one = [encode_imu_frame(ImuFrame(imu_node_id(node), period, c, m, g, a)) for m, g, a, c, _ in values]
    assert many == one_by_one
    ids = np.array([imu_node_id(v[4]) for v in values], dtype=np.int64)
    each_own = [encode_imu_frame(ImuFrame(imu_node_id(k), period, c, m, g, a)) for m, g, a, c, k in values]
    assert encode_imu_frames(ids, counters, mag, gyro, acc, period) == each_own


# ------------------------------------------------------------------ whole-stream (batch) forms
def as_record_tuples(records: np.ndarray) -> list[tuple]:
    return [(int(r["node_id"]), int(r["period_ms"]), int(r["counter"]), tuple(r["mag"].tolist()),
             tuple(r["gyro"].tolist()), tuple(r["acc"].tolist())) for r in records]


@given(nodes=st.lists(st.integers(10, 15), min_size=1, max_size=6, unique=True), samples=st.integers(0, 40),
       seed=st.integers(0, 2**32 - 1), loss=st.sampled_from([0.0, 0.1, 0.5]),
       damage=st.sampled_from(["none", "garbage", "key", "wild counter", "late node", "period", "tail"]))
@PROPERTY_SETTINGS
def test_parse_stream_delivers_what_the_parser_delivers(nodes, samples, seed, loss, damage):
    """The whole-stream parse (one pass over a clean stream, else the parser) against the parser fed
    the same bytes, on clean interleaved streams with losses and on damaged ones."""
    rng = np.random.default_rng(seed)
    stream = [imu_frame(node, k, int(rng.integers(-999, 999))) for k in range(samples) for node in nodes
              if rng.random() >= loss]
    if damage == "garbage" and stream:
        stream.insert(int(rng.integers(len(stream))), b"\x33\x01junk")
    elif damage == "key":
        stream.insert(int(rng.integers(len(stream) + 1)), encode_safety_key_frame(SafetyKey.STANDBY, 1))
    elif damage == "wild counter" and stream:
        stream.insert(int(rng.integers(len(stream))), imu_frame(nodes[0], 200))
    elif damage == "late node":
        stream += [imu_frame(9 + 1 + 5, k) for k in range(4)] if 15 not in nodes else []
    elif damage == "period" and stream:
        stream.append(imu_frame(nodes[0], samples, period_ms=20))
    elif damage == "tail":
        stream.append(b"\x33\x0a")
    data = b"".join(stream)
    assert as_record_tuples(parse_stream(data)) == [as_tuple(f) for f in FrameParser().feed(data)]


@given(frames=st.lists(st.tuples(st.integers(10, 12), st.integers(0, 255)), max_size=60))
@PROPERTY_SETTINGS
def test_sample_indices_are_sample_index_frame_by_frame(frames):
    index = SampleIndex()
    expected = [index(ImuFrame(node, 16, counter, (0, 0, 0), (0, 0, 0), (0, 0, 0))) for node, counter in frames]
    nodes = np.array([f[0] for f in frames], dtype=int)
    counters = np.array([f[1] for f in frames], dtype=int)
    assert sample_indices(nodes, counters).tolist() == expected


def test_row_positions_compiled_and_interpreted_are_the_same_rows():
    """The kernel compiled by numba (where installed) and run as Python give the same rows on a long
    stream of three nodes with losses, repeats and other nodes' frames."""
    rng = np.random.default_rng(3)
    slots = rng.choice([-1, 0, 1, 2], size=5000, p=[0.05, 0.32, 0.32, 0.31]).astype(np.int64)
    rows = _assembled_rows(slots, 3)
    assert rows.shape[1] == 3 and 1000 < len(rows) < 5000
    assert np.array_equal(rows, interpreted(_assembled_rows)(slots, 3))


@given(sequence=st.lists(st.integers(9, 13), max_size=80), k=st.integers(1, 4))
@PROPERTY_SETTINGS
def test_row_positions_are_the_row_assemblers_rows(sequence, k):
    """Rows of positions against RowAssembler fed frames one by one (losses, repeats, other nodes)."""
    ids = tuple(range(10, 10 + k))
    frames = [ImuFrame(node, 16, position % 256, (position, 0, 0), (0, 0, 0), (0, 0, 0))
              for position, node in enumerate(sequence)]
    assembler = RowAssembler(ids)
    expected = [[row[node_id].mag[0] for node_id in ids] for row in map(assembler.push, frames) if row is not None]
    assert row_positions(sequence, ids).tolist() == expected
