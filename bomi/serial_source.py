"""A live base-station stream: pyserial's ``serial_for_url`` -> :class:`~bomi.frames.FrameParser`.

Any URL pyserial knows works: a real port (``/dev/ttyUSB0``, 1,998,848 baud, raw mode, which is
what pyserial sets up on POSIX), a pseudo-terminal path, ``socket://host:port``, ``loop://``.
When the stream is lost (USB unplugged, pty or socket closed) the source says so on one line,
reconnects with exponential backoff and goes on; after the last attempt, or when the time asked
for runs out while waiting, it raises StreamLost.

Reading: the port is opened non-blocking (timeout 0) and each read asks for up to READ_SIZE
bytes, so a read returns everything that has arrived, on every kind of port. ``in_waiting`` is
not trusted: pyserial's socket:// reports 1 whatever is queued, which made a 60 Hz reader take
one frame per tick and fall ever further behind a 3-node stream. When nothing has arrived the
source waits ``poll_s`` (0 for a caller that paces itself) and yields b"".

``StreamReader`` reads a source on a thread of its own, so that neither a read nor a reconnection
(its backoff waits seconds) ever holds up a caller that must keep time: the live loop takes
whatever has arrived with ``poll()``, which never waits.
"""
from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import serial

from bomi.errors import BomiError
from bomi.frames import FrameParser, ImuFrame, SafetyKeyEvent

BASE_STATION_BAUD = 1_998_848
READ_SIZE = 1 << 16  # more than a second of a full 6-node network (12 kB/s)
POLL_S = 0.005       # wait between empty reads: far below a frame period (16 ms)


class StreamLost(BomiError):
    """The stream went away and did not come back (within the attempts or the time asked for)."""


def _stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


@dataclass(frozen=True)
class RetryPolicy:
    """Reconnection after a lost stream: ``attempts`` tries, delays doubling up to ``max_delay_s``."""

    attempts: int = 6
    first_delay_s: float = 0.5
    max_delay_s: float = 8.0

    def delays(self) -> list[float]:
        return [min(self.first_delay_s * 2 ** k, self.max_delay_s) for k in range(self.attempts)]


def open_port(url: str, baudrate: int = BASE_STATION_BAUD, timeout: float | None = 0.0) -> serial.SerialBase:
    """Open ``url`` with pyserial; any failure becomes a one-line BomiError naming the port."""
    try:
        return serial.serial_for_url(url, baudrate=baudrate, timeout=timeout)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise BomiError(f"{url}: cannot open the port ({_one_line(exc)})") from None


@dataclass
class SerialSource:
    """Frames from a base station at ``url``; iterate :meth:`batches`. Use as a context manager."""

    url: str
    baudrate: int = BASE_STATION_BAUD
    poll_s: float = POLL_S
    retry: RetryPolicy = field(default_factory=RetryPolicy)
    parser: FrameParser = field(default_factory=FrameParser)
    log: Callable[[str], None] = _stderr
    clock: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep
    port: serial.SerialBase | None = field(default=None, init=False)
    reconnections: int = field(default=0, init=False)

    def open(self) -> SerialSource:
        if self.port is None:
            self.port = open_port(self.url, self.baudrate)
        return self

    def close(self) -> None:
        if self.port is not None:
            self.port.close()
            self.port = None

    def __enter__(self) -> SerialSource:
        return self.open()

    def __exit__(self, *exc_info) -> None:
        self.close()

    def chunks(self, deadline: float | None = None) -> Iterator[bytes]:
        """Raw bytes as they arrive, all that is there at each read; ``b""`` when nothing has (after
        waiting ``poll_s``), so callers can keep time. Reconnection gives up at ``deadline`` (clock time)."""
        self.open()
        while True:
            try:
                data = self.port.read(READ_SIZE)
            except (serial.SerialException, OSError) as exc:
                self._reconnect(exc, deadline)
                continue
            if not data and self.poll_s:
                time.sleep(self.poll_s)  # not self.sleep: that one is the reconnection backoff
            yield data

    def batches(self, duration_s: float | None = None) -> Iterator[tuple[float, list[ImuFrame]]]:
        """(seconds since start, IMU frames completed by one chunk) until ``duration_s`` has passed,
        reconnections included."""
        start = self.clock()
        deadline = None if duration_s is None else start + duration_s
        for chunk in self.chunks(deadline):
            now = self.clock()
            elapsed = now - start
            if duration_s is not None and elapsed >= duration_s:
                return
            yield elapsed, self.parser.feed(chunk, now)

    def _reconnect(self, exc: BaseException, deadline: float | None = None) -> None:
        self.close()
        self.log(f"bomi: {self.url}: stream lost ({_one_line(exc)}); reconnecting")
        delays = self.retry.delays()
        for attempt, delay in enumerate(delays, start=1):
            if deadline is not None:
                delay = min(delay, deadline - self.clock())
                if delay <= 0:
                    raise StreamLost(f"{self.url}: stream lost and not back before the end of the time asked for "
                                     f"(last error: {_one_line(exc)})")
            self.log(f"bomi: {self.url}: retry {attempt} of {len(delays)} in {delay:g} s")
            self.sleep(delay)
            try:
                self.open()
            except BomiError as failure:
                exc = failure
                continue
            self.reconnections += 1
            self.log(f"bomi: {self.url}: reconnected")
            return
        raise StreamLost(f"{self.url}: stream lost and not back after {len(delays)} attempts "
                         f"over {sum(delays):g} s (last error: {_one_line(exc)})")


