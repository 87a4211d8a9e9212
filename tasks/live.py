"""The live loop: a base-station stream drives the simulated arm at its 60 Hz control rate.

    SerialSource -> OnlineChain -> Decision -> sanitizer -> DecisionStick -> Watchdog -> ArmSim.step

The arm never knows where the stick came from. Ticks are paced by the wall clock; each tick reads
whatever bytes arrived (without blocking), feeds their frames to the chain, and steps the arm once.
Safety: when no frame has arrived for ``Watchdog.timeout_s`` the tick's stick is zero (the
command is zero on the first tick after the timeout) and the last decision is forgotten, so the
arm moves again only on decisions made from fresh frames; decisions with an unknown class, a
NaN or an out-of-range value are dropped before the stick (and counted); the safety key's
standby holds the arm until its control event (its calibration event retakes the neutral posture).

Log (``--log L``, JSON lines, one object per control tick):
``tick``, ``t`` (wall seconds since start), ``frames`` (IMU frames read this tick), ``lost``
(frames lost so far, from the packet counters), ``stale`` (the watchdog held the arm),
``standby`` (the safety key held the arm), ``calibrating`` (neutral calibration still
collecting), ``decisions`` (the chain's decisions this tick: label, name, function, confidence,
rejected, gamma, nu, sample_index = node-1 samples counted from the end of the neutral
calibration), ``dropped`` (decisions the sanitizer refused: sample_index, reason), ``deflection`` and ``pressed`` (the
stick sent to the arm), ``mode`` (after the tick), ``linear`` (m/s), ``angular`` (rad/s) and
``finger`` (the arm's command); ``neutral`` (offsets per node index, degrees) on the tick they
take effect.
"""
from __future__ import annotations

import functools
import json
import math
import os
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import IO, Protocol

import mujoco
import numpy as np

from bomi.chain import Decision, OnlineChain
from bomi.errors import BomiError
from bomi.frames import FrameParser, ImuFrame, SafetyKey, SafetyKeyEvent
from bomi.serial_source import SerialSource
from sim.joystick import ArmCommand, JoystickState
from tasks.stick import DecisionStick

WATCHDOG_TIMEOUT_S = 0.1
STATUS_PERIOD_S = 0.5
VIEWER_EXIT_S = 5.0  # how long closing waits for the viewer's drawing thread to end


# ---------------------------------------------------------------------------------- safety
@dataclass
class Watchdog:
    """Expired when no frame has arrived for ``timeout_s`` (or none ever has). Pure: times are passed in."""

    timeout_s: float = WATCHDOG_TIMEOUT_S
    last_frame_s: float | None = None
    trips: int = 0          # times it went from fresh to expired
    _was_expired: bool = field(default=True, repr=False)

    def frames_arrived(self, now: float) -> None:
        self.last_frame_s = now

    def expired(self, now: float) -> bool:
        expired = self.last_frame_s is None or now - self.last_frame_s >= self.timeout_s
        self.trips += expired and not self._was_expired
        self._was_expired = expired
        return expired


def refusal(decision: Decision, functions: Mapping[int, str]) -> str | None:
    """Why ``decision`` must not reach the arm (None if it may). ``functions``: label -> function of the profile."""
    if functions.get(decision.label) != decision.function:
        return f"unknown class {decision.label} ({decision.function})"
    values = {"confidence": decision.confidence, "gamma": decision.gamma, "nu": decision.nu}
    for name, value in values.items():
        if not math.isfinite(value):
            return f"{name} is {value}"
    if not 0.0 <= decision.nu <= 1.0:
        return f"nu {decision.nu} outside [0, 1]"
    if not 0.0 <= decision.confidence <= 1.0:
        return f"confidence {decision.confidence} outside [0, 1]"
    return None


@dataclass
class SafetySwitch:
    """The safety key's events in order: standby holds the arm until control. The events are those the
    parser's key guard let through (``bomi.frames``: STANDBY at once, CONTROL and CALIBRATION only
    when the key frame before them vouches)."""

    standby: bool = False
    seen: int = 0

    def update(self, events: Sequence[SafetyKeyEvent]) -> bool:
        """Apply the events not seen yet; True if one asks for a new neutral calibration."""
        calibrate = False
        for event in events[self.seen:]:
            if event.event == SafetyKey.STANDBY:
                self.standby = True
            elif event.event == SafetyKey.CONTROL:
                self.standby = False
            calibrate |= event.event == SafetyKey.CALIBRATION
        self.seen = len(events)
        return calibrate


