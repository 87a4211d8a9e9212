"""The live loop: a base-station stream drives the simulated arm at its 60 Hz control rate.

    StreamReader (own thread) -> poll -> the live person (``tasks.trials.person.LivePerson``: Gate +
    fusion -> OnlineChain -> sanitizer -> button evidence -> DecisionStick) -> the safety hold
    (``SafetyHold``: watchdog, gate, standby, re-zero) -> [assistance] -> the env, stepped once a tick

The env is the one loop's (``tasks.stacking.env.StackingEnv``): without a task for ``bomi live``
(``FreeArm``: free mode, the arm at home and the cubes at A, no outcome judged), running trials for
``bomi trial`` (``tasks.trials.session.TrialArm``). The arm never knows where the stick came from.
Ticks are paced by the wall clock and never wait on I/O: a thread reads the port (and reconnects,
with its backoff) while each tick takes whatever has arrived (``StreamReader.poll``). ``LiveLoop`` is
the loop as a library: ``tick(now, frames, key_events)`` runs one control tick and tells every
observer its ``Tick`` (``bomi trial`` and replays use it; given the same ticks' inputs it does the
same, bit for bit).

Safety (the live path is a safety path: input it cannot trust leaves the arm at rest):

- the gate (``bomi.gate``): nothing reaches the chain, no neutral is taken and the arm does not
  move until every node's orientation filter has settled, judged on its fused angles ("warming
  up (node k)"); an implausible frame (a sensor all zero or saturated, an angle jump, counters out
  of step, more frames than the node's rate allows) or a node without frames for 100 ms holds the
  arm, and control resumes only after the node's signal has been plausible and steady for one
  settle window (1.6 s). Implausible frames never reach the fusion;
- a break in a node's stream (a reconnection of the source, a silence of 1 s, a packet counter that
  repeats or jumps: ``bomi.gate``) may bring another sitting, so no calibration is trusted across it:
  the node's orientation filter is started again, its warm-up rerun and then the neutral posture
  retaken from the stream, also when fixed offsets were given (``--neutral-from``: they belong to
  the sitting they were taken in, and so do the ones taken here), with the arm at rest until the new
  neutral holds (hold: "node k untrusted after reconnect: retaking warm-up and neutral");
- no frame at all for ``Watchdog.timeout_s`` (100 ms): the command is zero on every tick, and the
  last decision is forgotten, so the arm moves again only on decisions made from fresh frames. Both
  the watchdog and the gate judge a tick 1.5 periods ahead (the next tick's time, plus half a period
  of scheduling slack), so the zero command comes on the last tick before 100 ms without frames
  have passed (75-92 ms after the last frame was read);
- a backlog (more than ``BACKLOG_FRAMES`` of a node in one tick: the host stalled) is never replayed
  into the arm: every frame is fused and decided (the filter misses no sample), but only the newest
  decision reaches the stick (the others are counted in ``skipped``). More than ``FUSED_BACKLOG_FRAMES``
  in one tick come faster than the rate: only the newest window's frames are fused, and the node,
  whose filter lags the rest, settles again;
- decisions with an unknown class, a NaN or an out-of-range value are dropped before the stick
  (and counted); a button class (B1, B2) reaches the stick only once it has been decided for the
  profile's ``button_hold_s`` without a break (``bomi.gate.ButtonEvidence``);
- the safety key's standby holds the arm until its control event (its calibration event retakes
  the neutral posture);
- re-zero by the person (issue 42): a button class held for the profile's ``rezero_hold_s`` (3 s),
  then rest, retakes the neutral posture (``bomi.gate.LongPressGesture``; the button's own press acts
  as usual on the way), the arm at rest until it holds: the tick logs ``rezero``, the new offsets
  come in ``neutral``, and a replay of the session's bytes makes the same gesture again;
- recalibration by the person: a button class held for the profile's ``recalibrate_hold_s`` (8 s),
  then rest, starts the calibration protocol once, its cue shown as what holds the arm; at its end
  the classifier retrained on it takes the old one's place (``tasks.trials.recalibration``). A
  stream the loop cannot trust meanwhile gives it up, the old model kept;
- the loop's own rate and overruns are measured and shown; the film (``--video``) is made in a
  process of its own and drops film frames, never ticks; a log that cannot be written (disk full)
  is given up with one warning, and control goes on.

Log (``--log L``, JSON lines, one object per control tick):
``tick``, ``t`` (wall seconds since start), ``frames`` (IMU frames read this tick), ``reconnected``
(the source reconnected since the last tick), ``rezero`` (the person's re-zero gesture completed),
``recalibrating`` (a recalibration's protocol holds the arm), ``recalibrated`` (on the tick it ended:
"retrained", "given up: ..." or "old model kept: ..."; else null), ``skipped``
(decisions of a backlog kept from the stick, and frames kept from the filter, this tick), ``lost``
(samples lost so far, from the packet counters), ``stale`` (no frames: the watchdog held the arm),
``standby`` (the safety key held the arm), ``hold`` (why the arm is held, or null: "no frames", "standby", "warming up
(node k)", "node k: accelerometer all zero", ...), ``calibrating`` (neutral calibration still
collecting), ``loop_hz`` (ticks in the last second), ``overruns`` (control periods missed so far),
``decisions`` (the chain's decisions this tick: label, name, function, confidence, rejected,
gamma, nu, sample_index = node-1 samples counted from the end of the neutral calibration),
``dropped`` (decisions the sanitizer refused: sample_index, reason), ``deflection`` and
``pressed`` (the stick sent to the arm), ``mode`` (after the tick), ``linear`` (m/s), ``angular``
(rad/s) and ``finger`` (the arm's command); ``neutral`` (offsets per node index, degrees) on the
tick they take effect.
"""
from __future__ import annotations

