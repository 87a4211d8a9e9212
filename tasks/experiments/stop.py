"""Termination signals that always end a session.

A signal handler that only raises ``KeyboardInterrupt`` can be lost: the raise lands wherever the
main thread is, and code there may swallow or merely print it (a finalizer, a callback, an
``except Exception`` around a compiled call, whose interrupted run comes back as a ``SystemError``).
``StopRequest`` keeps the request: its handler records the signal and raises, and the session
calls ``check`` on every tick and between trials, which raises again while the request stands, so
the session ends as a Ctrl-C ends it whatever swallowed the first raise. While ``shielded`` (the
last trial's files being written after an interruption), a signal is recorded, not raised, and
``check`` raises when the shield lifts.
"""
from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

# Ctrl-C, a `kill`, a closed terminal: each ends a session as Ctrl-C does
TERMINATION = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@dataclass
class StopRequest:
    """The first termination signal received (None: none yet); see the module docstring."""

    signal: signal.Signals | None = None
    _shields: int = field(default=0, repr=False)

    def handle(self, signum: int, frame) -> None:
        """The signal handler: record the request, and raise it unless shielded."""
        if self.signal is None:
            self.signal = signal.Signals(signum)
        self.check()

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` (named by the signal) if a stop was requested and no shield is up."""
        if self.signal is not None and not self._shields:
            raise KeyboardInterrupt(self.signal.name)

    @contextmanager
    def shielded(self) -> Iterator[None]:
        """Signals recorded but not raised inside (files being written); raised when it ends."""
        self._shields += 1
        try:
            yield
        finally:
            self._shields -= 1
        self.check()

    @contextmanager
    def installed(self, signals: tuple[signal.Signals, ...] = TERMINATION) -> Iterator[StopRequest]:
        """This request's handler for ``signals`` inside, the handlers before it restored after."""
        before = {signum: signal.signal(signum, self.handle) for signum in signals}
        try:
            yield self
        finally:
            for signum, handler in before.items():
                signal.signal(signum, handler)