# ---------------------------------------------------------------------------------- one tick
@dataclass
class Tick:
    """What one control tick read, decided and commanded."""

    tick: int
    t: float
    frames: int
    lost: int
    stale: bool
    standby: bool
    calibrating: bool
    decisions: list[Decision]
    dropped: list[tuple[int, str]]
    state: JoystickState
    mode: str
    command: ArmCommand
    neutral: dict[int, tuple[float, float, float]] | None = None

    def record(self) -> dict:
        """The tick as one JSON-ready log object (columns in the module docstring)."""
        out = {"tick": self.tick, "t": self.t, "frames": self.frames, "lost": self.lost, "stale": self.stale,
               "standby": self.standby, "calibrating": self.calibrating,
               "decisions": [asdict(d) for d in self.decisions],
               "dropped": [{"sample_index": i, "reason": r} for i, r in self.dropped],
               "deflection": dict(self.state.deflection), "pressed": sorted(self.state.pressed), "mode": self.mode,
               "linear": self.command.linear.tolist(), "angular": self.command.angular.tolist(),
               "finger": float(self.command.finger)}
        if self.neutral is not None:
            out["neutral"] = {str(node): list(offset) for node, offset in self.neutral.items()}
        return out


class Arm(Protocol):
    """What the loop needs of sim.env.ArmSim."""

    dt: float

    def step(self, state: JoystickState) -> ArmCommand: ...

    @property
    def mode(self): ...


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
        before = set(threading.enumerate())
        # the scene fills the window; Tab and Shift+Tab bring MuJoCo's side panels back
        self._handle = mujoco.viewer.launch_passive(model, data, show_left_ui=False, show_right_ui=False,
                                                    key_callback=key_callback)
        # the viewer draws from a thread of its own; close() waits for it, so that the process never
        # exits while it is still drawing into a window being destroyed
        self._threads = [thread for thread in threading.enumerate() if thread not in before]

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


class VideoDisplay:
    """The fixed camera's view filmed to an MP4 that plays in real time, the status line as its
    caption. Frames are due on the wall clock at the render rate; when rendering falls behind (a
    busy machine, software OpenGL) a frame is repeated for the slots it missed, and the control
    loop never waits for more than one render per tick."""

    def __init__(self, arm, path: Path, clock: Callable[[], float] = time.monotonic):
        from sim.render import VideoWriter  # only a filmed run needs the encoder

        self.arm, self.path, self.clock = arm, Path(path), clock
        self.fps = arm.config.render.fps
        self.writer = VideoWriter(self.path, self.fps)
        self.start: float | None = None
        self.frames = 0

    def running(self) -> bool:
        return True

    def sync(self, status: Callable[[], str]) -> None:
        now = self.clock()
        self.start = now if self.start is None else self.start
        due = int((now - self.start) * self.fps) + 1 - self.frames  # frame slots up to now not yet filled
        if due > 0:
            fields = status().split(" | ")
            frame = self.arm.render((" | ".join(fields[:4]), " | ".join(fields[4:])))
            for _ in range(due):
                self.writer.append(frame)
            self.frames += due

    def close(self) -> None:
        self.writer.close()


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


# ---------------------------------------------------------------------------------- status
def status_text(tick: Tick, parser: FrameParser, decision: Decision | None) -> str:
    """Rate, lost packets, current class, confidence, mode, commanded speed."""
    rates = [stats.rate_hz for stats in parser.nodes.values()]
    sent = sum(stats.frames + stats.lost for stats in parser.nodes.values())
    lost = f"lost {parser.total_lost} ({100 * parser.total_lost / sent if sent else 0:.1f} %)"
    if tick.calibrating:
        what = "calibrating neutral, hold still"
    elif decision is None:
        what = "no decision yet"
    else:
        what = f"c{decision.label} {decision.function} conf {decision.confidence:.2f}"
    linear = f"{100 * np.linalg.norm(tick.command.linear):.1f} cm/s"
    angular = f"{np.degrees(np.linalg.norm(tick.command.angular)):.0f} deg/s"
    speed = {"translation": linear, "height": f"{linear} {angular}", "wrist": angular}.get(
        tick.mode, f"fingers {tick.command.finger:+.2f}")
    guard = "STOPPED: no frames" if tick.stale else "STANDBY (safety key)" if tick.standby else "ok"
    return (f"{tick.t:6.1f} s | {(sum(rates) / len(rates) if rates else 0):5.1f} Hz | {lost} | {what} | "
            f"{tick.mode} | {speed} | {guard}")


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


# ---------------------------------------------------------------------------------- the loop
@dataclass
class LiveSummary:
    ticks: int = 0
    frames: int = 0
    decisions: int = 0
    dropped: int = 0
    stale_ticks: int = 0
    standby_ticks: int = 0
    watchdog_trips: int = 0
    neutral: dict[int, tuple[float, float, float]] | None = None

    def count(self, tick: Tick) -> None:
        self.ticks += 1
        self.frames += tick.frames
        self.decisions += len(tick.decisions)
        self.dropped += len(tick.dropped)
        self.stale_ticks += tick.stale
        self.standby_ticks += tick.standby


