"""Where a live run is shown and logged: MuJoCo's viewer, a film made by a process of its own,
nothing (headless), several at once; the terminal's status line and the per-tick JSON-lines log
(``tasks.trials.live`` describes what they show)."""
from __future__ import annotations

import json
import multiprocessing
import os
import queue
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Protocol

import mujoco

from bomi.errors import BomiError

STATUS_PERIOD_S = 0.5
VIEWER_EXIT_S = 5.0  # how long closing waits for the viewer's drawing thread to end
FILM_START_S = 60.0  # how long the film's process may take to start (imports, the scene, the encoder)
FILM_QUEUE = 4       # film frames waiting for the film's process; more are dropped
FILM_NICENESS = 19   # the film's process (and the viewer's drawing thread) at the lowest priority: the control loop gets the processor


class Display(Protocol):
    """Where a live run is shown: ``sync`` after every tick, with the tick's status line (made only
    if the display draws it)."""

    def running(self) -> bool: ...

    def sync(self, status: Callable[[], str]) -> None: ...

    def close(self) -> None: ...


class Headless:
    def running(self) -> bool:
        return True

    def sync(self, status: Callable[[], str]) -> None:
        """Nothing to draw."""

    def close(self) -> None:
        """Nothing to release."""


class PassiveViewer:
    """MuJoCo's interactive viewer, following the simulation, with the status line in its top-left
    corner (closing its window ends the run)."""

    def __init__(self, model, data, key_callback: Callable[[int], None] | None = None):
        import mujoco.viewer  # needs a display; imported only when one is there
        before, tasks_before = set(threading.enumerate()), _thread_ids()
        # the scene fills the window; Tab and Shift+Tab bring MuJoCo's side panels back
        self._handle = mujoco.viewer.launch_passive(model, data, show_left_ui=False, show_right_ui=False,
                                                    key_callback=key_callback)
        # the viewer draws from a thread of its own; close() waits for it, so that the process never
        # exits while it is still drawing into a window being destroyed
        self._threads = [thread for thread in threading.enumerate() if thread not in before]
        # and it redraws as fast as it can where the display does not pace it (no vertical sync: a
        # software renderer, a virtual X server): every thread it brought (its own, a software
        # renderer's workers) at the film's priority, so that it draws with the processor the control
        # loop leaves and never slows the loop that drives the arm
        for thread_id in _thread_ids() - tasks_before:
            try:
                os.setpriority(os.PRIO_PROCESS, thread_id, FILM_NICENESS)
            except ProcessLookupError:   # a thread that has ended meanwhile
                pass

    def running(self) -> bool:
        return self._handle.is_running()

    def sync(self, status: Callable[[], str]) -> None:
        self._handle.set_texts((mujoco.mjtFontScale.mjFONTSCALE_150, mujoco.mjtGridPos.mjGRID_TOPLEFT,
                                status().replace(" | ", "\n"), ""))
        self._handle.sync()

    def close(self) -> None:
        self._handle.close()
        for thread in self._threads:
            thread.join(timeout=VIEWER_EXIT_S)


def _thread_ids() -> set[int]:
    """This process's threads by their kernel ids, where each has a priority of its own (Linux's
    /proc); elsewhere none."""
    tasks = Path("/proc/self/task")
    return {int(task.name) for task in tasks.iterdir()} if sys.platform.startswith("linux") and tasks.is_dir() else set()


def _film(layout, path: Path, frames: multiprocessing.Queue, ready) -> None:
    """The film's process: its own copy of the scene, posed and rendered from the states it is sent.
    Film frames are due on the sender's clock at the render rate; a slot without a state of its own
    repeats the previous frame, so the film plays in real time."""
    from sim.env import ArmSim
    from sim.render import VideoWriter

    sim = ArmSim(layout=layout)
    fps = sim.config.render.fps
    with VideoWriter(path, fps) as writer:
        sim.render(("", ""))   # the rendering context and fonts made before the loop starts, not during it
        # the lowest priority once filming: the start (the scene, the GL context, the encoder) runs while
        # the loop waits for it, and at that priority it could starve for minutes on a busy machine
        os.nice(FILM_NICENESS)
        ready.set()
        start, written = None, 0
        while (item := frames.get()) is not None:
            t, qpos, caption = item
            start = t if start is None else start
            sim.data.qpos[:] = qpos
            mujoco.mj_kinematics(sim.model, sim.data)
            frame = sim.render(caption)
            due = max(int((t - start) * fps) + 1 - written, 0)   # slots up to t not yet filled
            for _ in range(due):
                writer.append(frame)
            written += due
    sim.close()


