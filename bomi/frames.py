"""Base-station wire format (../shared/docs/hardware.md §1): 32-byte frames, encode and parse.

The parser is incremental (feed it any chunk of bytes), resynchronises on the documented rule
(a candidate starting with 0x33 counts only if its byte 31 is 0x34; after a bad candidate the
search restarts at the next 0x33 after the old start), and never raises on bad bytes. Pure:
no I/O; arrival times are passed in by the caller.

Phantom-frame guard: the format has no checksum, so noise (or the data bytes of a real frame
after a lost byte) can pass the start/end check. An IMU frame is delivered only from a node that
has been confirmed: ``CONFIRM_FRAMES`` candidate frames of that node in a row, each with the same
period byte and a counter 1..``MAX_COUNTER_GAP`` ahead of the previous one. The frames that
confirm a node are delivered then, and every frame in arrival order (a clean stream loses nothing
and keeps its interleaving); a confirmed node's frame that breaks the rule starts a new probation,
so a phantom cannot inject a node or, beyond one frame whose counter happens to fit, a sample.
Measured by the hypothesis tests of tests/test_frames.py (rates: docs/runs.md, parser-fuzz).

Safety-key events (node 40) are guarded fail-safe. STANDBY, which holds the arm, acts at once, from
any frame. Every other event (CONTROL ends a standby; CALIBRATION retakes the neutral posture, and a
neutral taken mid-motion makes the relaxed posture read as a motion, so both can make the arm move;
unknown codes too) is delivered only when the key frame just before it (of any event, 0 included)
vouches for it: same period byte and a counter 1..``MAX_COUNTER_GAP`` behind. A phantom must then
carry id 40, a moving event, the key's period and a counter just ahead of the key's last one; the
key's real frame pattern is not documented (hardware.md) and the published recordings hold no key
frames, so the rule is chosen to work for any pattern, at a cost that depends on it: a key that
streams a frame every period acts on the event's first frame (no added latency); one that repeats the
event while held acts at the latest on its second frame (one key period); one that sends a single
frame per press acts at once when its counter counts sent frames (the previous press vouches), except
for the first press after start, and otherwise (its counter counts periods) needs the press twice
within ``MAX_COUNTER_GAP`` counters. Dropped events are counted (``key_events_unconfirmed``, in ``summary``). Phantom key
frames accepted (a fuzz of 100,000 frames per pattern, seed 0; docs/runs.md): 100 % without
the guard, 0.017-0.030 % with it (expected 16/65,536); costs per pattern in docs/signal_chain.md.
"""
from __future__ import annotations

import struct
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from bomi.compiled import kernel

FRAME_SIZE = 32
START_BYTE = 0x33
END_BYTE = 0x34
FIRST_IMU_NODE_ID = 10
MAX_IMU_NODES = 6
SAFETY_KEY_NODE_ID = 40
SAMPLE_RATE_HZ = 62.5  # every IMU node samples at 62.5 Hz (hardware.md: the period byte says 16 ms)
SAMPLE_PERIOD_S = 1.0 / SAMPLE_RATE_HZ
DEFAULT_PERIOD_MS = round(1000 / SAMPLE_RATE_HZ)
COUNTER_MODULO = 256  # the packet counter is one byte
SAFETY_EVENT_BYTE = 14
# Phantom-frame guard (module docstring). 3 frames: random bytes pass the start/end check about once
# per 65,536 positions and would then need two more frames of the same node, period and nearby counters.
# A gap of 16 counters is 256 ms of consecutive loss; a longer outage costs the next 2 frames' delay.
CONFIRM_FRAMES = 3
MAX_COUNTER_GAP = 16
# Frames are delivered in arrival order, so a frame on probation holds back the ones after it, at most
# this many (2 x 3 frames of each of 6 nodes: a real node confirms well within it, a phantom is dropped).
HOLD_FRAMES = 2 * CONFIRM_FRAMES * MAX_IMU_NODES
_OK, _PENDING, _DROPPED = 0, 1, 2

# start, node id, period, counter, unused, mag xyz, gyro xyz, acc xyz, 8 unused, end
_FRAME = struct.Struct(">BBBBx3h3h3h8xB")
_HEADER = struct.Struct(">BBBB")

Vector3 = tuple[int, int, int]


