"""A base station in software: plays raw samples as 32-byte frames at the real rate.

The samples come from a recording, or block by block from any generator (``block_chunks``;
``bomi emulate --participant`` plays a virtual participant that way, see tasks.participants.wire).

Nodes are interleaved sample by sample (node 1, 2, ... with the same counter), optionally with
frame loss (the counter still advances, as on the radio link) and byte corruption, deterministic
for a seed. Sinks: a pseudo-terminal (``pty``), ``socket://HOST:PORT`` (waits for one client)
or any pyserial URL/port. Encoding is exact: only whole int16 raw values are accepted.
"""
from __future__ import annotations

import os
import select
import socket
import time
import tty
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Protocol
from urllib.parse import urlsplit

import numpy as np
import serial

from bomi.errors import BomiError
from bomi.frames import COUNTER_MODULO, SAMPLE_RATE_HZ, ImuFrame, encode_imu_frame, imu_node_id
from bomi.recording import RAW_SIGNALS, Recording
from bomi.serial_source import BASE_STATION_BAUD, open_port

# pyserial flushes the input (a tty's queue, a socket's ready bytes) right after opening a port:
# give the reader time to get past that before streaming.
READER_SETTLE_S = 0.3
_SIGNALS = ("mag", "gyro", "acc")  # frame order


