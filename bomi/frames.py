"""Base-station wire format (../shared/docs/hardware.md §1): 32-byte frames, encode and parse.

The parser is incremental (feed it any chunk of bytes), resynchronises on the documented rule
(a candidate starting with 0x33 counts only if its byte 31 is 0x34; after a bad candidate the
search restarts at the next 0x33 after the old start), and never raises on bad bytes. Pure:
no I/O; arrival times are passed in by the caller.
"""
from __future__ import annotations

import struct
from collections import Counter
from dataclasses import dataclass, field
from enum import IntEnum

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
    """A safety-key press; ``frame_number`` is its position among all accepted frames."""

    event: int
    counter: int
    frame_number: int


def counter_step(previous: int, counter: int) -> int:
    """Samples from a frame with packet counter ``previous`` to the next one of the same node with
    ``counter`` (1 when none was lost in between; the counter wraps at ``COUNTER_MODULO``)."""
    return (counter - previous) % COUNTER_MODULO


@dataclass
class SampleIndex:
    """Per-node sample index from the wrapping packet counters: a node's first frame counts as its
    counter, each later frame as the previous index plus ``counter_step`` (lost frames included)."""

    _last: dict[int, int] = field(default_factory=dict)

    def __call__(self, frame: ImuFrame) -> int:
        last = self._last.get(frame.node_id, frame.counter - 1)
        index = self._last[frame.node_id] = last + counter_step(last, frame.counter)
        return index


def encode_imu_frame(frame: ImuFrame) -> bytes:
    """The 32 bytes the base station sends for ``frame``."""
    return _FRAME.pack(START_BYTE, frame.node_id, frame.period_ms, frame.counter,
                       *frame.mag, *frame.gyro, *frame.acc, END_BYTE)


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
    lost: int = 0
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

    @property
    def loss_fraction(self) -> float:
        sent = self.frames + self.lost
        return self.lost / sent if sent else 0.0


@dataclass
class FrameParser:
    """Incremental base-station frame parser; see the module docstring for the rules."""

    nodes: dict[int, NodeStats] = field(default_factory=dict)
    skipped: Counter = field(default_factory=Counter)
    safety_events: list[SafetyKeyEvent] = field(default_factory=list)
    discarded_bytes: int = 0
    frames_accepted: int = 0
    _buffer: bytearray = field(default_factory=bytearray, repr=False)

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
            frame = self._accept(buf, start, now)
            if frame is not None:
                frames.append(frame)
            pos = start + FRAME_SIZE
        del buf[:pos]
        return frames

    def _accept(self, buf: bytearray, start: int, now: float | None) -> ImuFrame | None:
        self.frames_accepted += 1
        _, node_id, period_ms, counter = _HEADER.unpack_from(buf, start)
        if imu_index(node_id) is None:
            self.skipped[node_id] += 1
            if node_id == SAFETY_KEY_NODE_ID and buf[start + SAFETY_EVENT_BYTE] != SafetyKey.NONE:
                self.safety_events.append(SafetyKeyEvent(
                    buf[start + SAFETY_EVENT_BYTE], counter, self.frames_accepted - 1))
            return None
        values = _FRAME.unpack_from(buf, start)
        stats = self.nodes.get(node_id)
        if stats is None:
            stats = self.nodes[node_id] = NodeStats()
        else:
            stats.lost += (counter_step(stats.last_counter, counter) - 1) % COUNTER_MODULO  # a repeated counter: a full wrap lost
        stats.frames += 1
        stats.period_ms = period_ms
        stats.last_counter = counter
        if now is not None:
            if stats.first_time is None:
                stats.first_time = now
            stats.last_time = now
        return ImuFrame(node_id, period_ms, counter, values[4:7], values[7:10], values[10:13])

    @property
    def total_lost(self) -> int:
        return sum(stats.lost for stats in self.nodes.values())

    def summary(self) -> str:
        """One line of signal quality: per-node rate and lost packets, skipped frames, garbage."""
        parts = [
            f"IMU{imu_index(node_id)}(id {node_id}): {stats.frames} frames, {stats.lost} lost "
            f"({100 * stats.loss_fraction:.1f} %), {stats.rate_hz:.1f} Hz"
            for node_id, stats in sorted(self.nodes.items())
        ]
        if self.skipped:
            parts.append("skipped " + ", ".join(f"id {k}: {v}" for k, v in sorted(self.skipped.items())))
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