def imu_node_id(index: int) -> int:
    """Base-station node id of IMU number ``index`` (1 = headset = id 10, 2 = id 11, ...)."""
    if not 1 <= index <= MAX_IMU_NODES:
        raise ValueError(f"IMU index must be 1..{MAX_IMU_NODES}, got {index}")
    return FIRST_IMU_NODE_ID + index - 1


def imu_index(node_id: int) -> int | None:
    """Inverse of :func:`imu_node_id`; ``None`` for ids that are not IMU nodes."""
    index = node_id - FIRST_IMU_NODE_ID + 1
    return index if 1 <= index <= MAX_IMU_NODES else None


class SafetyKey(IntEnum):
    """Event codes a safety-key frame (node 40) carries in byte 14."""

    NONE = 0
    CALIBRATION = 1
    STANDBY = 2
    CONTROL = 3


@dataclass(frozen=True, slots=True)
class ImuFrame:
    """One IMU sample as sent by the base station: raw signed 16-bit sensor counts."""

    node_id: int
    period_ms: int
    counter: int
    mag: Vector3
    gyro: Vector3
    acc: Vector3


@dataclass(frozen=True, slots=True)
class SafetyKeyEvent:
    """A safety-key frame's event; ``frame_number`` is its position among all accepted frames."""

    event: int
    period_ms: int
    counter: int
    frame_number: int


def counter_step(previous: int, counter: int) -> int:
    """Samples from a frame with packet counter ``previous`` to the next one of the same node with
    ``counter`` (1 when none was lost in between; the counter wraps at ``COUNTER_MODULO``)."""
    return (counter - previous) % COUNTER_MODULO


def counter_steps(previous: int, counters: np.ndarray) -> np.ndarray:
    """``counter_step`` of each of a node's (n,) int64 ``counters`` from the one before it, the first
    from ``previous``."""
    return counter_step(np.concatenate(([previous], counters[:-1])), counters)


@dataclass
class SampleIndex:
    """Per-node sample index from the wrapping packet counters: a node's first frame counts as its
    counter, each later frame as the previous index plus ``counter_step`` (lost frames included)."""

    _last: dict[int, int] = field(default_factory=dict)

    def __call__(self, frame: ImuFrame) -> int:
        last = self._last.get(frame.node_id, frame.counter - 1)
        index = self._last[frame.node_id] = last + counter_step(last, frame.counter)
        return index

    def many(self, node_ids: np.ndarray, counters: np.ndarray) -> np.ndarray:
        """The indices of n frames in arrival order at once ((n,) node ids and packet counters), as n calls make them."""
        counters = np.asarray(counters, dtype=np.int64)
        out = np.empty(len(counters), dtype=np.int64)
        for node_id in set(node_ids.tolist()):   # each node's indices apart: the order of the nodes does not matter
            mine = np.flatnonzero(node_ids == node_id)
            last = self._last.get(node_id, int(counters[mine[0]]) - 1)
            out[mine] = last + np.cumsum(counter_steps(last, counters[mine]))
            self._last[node_id] = int(out[mine[-1]])
        return out


def encode_imu_frame(frame: ImuFrame) -> bytes:
    """The 32 bytes the base station sends for ``frame``."""
    return _FRAME.pack(START_BYTE, frame.node_id, frame.period_ms, frame.counter,
                       *frame.mag, *frame.gyro, *frame.acc, END_BYTE)


# The same 32 bytes as ``_FRAME``, as a numpy record: many frames encoded in one pass.
_FRAME_RECORD = np.dtype([("start", "u1"), ("node_id", "u1"), ("period_ms", "u1"), ("counter", "u1"), ("unused", "u1"),
                          ("mag", ">i2", 3), ("gyro", ">i2", 3), ("acc", ">i2", 3), ("unused_tail", "u1", 8),
                          ("end", "u1")])


def encode_imu_frames(node_id: int | np.ndarray, counters: np.ndarray, mag: np.ndarray, gyro: np.ndarray,
                      acc: np.ndarray, period_ms: int = DEFAULT_PERIOD_MS) -> list[bytes]:
    """``encode_imu_frame`` of n frames at once: the node id of all of them (or (n,) node ids), (n,) packet
    counters (0..255) and (n, 3) int16 mag, gyro, acc -> n frames of 32 bytes, each the bytes
    ``encode_imu_frame`` gives."""
    records = np.zeros(len(counters), dtype=_FRAME_RECORD)
    records["start"], records["node_id"], records["period_ms"], records["end"] = START_BYTE, node_id, period_ms, END_BYTE
    records["counter"] = counters
    records["mag"], records["gyro"], records["acc"] = mag, gyro, acc
    return records.view(f"S{FRAME_SIZE}").tolist()   # whole: numpy strips a bytes item's trailing zeros, END_BYTE is not 0