import functools
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Protocol

import numpy as np

from bomi.chain import Decision, OnlineChain
from bomi.errors import BomiError
from bomi.frames import FrameParser, ImuFrame, SafetyKeyEvent
from bomi.fusion import NodeFusion
from bomi.gate import Gate, GateConfig
from sim.joystick import ArmCommand, JoystickState
from tasks.stacking.env import Command, StackingEnv
from tasks.trials.person import NO_INFO, LivePerson, SafetyHold, Watchdog
from tasks.trials.displays import Display, Headless, StatusLine, TickLog

# ---------------------------------------------------------------------------------- one tick
@dataclass
class Tick:
    """What one control tick read, decided and commanded (``imu``: the frames it read, in arrival order)."""

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
    hold: str | None = None
    skipped: int = 0
    loop_hz: float = 0.0
    overruns: int = 0
    imu: Sequence[ImuFrame] = ()
    reconnected: bool = False
    rezero: bool = False   # the person's re-zero gesture completed on this tick: the neutral is being retaken
    recalibrating: bool = False      # a recalibration's protocol holds the arm (tasks.trials.recalibration)
    recalibrated: str | None = None  # on the tick its protocol ended: "retrained", or why the old model stays

    def record(self) -> dict:
        """The tick as one JSON-ready log object (columns in the module docstring)."""
        out = {"tick": self.tick, "t": self.t, "frames": self.frames, "reconnected": self.reconnected,
               "rezero": self.rezero, "recalibrating": self.recalibrating, "recalibrated": self.recalibrated,
               "skipped": self.skipped, "lost": self.lost,
               "stale": self.stale, "standby": self.standby, "hold": self.hold, "calibrating": self.calibrating,
               "loop_hz": self.loop_hz, "overruns": self.overruns,
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


class FreeArm:
    """The env without a task (``StackingEnv.reset(options={"task": False})``: the arm at home, the cubes at
    A, no outcome judged) as the loop's arm: what ``bomi live`` drives, stepped once a tick."""

    def __init__(self, env: StackingEnv):
        self.env, self.dt = env, env.sim.dt
        env.reset(options={"task": False})

    @property
    def mode(self):
        return self.env.sim.mode

    def step(self, state: JoystickState) -> Command:
        return self.env.step(state)[-1]["command"]


class Source(Protocol):
    """Where frames come from (``bomi.serial_source.StreamReader``): ``poll`` never waits."""

    parser: FrameParser
    error: BomiError | None   # set once the source has given up
    reconnections: int        # times the source has reconnected (read after ``poll``)

    def poll(self) -> tuple[list[ImuFrame], list[SafetyKeyEvent]]: ...


# ---------------------------------------------------------------------------------- status
def status_text(tick: Tick, parser: FrameParser, decision: Decision | None) -> str:
    """Loop rate and overruns, stream rate, lost packets, current class, confidence, mode,
    commanded speed, and what holds the arm (or "ok")."""
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
    guard = ("STOPPED: no frames" if tick.stale else "STANDBY (safety key)" if tick.standby
             else f"HELD: {tick.hold}" if tick.hold else "ok")
    return (f"{tick.t:6.1f} s | loop {tick.loop_hz:4.1f} Hz, {tick.overruns} overruns | "
            f"stream {(sum(rates) / len(rates) if rates else 0):5.1f} Hz | {lost} | {what} | "
            f"{tick.mode} | {speed} | {guard}")


# ---------------------------------------------------------------------------------- the loop
@dataclass
class LiveSummary:
    ticks: int = 0
    frames: int = 0
    decisions: int = 0
    dropped: int = 0
    skipped: int = 0
    stale_ticks: int = 0
    standby_ticks: int = 0
    held_ticks: int = 0
    watchdog_trips: int = 0
    overruns: int = 0
    rezeros: int = 0   # neutral postures retaken at the person's gesture
    recalibrations: int = 0   # classifiers retrained at the person's gesture
    holds: Counter = field(default_factory=Counter)   # why the gate held the arm, in ticks
    neutral: dict[int, tuple[float, float, float]] | None = None

    def count(self, tick: Tick) -> None:
        self.ticks += 1
        self.frames += tick.frames
        self.decisions += len(tick.decisions)
        self.dropped += len(tick.dropped)
        self.skipped += tick.skipped
        self.stale_ticks += tick.stale
        self.standby_ticks += tick.standby
        self.held_ticks += tick.hold is not None
        self.overruns = tick.overruns
        if tick.hold is not None and not tick.stale and not tick.standby:
            self.holds[tick.hold.split(" (")[0]] += 1     # the reason, without its numbers


@dataclass
class LoopRate:
    """The control loop's own rate (ticks over the last second) and the control periods it missed."""

    dt: float
    overruns: int = 0
    _ticks: deque = field(default_factory=deque, repr=False)

    def ticked(self, now: float, due: float) -> None:
        self.overruns += int((now - due) / self.dt)  # periods that passed with no tick
        self._ticks.append(now)
        while self._ticks[0] <= now - 1.0:
            self._ticks.popleft()

    @property
    def hz(self) -> float:
        return float(len(self._ticks))


Observer = Callable[[Tick], None]


class LiveLoop:
    """The live path as a library: one control tick at a time, observers told every tick.

    ``chain`` (a fresh ``OnlineChain`` of the model and profile), ``arm`` (what the loop steps once a
    tick: ``FreeArm`` (the env without a task: ``bomi live``), ``tasks.trials.session.TrialArm`` (the
    env running trials), or anything with ``step``/``mode``/``dt``), ``neutral`` (offsets per node
    index; None: taken from the stream once it has settled), ``assist`` (``tasks.operators.assist``:
    between the decided stick and the arm, not consulted while the arm is held), ``observers`` (called
    with each ``Tick`` after the arm has stepped: read the arm's state then), ``on_neutral`` (told the
    offsets once they hold).

    A tick: the live person (``LivePerson``, the action source) senses the tick's stream, the safety hold
    (``SafetyHold``) gives the person's stick or rest, the assistance may change it, the arm steps once,
    and the ``Tick`` is built.

    ``tick(now, frames, key_events)``: one control tick at ``now`` (seconds, any clock that the
    caller keeps) with the IMU frames read since the last tick (arrival order) and the new safety-key
    events. The loop is deterministic given these: feeding the logged inputs of a run again, tick by
    tick, reproduces its decisions, commands and the arm's path. ``run`` paces ticks on a clock
    with a ``Source``. ``rate`` is filled in by ``run`` (or the caller) before each tick.
    """

    def __init__(self, chain: OnlineChain, arm: Arm, *, neutral: Mapping[int, Sequence[float]] | None = None,
                 assist: Callable[[JoystickState], JoystickState] | None = None, observers: Sequence[Observer] = (),
                 on_neutral: Callable[[dict], None] = lambda offsets: None, gate: GateConfig | None = None,
                 watchdog: Watchdog | None = None):
        self.arm, self.assist, self.on_neutral = arm, assist, on_neutral
        self.observers = list(observers)
        self.person = LivePerson(chain, arm.dt, neutral=neutral, gate=gate, watchdog=watchdog)
        self.source = SafetyHold(self.person)
        self.summary = LiveSummary()
        self.rate = LoopRate(arm.dt)

    @property
    def chain(self) -> OnlineChain:
        """The person's chain (a recalibration puts a retrained one in its place)."""
        return self.person.chain

    @property
    def gate(self) -> Gate:
        return self.person.gate

    @property
    def fusion(self) -> dict[int, NodeFusion]:
        return self.person.fusion

    @property
    def watchdog(self) -> Watchdog:
        return self.person.watchdog

    def tick(self, now: float, frames: Sequence[ImuFrame], key_events: Sequence[SafetyKeyEvent] = (),
             reconnected: bool = False) -> Tick:
        """One control tick (see the class docstring); returns it after telling the observers.
        ``reconnected``: the source reconnected since the last tick (every node's stream broke)."""
        person, summary = self.person, self.summary
        sensed = person.sense(now, frames, key_events, reconnected)
        state = self.source.act(NO_INFO)
        if self.assist is not None and sensed.hold is None:
            state = self.assist(state)
        command = self.arm.step(state)
        new_neutral = person.neutral_taken()
        summary.neutral, summary.rezeros, summary.recalibrations = person.offsets, person.rezeros, person.recalibrations
        if new_neutral is not None:
            self.on_neutral(new_neutral)
        tick = Tick(summary.ticks, now, len(frames), self.gate.lost, sensed.stale, person.safety.standby,
                    self.chain.calibrating, sensed.decisions, sensed.dropped, state, self.arm.mode.value, command,
                    new_neutral, sensed.hold, sensed.skipped, self.rate.hz, self.rate.overruns, tuple(frames),
                    reconnected, sensed.rezero, sensed.recalibrating, sensed.recalibrated)
        summary.count(tick)
        summary.watchdog_trips = self.watchdog.trips
        for observer in self.observers:
            observer(tick)
        return tick

    def run(self, source: Source, *, duration_s: float | None = None, log: TickLog | None = None,
            status: StatusLine | None = None, display: Display = Headless(),
            clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> LiveSummary:
        """Tick every ``arm.dt`` on ``clock`` with what ``source`` has, until ``duration_s`` (kept
        whatever the source does), the display closes, or (without a duration) the source gives up."""
        last_decision: Decision | None = None
        reconnections = source.reconnections
        start = clock()
        for now, due in paced_ticks(self.arm.dt, display, clock, sleep, start, duration_s):
            if duration_s is None and source.error is not None:
                break
            frames, events = source.poll()
            reconnected, reconnections = source.reconnections != reconnections, source.reconnections
            self.rate.ticked(now, due)
            tick = self.tick(now - start, frames, events, reconnected)
            if log is not None:
                log.write(tick.record())
            last_decision = tick.decisions[-1] if tick.decisions else last_decision
            line = functools.partial(status_text, tick, source.parser, last_decision)
            display.sync(line)
            if status is not None:
                status.show(tick.t, line)
        return self.summary


def run_live(source: Source, chain: OnlineChain, arm: Arm, *, duration_s: float | None = None,
             neutral: Mapping[int, Sequence[float]] | None = None, log: TickLog | None = None,
             status: StatusLine | None = None, display: Display = Headless(),
             watchdog: Watchdog | None = None, on_neutral: Callable[[dict], None] = lambda offsets: None,
             clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
             assist: Callable[[JoystickState], JoystickState] | None = None, observers: Sequence[Observer] = (),
             gate: GateConfig | None = None) -> LiveSummary:
    """Drive ``arm`` from ``source`` until ``duration_s`` (or the display closes): ``LiveLoop(...).run(...)``."""
    loop = LiveLoop(chain, arm, neutral=neutral, assist=assist, observers=observers, on_neutral=on_neutral,
                    gate=gate, watchdog=watchdog)
    return loop.run(source, duration_s=duration_s, log=log, status=status, display=display, clock=clock, sleep=sleep)


def paced_ticks(dt: float, display: Display, clock: Callable[[], float], sleep: Callable[[float], None],
                start: float, duration_s: float | None) -> Iterator[tuple[float, float]]:
    """(time, time it was due) of the control ticks, every ``dt`` on ``clock`` from ``start``, while
    the display runs and until ``duration_s``; a late tick does not make the next ones hurry."""
    due = start
    while display.running():
        wait = due - clock()
        if wait > 0:
            sleep(wait)
        now = clock()
        if duration_s is not None and now - start >= duration_s:
            return
        yield now, due
        due = max(due + dt, now)