def admitted_decisions(chain: OnlineChain, frames: Iterable[ImuFrame],
                       functions: Mapping[int, str]) -> tuple[list[Decision], list[tuple[int, str]]]:
    """The frames through the chain: the decisions that may reach the arm, and (sample, reason) of the others."""
    decisions, dropped = [], []
    for decision in chain.push_frames(frames):
        reason = refusal(decision, functions)
        if reason is None:
            decisions.append(decision)
        else:
            dropped.append((decision.sample_index, reason))
    return decisions, dropped


def run_live(source: SerialSource, chain: OnlineChain, arm: Arm, *, duration_s: float | None = None,
             neutral: Mapping[int, Sequence[float]] | None = None, log: IO[str] | None = None,
             status: StatusLine | None = None, display: Display = Headless(),
             watchdog: Watchdog | None = None, on_neutral: Callable[[dict], None] = lambda offsets: None,
             clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
             assist: Callable[[JoystickState], JoystickState] | None = None,
             observer: Callable[[Tick], None] | None = None) -> LiveSummary:
    """Drive ``arm`` from ``source`` until ``duration_s`` (or the display closes).

    ``assist``: the assistance layer between the decided stick and the arm (``tasks.assist``;
    it may switch the arm's mode); not consulted while the watchdog or the safety key holds the arm.
    Neutral offsets: ``neutral`` if given, else the first ``profile.neutral_samples`` samples.
    ``on_neutral`` is told the offsets once they hold. ``log`` gets one JSON line per tick;
    ``observer`` every tick as it is (a trial runner records and scores it), before the display syncs.
    """
    watchdog = watchdog or Watchdog()
    stick, safety = DecisionStick(), SafetySwitch()
    functions = {cls.label: cls.function for cls in chain.profile.classes}
    summary = LiveSummary()
    if neutral is None:
        chain.begin_neutral_calibration()
    else:
        chain.set_neutral(neutral)
        summary.neutral = chain.neutral
        on_neutral(summary.neutral)
    batches = source.batches()
    last_decision: Decision | None = None
    start = clock()
    for now in paced_ticks(arm.dt, display, clock, sleep, start, duration_s):
        _, frames = next(batches)
        decisions, dropped = admitted_decisions(chain, frames, functions)
        if frames:
            watchdog.frames_arrived(now)
        if safety.update(source.parser.safety_events):
            chain.begin_neutral_calibration()
            summary.neutral = None
        stale = watchdog.expired(now)
        state = guarded_stick(stick, decisions, stale or safety.standby)
        if assist is not None and not (stale or safety.standby):
            state = assist(state)
        command = arm.step(state)
        new_neutral = None
        if summary.neutral is None and not chain.calibrating:
            new_neutral = summary.neutral = chain.neutral
            on_neutral(new_neutral)
        tick = Tick(summary.ticks, now - start, len(frames), source.parser.total_lost, stale, safety.standby,
                    chain.calibrating, decisions, dropped, state, arm.mode.value, command, new_neutral)
        if log is not None:
            log.write(json.dumps(tick.record()) + "\n")
        if observer is not None:
            observer(tick)
        last_decision = decisions[-1] if decisions else last_decision
        line = functools.partial(status_text, tick, source.parser, last_decision)
        display.sync(line)
        if status is not None:
            status.show(tick.t, line)
        summary.count(tick)
    summary.watchdog_trips = watchdog.trips
    return summary


def paced_ticks(dt: float, display: Display, clock: Callable[[], float], sleep: Callable[[float], None],
                start: float, duration_s: float | None) -> Iterator[float]:
    """The times of the control ticks, every ``dt`` on ``clock`` from ``start``, while the display
    runs and until ``duration_s``; a late tick does not make the next ones hurry."""
    due = start
    while display.running():
        wait = due - clock()
        if wait > 0:
            sleep(wait)
        now = clock()
        if duration_s is not None and now - start >= duration_s:
            return
        due = max(due + dt, now)
        yield now


def guarded_stick(stick: DecisionStick, decisions: Sequence[Decision], hold: bool) -> JoystickState:
    """The tick's stick: centred, and the last decision forgotten, while the arm is held (no fresh
    frames, or the safety key's standby); else the decisions on the stick."""
    if hold:
        stick.release()
        return JoystickState()
    return stick.update(decisions)


def open_log(path: Path) -> IO[str]:
    """A new log file (never replaces one)."""
    try:
        return path.open("x", encoding="utf-8")
    except FileExistsError:
        raise BomiError(f"{path}: file exists, not overwriting it") from None
    except OSError as exc:
        raise BomiError(f"{path}: cannot write the log ({exc.strerror})") from None