def frame_records(frames: Sequence[ImuFrame]) -> np.ndarray:
    """Parsed frames as ``_FRAME_RECORD`` records (the batch form of a frame list)."""
    records = np.zeros(len(frames), dtype=_FRAME_RECORD)
    if frames:
        records["start"], records["end"] = START_BYTE, END_BYTE
        header = np.array([(f.node_id, f.period_ms, f.counter) for f in frames], dtype=np.int64)
        records["node_id"], records["period_ms"], records["counter"] = header.T
        values = np.array([f.mag + f.gyro + f.acc for f in frames], dtype=np.int64).reshape(-1, 3, 3)
        records["mag"], records["gyro"], records["acc"] = values[:, 0], values[:, 1], values[:, 2]
    return records


def parse_stream(data: bytes) -> np.ndarray:
    """The IMU frames a fresh ``FrameParser`` delivers when fed ``data`` whole, as ``_FRAME_RECORD``
    records (fields node_id, period_ms, counter, mag, gyro, acc), in delivery order.

    A clean stream (whole frames back to back, IMU nodes only, each node's frames following one
    another by the guard's rule and every node confirmed within the first HOLD_FRAMES frames: the
    parser then delivers every frame in arrival order) is read in one pass; any other goes through
    the parser itself, frame by frame.  Both give the same records (tests/test_frames.py)."""
    if len(data) % FRAME_SIZE == 0:
        records = np.frombuffer(data, dtype=_FRAME_RECORD)
        if _delivered_whole(records):
            return records
    return frame_records(FrameParser().feed(data))


def _delivered_whole(records: np.ndarray) -> bool:
    """Whether a default ``FrameParser`` fed these back-to-back frames delivers every one, in order."""
    if not (np.all(records["start"] == START_BYTE) and np.all(records["end"] == END_BYTE)):
        return False
    node = records["node_id"]
    if np.any((node < FIRST_IMU_NODE_ID) | (node >= FIRST_IMU_NODE_ID + MAX_IMU_NODES)):
        return False
    for node_id in np.unique(node):
        mine = np.flatnonzero(node == node_id)
        step = np.diff(records["counter"][mine].astype(int)) % COUNTER_MODULO
        if (len(mine) < CONFIRM_FRAMES or mine[CONFIRM_FRAMES - 1] >= HOLD_FRAMES
                or np.any(records["period_ms"][mine] != records["period_ms"][mine[0]])
                or np.any((step < 1) | (step > MAX_COUNTER_GAP))):
            return False
    return True


def sample_indices(node_ids: np.ndarray, counters: np.ndarray) -> np.ndarray:
    """``SampleIndex`` of a whole sequence of frames at once: (n,) node ids and packet counters in
    arrival order -> (n,) per-node sample indices (first frame: its counter; then + ``counter_step``)."""
    return SampleIndex().many(node_ids, counters)


def encode_safety_key_frame(event: int, counter: int, period_ms: int = DEFAULT_PERIOD_MS) -> bytes:
    """A safety-key frame (node 40) carrying ``event`` in byte 14."""
    frame = bytearray(FRAME_SIZE)
    _HEADER.pack_into(frame, 0, START_BYTE, SAFETY_KEY_NODE_ID, period_ms, counter)
    frame[SAFETY_EVENT_BYTE] = event
    frame[-1] = END_BYTE
    return bytes(frame)