READER_EXIT_S = 2.0   # how long stop() waits for the reading thread
# A poll parses at most this many of the newest bytes (about a second of a full 6-node network): a
# backlog or a flood is not replayed and cannot make a poll take longer than a control period.
POLL_BYTES = 32 * 6 * 64


class StreamReader:
    """``source`` read on a daemon thread; :meth:`poll` hands over what has arrived, parsed, without waiting.

    The thread keeps the raw chunks with their arrival times; parsing happens in :meth:`poll`, on
    the caller's thread, so the parser is never shared. The source's reconnection backoff waits on
    an event that :meth:`stop` sets, so stopping never waits for a backoff. When the source gives up
    (``StreamLost``) the error is kept in ``error`` and ``poll`` returns nothing from then on.
    """

    def __init__(self, source: SerialSource):
        self.source = source
        self.error: StreamLost | None = None
        self._chunks: deque[tuple[float, bytes]] = deque()
        self._stop = threading.Event()
        self._seen_events = 0
        self.dropped_bytes = 0
        source.sleep = self._stop.wait   # type: ignore[assignment]  # a backoff that stop() cuts short
        if not source.poll_s:
            source.poll_s = POLL_S        # the thread, not a paced caller, waits between empty reads
        self._thread = threading.Thread(target=self._read, name=f"read {source.url}", daemon=True)

    @property
    def parser(self) -> FrameParser:
        return self.source.parser

    @property
    def reconnections(self) -> int:
        """Times the source has reconnected; read after ``poll``, it counts every reconnection that came
        before the frames that poll returned (the thread counts one before it reads the new stream)."""
        return self.source.reconnections

    def start(self) -> StreamReader:
        self.source.open()
        self._thread.start()
        return self

    def _read(self) -> None:
        try:
            for chunk in self.source.chunks():
                if self._stop.is_set():
                    return
                if chunk:
                    self._chunks.append((self.source.clock(), chunk))
        except StreamLost as exc:
            if not self._stop.is_set():
                self.error = exc   # the caller reports it (once)

    def poll(self) -> tuple[list[ImuFrame], list[SafetyKeyEvent]]:
        """The IMU frames completed since the last poll, and the safety-key events the parser let through."""
        frames: list[ImuFrame] = []
        chunks = [self._chunks.popleft() for _ in range(len(self._chunks))]
        keep = POLL_BYTES
        for k in range(len(chunks) - 1, -1, -1):      # newest first: what fits in POLL_BYTES
            arrival, chunk = chunks[k]
            if len(chunk) >= keep:
                self.dropped_bytes += len(chunk) - keep + sum(len(c) for _, c in chunks[:k])
                chunks = [(arrival, chunk[len(chunk) - keep:])] + chunks[k + 1:]
                break
            keep -= len(chunk)
        for arrival, chunk in chunks:
            frames += self.source.parser.feed(chunk, arrival)
        events = self.source.parser.safety_events[self._seen_events:]
        self._seen_events += len(events)
        return frames, events

    def discard(self) -> int:
        """Drop what has arrived and not been polled (e.g. while the caller was getting ready); the bytes dropped."""
        dropped = sum(len(chunk) for chunk in (self._chunks.popleft()[1] for _ in range(len(self._chunks))))
        self.dropped_bytes += dropped
        return dropped

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=READER_EXIT_S)
        self.source.close()

    def __enter__(self) -> StreamReader:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.stop()