class VideoDisplay:
    """The fixed camera's view filmed to an MP4 that plays in real time, the status line as its
    caption, by a process of its own: a tick only copies the arm's pose into a short queue when a
    film frame is due (at the render rate) and drops it when the queue is full, so filming never
    slows the control loop (``dropped`` counts the film frames lost that way)."""

    def __init__(self, arm, path: Path, clock: Callable[[], float] = time.monotonic):
        self.arm, self.path, self.clock = arm, Path(path), clock
        self.fps = arm.config.render.fps
        context = multiprocessing.get_context("spawn")   # no fork of a process holding GL contexts and threads
        self._frames = context.Queue(FILM_QUEUE)
        ready = context.Event()
        self._process = context.Process(target=_film, args=(arm.layout, self.path, self._frames, ready),
                                        name="bomi film", daemon=True)
        self._process.start()
        if not ready.wait(FILM_START_S):
            self._process.kill()
            raise BomiError(f"{self.path}: the film's process did not start within {FILM_START_S:g} s")
        self._next: float | None = None
        self.frames = self.dropped = 0

    def running(self) -> bool:
        return True

    def sync(self, status: Callable[[], str]) -> None:
        now = self.clock()
        if self._next is not None and now < self._next:
            return
        self._next = now + 1.0 / self.fps if self._next is None else max(self._next + 1.0 / self.fps, now)
        fields = status().split(" | ")
        try:
            self._frames.put_nowait((now, self.arm.data.qpos.copy(), (" | ".join(fields[:5]), " | ".join(fields[5:]))))
            self.frames += 1
        except queue.Full:
            self.dropped += 1

    def close(self) -> None:
        self._frames.put(None)
        self._process.join()
        self._frames.close()


@dataclass
class Displays:
    """Several displays at once (the viewer and a film): running while all are."""

    members: Sequence[Display]

    def running(self) -> bool:
        return all(display.running() for display in self.members)

    def sync(self, status: Callable[[], str]) -> None:
        for display in self.members:
            display.sync(status)

    def close(self) -> None:
        for display in self.members:
            display.close()


def has_display(environ: Mapping[str, str] = os.environ) -> bool:
    return bool(environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY"))


def display_opens() -> bool:
    """Whether GLFW (the viewer's window library) can reach the display; the viewer would exit the process."""
    import glfw
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        opened = glfw.init()
    if opened:
        glfw.terminate()
    return bool(opened)


@dataclass
class StatusLine:
    """A status line about every ``period_s``: rewritten in place on a terminal, one line each otherwise."""

    out: IO[str] = field(default_factory=lambda: sys.stderr)
    period_s: float = STATUS_PERIOD_S
    _next: float = 0.0

    def show(self, t: float, text: Callable[[], str]) -> None:
        if t < self._next:
            return
        self._next = t + self.period_s
        if self.out.isatty():
            self.out.write("\r" + text().ljust(100))
        else:
            self.out.write(text() + "\n")
        self.out.flush()

    def close(self) -> None:
        if self.out.isatty():
            self.out.write("\n")


def _warn(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


@dataclass
class TickLog:
    """The per-tick JSON-lines log. A write that fails (disk full, EIO) gives one warning and ends
    the logging; the run goes on (``failed`` says why it stopped)."""

    out: IO[str] | None
    name: str = "--log"
    warn: Callable[[str], None] = _warn
    failed: str | None = None

    def write(self, record: dict) -> None:
        if self.out is None:
            return
        try:
            self.out.write(json.dumps(record) + "\n")
        except OSError as exc:
            self._give_up(exc)

    def _give_up(self, exc: OSError) -> None:
        self.failed = exc.strerror or str(exc)
        self.warn(f"bomi: warning: {self.name}: cannot write ({self.failed}); logging stopped, control goes on")
        out, self.out = self.out, None
        try:
            out.close()
        except OSError:
            pass   # what it could not write is lost either way; the warning said so

    def close(self) -> None:
        if self.out is not None:
            try:
                self.out.close()
            except OSError as exc:
                self._give_up(exc)


def open_log(path: Path) -> IO[str]:
    """A new log file (never replaces one)."""
    try:
        return path.open("x", encoding="utf-8")
    except FileExistsError:
        raise BomiError(f"{path}: file exists, not overwriting it") from None
    except OSError as exc:
        raise BomiError(f"{path}: cannot write the log ({exc.strerror})") from None