@dataclass
class NodeStats:
    """What the stream told about one IMU node so far."""

    frames: int = 0
    lost: int = 0          # samples lost within a stream: the counter steps of 2 .. MAX_COUNTER_GAP, less one
    restarts: int = 0      # counters that repeated or jumped further: a new stream (lost samples not countable)
    period_ms: int = 0
    last_counter: int = -1
    first_time: float | None = None
    last_time: float | None = None

    @property
    def nominal_rate_hz(self) -> float:
        """The rate the node announces (1000 / its period)."""
        return 1000.0 / self.period_ms if self.period_ms else 0.0

    @property
    def rate_hz(self) -> float:
        """Frames received per second of arrival time (0 until two arrival times are known)."""
        if self.first_time is None or self.last_time is None or self.last_time <= self.first_time:
            return 0.0
        return (self.frames - 1) / (self.last_time - self.first_time)

    def counter_stepped(self, step: int, max_gap: int) -> None:
        """A delivered frame's counter is ``step`` ahead of the node's last: within a stream (a step of
        1 .. ``max_gap``) ``step - 1`` samples were lost; a repeated counter or a longer jump (delivered only
        once the frames after it vouched for it) is a new stream: the sender restarted, the source
        reconnected or another sitting came in, and the one-byte counter cannot tell how many samples went
        between (not the 229 or 255 its arithmetic gives whatever the gap). As ``bomi.gate``'s break rule."""
        if 1 <= step <= max_gap:
            self.lost += step - 1
        else:
            self.restarts += 1

    @property
    def loss_fraction(self) -> float:
        sent = self.frames + self.lost
        return self.lost / sent if sent else 0.0