@dataclass(frozen=True)
class EmulatorConfig:
    rate_hz: float = SAMPLE_RATE_HZ
    loss: float = 0.0     # probability that a frame is dropped
    corrupt: float = 0.0  # probability that a byte is altered
    seed: int = 0

    def __post_init__(self) -> None:
        if not 1000 / 255 <= self.rate_hz <= 1000:
            raise BomiError(f"--rate {self.rate_hz:g}: the frame's period byte allows 3.93..1000 Hz")
        for name in ("loss", "corrupt"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise BomiError(f"--{name} {getattr(self, name):g}: must be a probability in [0, 1)")

    @property
    def period_ms(self) -> int:
        return round(1000 / self.rate_hz)


@dataclass
class EmulatorStats:
    samples: int = 0
    frames_sent: int = 0
    frames_dropped: int = 0
    bytes_corrupted: int = 0


def raw_samples(rec: Recording) -> dict[int, np.ndarray]:
    """Per node index: (n, 9) int array of mag, gyro, acc as the frame carries them.

    Refuses values that a frame cannot carry exactly (the published .mat files hold rotated,
    non-integer raw values).
    """
    rec.require(rec.node_indices, RAW_SIGNALS, "a base-station stream")
    raw = {}
    for index, node in sorted(rec.nodes.items()):
        for signal in _SIGNALS:
            values = getattr(node, signal)
            bad = np.flatnonzero((values != np.round(values)).any(axis=1)
                                 | (values < -32768).any(axis=1) | (values > 32767).any(axis=1))
            if bad.size:
                row = bad[0]
                raise BomiError(
                    f"{rec.source}: node {index} {signal} at row {row + 1} is {values[row].tolist()}: "
                    "a frame carries whole int16 sensor counts, this recording holds other values")
        raw[index] = np.hstack([getattr(node, signal) for signal in _SIGNALS]).astype(np.int64)
    return raw


def frame_chunks(raw: dict[int, np.ndarray], config: EmulatorConfig,
                 stats: EmulatorStats) -> Iterator[tuple[float, bytes]]:
    """(send time in s, bytes of every node's frame for one sample), with loss and corruption."""
    return block_chunks([raw], config, stats)


def block_chunks(blocks: Iterable[dict[int, np.ndarray]], config: EmulatorConfig,
                 stats: EmulatorStats) -> Iterator[tuple[float, bytes]]:
    """:func:`frame_chunks` of consecutive blocks of raw samples (e.g. made as they are played)."""
    rng = np.random.default_rng(config.seed)
    k = 0
    for raw in blocks:
        for rows in zip(*(values.tolist() for values in raw.values())):
            frames = []
            for index, row in zip(raw, rows):
                if rng.random() < config.loss:
                    stats.frames_dropped += 1
                    continue
                frames.append(encode_imu_frame(ImuFrame(imu_node_id(index), config.period_ms, k % COUNTER_MODULO,
                                                        tuple(row[0:3]), tuple(row[3:6]), tuple(row[6:9]))))
            stats.frames_sent += len(frames)
            stats.samples += 1
            chunk = bytearray(b"".join(frames))
            if config.corrupt:
                hit = np.flatnonzero(rng.random(len(chunk)) < config.corrupt)
                for i, flip in zip(hit.tolist(), rng.integers(1, 256, hit.size).tolist()):
                    chunk[i] ^= flip
                stats.bytes_corrupted += hit.size
            yield k / config.rate_hz, bytes(chunk)
            k += 1


class Sink(Protocol):
    description: str

    def wait_for_reader(self) -> None:
        """Block until someone reads the stream (where the sink can tell)."""

    def write(self, data: bytes) -> bool:
        """Send ``data``; False once the reader has gone."""

    def finish(self) -> None:
        """After the last frame: let the reader take what was sent, then release everything."""


class PtySink:
    """A pseudo-terminal in raw mode; the reader opens ``description`` (the slave path)."""

    def __init__(self, linger_s: float):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.description = os.ttyname(slave)
        os.close(slave)  # while no reader holds the slave, the master reports POLLHUP
        self.linger_s = linger_s
        self._poll = select.poll()
        self._poll.register(self.master, select.POLLOUT)

    def _reader_present(self) -> bool:
        events = self._poll.poll(0)
        return not (events and events[0][1] & select.POLLHUP)

    def wait_for_reader(self) -> None:
        while not self._reader_present():
            time.sleep(0.05)
        time.sleep(READER_SETTLE_S)

    def write(self, data: bytes) -> bool:
        view = memoryview(data)
        while view:
            events = self._poll.poll(1000)  # blocks while the reader lags and the buffer is full
            if events and events[0][1] & select.POLLHUP:
                return False
            if events:
                view = view[os.write(self.master, view):]
        return True

    def finish(self) -> None:
        deadline = time.monotonic() + self.linger_s
        while self._reader_present() and time.monotonic() < deadline:
            time.sleep(0.05)
        os.close(self.master)


class SocketSink:
    """Listens on ``socket://HOST:PORT`` and streams to the first client that connects."""

    def __init__(self, url: str):
        parts = urlsplit(url)
        try:
            address = (parts.hostname or "127.0.0.1", parts.port or 0)
            self._server = socket.create_server(address)
        except (OSError, ValueError) as exc:
            raise BomiError(f"{url}: cannot listen there ({exc})") from None
        host, port = self._server.getsockname()[:2]
        self.description = f"socket://{host}:{port}"
        self._client: socket.socket | None = None

    def wait_for_reader(self) -> None:
        self._client, _ = self._server.accept()
        self._server.close()
        time.sleep(READER_SETTLE_S)

    def write(self, data: bytes) -> bool:
        try:
            self._client.sendall(data)
        except OSError:
            return False
        return True

    def finish(self) -> None:
        self._client.close()


class PortSink:
    """Any pyserial port or URL (a real serial port wired to the host, ``loop://``, ...)."""

    def __init__(self, url: str, baudrate: int = BASE_STATION_BAUD):
        self.description = url
        self._port = open_port(url, baudrate)

    def wait_for_reader(self) -> None:
        """A serial line cannot tell whether anyone listens."""

    def write(self, data: bytes) -> bool:
        try:
            self._port.write(data)
        except (serial.SerialException, OSError):
            return False
        return True

    def finish(self) -> None:
        self._port.flush()
        self._port.close()


def open_sink(to: str, linger_s: float = 5.0, baudrate: int = BASE_STATION_BAUD) -> Sink:
    """``pty`` -> a new pseudo-terminal, ``socket://...`` -> a listening socket, else a port URL."""
    if to == "pty":
        return PtySink(linger_s)
    if to.startswith("socket://"):
        return SocketSink(to)
    return PortSink(to, baudrate)


def play(chunks: Iterator[tuple[float, bytes]], sink: Sink,
         clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> bool:
    """Send each chunk at its time (relative to the first); False if the reader went away."""
    start = clock()
    for at, data in chunks:
        delay = start + at - clock()
        if delay > 0:
            sleep(delay)
        if not sink.write(data):
            return False
    return True