@dataclass
class FrameParser:
    """Incremental base-station frame parser; see the module docstring for the rules.

    ``safety_events``: the key events the guard let through, in order. ``confirm_frames=1``
    turns both guards off (hardware.md's framing rule alone)."""

    nodes: dict[int, NodeStats] = field(default_factory=dict)
    skipped: Counter = field(default_factory=Counter)
    safety_events: list[SafetyKeyEvent] = field(default_factory=list)
    discarded_bytes: int = 0
    frames_accepted: int = 0
    unconfirmed: int = 0          # IMU frames the phantom-frame guard dropped
    key_events_unconfirmed: int = 0   # safety-key events other than STANDBY that no key frame vouched for
    confirm_frames: int = CONFIRM_FRAMES
    max_counter_gap: int = MAX_COUNTER_GAP
    _buffer: bytearray = field(default_factory=bytearray, repr=False)
    _queue: deque = field(default_factory=deque, repr=False)       # [frame, arrival, status] in arrival order
    _probation: dict[int, list[list]] = field(default_factory=dict, repr=False)  # node id -> its queue entries
    _last: dict[int, ImuFrame] = field(default_factory=dict, repr=False)         # last frame let through
    _last_key: SafetyKeyEvent | None = field(default=None, repr=False)            # last key frame, any event

    def feed(self, data: bytes, now: float | None = None) -> list[ImuFrame]:
        """Parse ``data`` (any chunk); return the IMU frames completed by it, in order.

        ``now`` is the arrival time of the chunk (seconds, any clock); it only feeds the
        measured per-node rate.
        """
        buf = self._buffer
        buf += data
        frames: list[ImuFrame] = []
        size = len(buf)
        pos = 0
        while True:
            start = buf.find(START_BYTE, pos)
            if start < 0:
                self.discarded_bytes += size - pos
                pos = size
                break
            if start + FRAME_SIZE > size:
                self.discarded_bytes += start - pos
                pos = start
                break
            if buf[start + FRAME_SIZE - 1] != END_BYTE:
                self.discarded_bytes += start + 1 - pos
                pos = start + 1
                continue
            self.discarded_bytes += start - pos
            frames += self._accept(buf, start, now)
            pos = start + FRAME_SIZE
        del buf[:pos]
        return frames

    @property
    def idle(self) -> bool:
        """Nothing buffered, held on probation or queued: the next frame is judged on its own."""
        return not (self._buffer or self._queue or any(self._probation.values()))

    def feed_whole(self, data: bytes, now: float | None = None) -> np.ndarray | None:
        """``feed`` in one pass where it would deliver every frame of ``data`` at once and in order:
        nothing buffered or held, and ``data`` back-to-back frames of confirmed IMU nodes, each
        following its node's last frame by the guard's rule (a continuing clean stream). Then the
        frames as ``_FRAME_RECORD`` records, the parser's state advanced as ``feed`` advances it;
        otherwise None, nothing consumed (feed it to ``feed``). tests/test_frames.py compares both."""
        if not self.idle or len(data) % FRAME_SIZE:
            return None
        records = np.frombuffer(data, dtype=_FRAME_RECORD)
        if not ((records["start"] == START_BYTE).all() and (records["end"] == END_BYTE).all()):
            return None
        node, counter, period = records["node_id"], records["counter"].astype(np.int64), records["period_ms"]
        nodes = []
        for node_id in np.unique(node).tolist():
            mine = np.flatnonzero(node == node_id)
            last = self._last.get(node_id)
            if last is None or (period[mine] != last.period_ms).any():
                return None
            steps = counter_steps(last.counter, counter[mine])
            if ((steps < 1) | (steps > self.max_counter_gap)).any():
                return None
            nodes.append((node_id, mine, steps))
        self.frames_accepted += len(records)
        values = [records[name] for name in ("mag", "gyro", "acc")]
        for node_id, mine, steps in nodes:
            end = int(mine[-1])
            frame = ImuFrame(node_id, int(period[end]), int(counter[end]), *(tuple(v[end].tolist()) for v in values))
            stats = self.nodes[node_id]   # its last counter is the last frame's (nothing held)
            stats.lost += int(steps.sum()) - len(steps)
            stats.frames += len(mine)
            stats.period_ms, stats.last_counter = frame.period_ms, frame.counter
            if now is not None:
                stats.first_time = now if stats.first_time is None else stats.first_time
                stats.last_time = now
            self._last[node_id] = frame
        return records

    def _accept(self, buf: bytearray, start: int, now: float | None) -> list[ImuFrame]:
        self.frames_accepted += 1
        node_id = buf[start + 1]
        if not FIRST_IMU_NODE_ID <= node_id < FIRST_IMU_NODE_ID + MAX_IMU_NODES:
            _, node_id, period_ms, counter = _HEADER.unpack_from(buf, start)
            self.skipped[node_id] += 1
            if node_id == SAFETY_KEY_NODE_ID:
                self._key_frame(SafetyKeyEvent(buf[start + SAFETY_EVENT_BYTE], period_ms, counter,
                                               self.frames_accepted - 1))
            return []
        values = _FRAME.unpack_from(buf, start)
        frame = ImuFrame(node_id, values[2], values[3], values[4:7], values[7:10], values[10:13])
        last = self._last.get(node_id)
        chain = self._probation.setdefault(node_id, [])
        if last is not None and self._follows(last, frame):
            self._last[node_id] = frame
            if chain:
                self._drop(chain)  # the node's own stream goes on: what was on probation was not it
            elif not self._queue:
                return [self._deliver(frame, now)]  # nothing held before it: out at once (what _release does)
            self._queue.append([frame, now, _OK])
        else:
            entry = [frame, now, _OK]
            self._queue.append(entry)
            if chain and not self._follows(chain[-1][0], frame):
                self._drop(chain)
            entry[2] = _PENDING
            chain.append(entry)
            if len(chain) >= self.confirm_frames:
                for held in chain:
                    held[2] = _OK
                self._last[node_id] = frame
                chain.clear()
        return self._release()

    def _key_frame(self, key: SafetyKeyEvent) -> None:
        """STANDBY at once; any other event only if the previous key frame vouches for it (module docstring)."""
        previous, self._last_key = self._last_key, key
        if key.event == SafetyKey.NONE:
            return
        vouched = self.confirm_frames == 1 or (previous is not None and self._follows(previous, key))
        if key.event == SafetyKey.STANDBY or vouched:
            self.safety_events.append(key)
        else:
            self.key_events_unconfirmed += 1

    def _follows(self, last: ImuFrame | SafetyKeyEvent, frame: ImuFrame | SafetyKeyEvent) -> bool:
        return frame.period_ms == last.period_ms and 1 <= counter_step(last.counter, frame.counter) <= self.max_counter_gap

    def _drop(self, chain: list[list]) -> None:
        for held in chain:
            held[2] = _DROPPED
        self.unconfirmed += len(chain)
        chain.clear()

    def _release(self) -> list[ImuFrame]:
        """Frames in arrival order up to the first one still on probation; a probation that holds
        more than HOLD_FRAMES frames behind it is given up (a phantom that never repeated)."""
        queue, out = self._queue, []
        while queue:
            frame, now, status = queue[0]
            if status == _PENDING:
                if len(queue) <= HOLD_FRAMES:
                    break
                self._drop(self._probation[frame.node_id])
                continue
            queue.popleft()
            if status == _OK:
                out.append(self._deliver(frame, now))
        return out

    def _deliver(self, frame: ImuFrame, now: float | None) -> ImuFrame:
        stats = self.nodes.get(frame.node_id)
        if stats is None:
            stats = self.nodes[frame.node_id] = NodeStats()
        else:
            stats.counter_stepped(counter_step(stats.last_counter, frame.counter), self.max_counter_gap)
        stats.frames += 1
        stats.period_ms = frame.period_ms
        stats.last_counter = frame.counter
        if now is not None:
            if stats.first_time is None:
                stats.first_time = now
            stats.last_time = now
        return frame

    @property
    def total_lost(self) -> int:
        return sum(stats.lost for stats in self.nodes.values())

    def summary(self) -> str:
        """One line of signal quality: per-node rate and lost packets, skipped frames, garbage."""
        parts = [
            f"IMU{imu_index(node_id)}(id {node_id}): {stats.frames} frames, {stats.lost} lost "
            f"({100 * stats.loss_fraction:.1f} %), {stats.rate_hz:.1f} Hz"
            + (f", {stats.restarts} counter restart(s)" if stats.restarts else "")
            for node_id, stats in sorted(self.nodes.items())
        ]
        if self.skipped:
            parts.append("skipped " + ", ".join(f"id {k}: {v}" for k, v in sorted(self.skipped.items())))
        if self.unconfirmed:
            parts.append(f"{self.unconfirmed} frames dropped by the phantom-frame guard")
        if self.key_events_unconfirmed:
            parts.append(f"{self.key_events_unconfirmed} safety-key events dropped by the guard")
        parts.append(f"{self.discarded_bytes} garbage bytes")
        return "; ".join(parts)


@dataclass
class RowAssembler:
    """Groups interleaved frames of ``node_ids`` into rows holding one frame per node.

    A row is complete when every node has delivered a frame; when a node delivers again first
    (its partner's frame was lost), the row is emitted with the missing nodes' previous frames
    (counted in ``held``). Rows before every node has been seen once are dropped. Frames are
    paired by arrival, as nodes have their own clocks and counters: after a loss a row may pair
    neighbouring samples (one period apart) of different nodes.
    """

    node_ids: tuple[int, ...]
    held: int = 0
    _pending: dict[int, ImuFrame] = field(default_factory=dict, repr=False)
    _last: dict[int, ImuFrame] = field(default_factory=dict, repr=False)

    def push(self, frame: ImuFrame) -> dict[int, ImuFrame] | None:
        """Add a frame; return the row it completes, if any. Frames of other nodes are ignored."""
        if frame.node_id not in self.node_ids:
            return None
        row = self._flush() if frame.node_id in self._pending else None
        self._pending[frame.node_id] = frame
        if len(self._pending) == len(self.node_ids):
            row = self._flush()
        return row

    def _flush(self) -> dict[int, ImuFrame] | None:
        row = {**self._last, **self._pending}
        fresh = len(self._pending)
        self._pending = {}
        if len(row) < len(self.node_ids):
            return None
        self.held += len(self.node_ids) - fresh
        self._last = row
        return row


def row_positions(node_sequence: Sequence[int] | np.ndarray, node_ids: tuple[int, ...]) -> np.ndarray:
    """``RowAssembler`` over a whole sequence of frames at once: their node ids in arrival order ->
    (rows, len(node_ids)) positions in the sequence of the frame each row holds per node (a held
    frame's position repeats). The same rule, in a compiled loop (``_assembled_rows``):
    tests/test_frames.py checks it against the assembler frame by frame."""
    nodes = np.asarray(node_sequence, dtype=np.int64).reshape(-1)
    slots = np.full(len(nodes), -1, dtype=np.int64)
    for j, node_id in enumerate(node_ids):
        slots[nodes == node_id] = j
    return _assembled_rows(slots, len(node_ids))


@kernel
def _assembled_rows(slots: np.ndarray, k: int) -> np.ndarray:
    """The rows of ``row_positions`` from each frame's slot among the k nodes (-1: another node)."""
    rows = np.empty((len(slots), k), dtype=np.int64)   # a frame ends at most one row
    current = np.zeros(k, dtype=np.int64)   # the last row emitted, overwritten by the frames pending since
    full = (1 << k) - 1
    pending = 0                              # bit mask of the nodes with a frame pending
    emitted = False                          # no row yet: RowAssembler has no frame to hold, a repeat drops the pending
    count = 0
    for position in range(len(slots)):
        slot = slots[position]
        if slot < 0:
            continue
        bit = 1 << slot
        if pending & bit:                    # the node again before the row was full: emit it with held frames
            if emitted:
                rows[count, :] = current
                count += 1
            pending = 0
        current[slot] = position
        pending |= bit
        if pending == full:
            rows[count, :] = current
            count += 1
            emitted, pending = True, 0
    return rows[:count].copy()
