"""The live loop: a base-station stream drives the simulated arm at its 60 Hz control rate.

    StreamReader (own thread) -> poll -> Gate + fusion -> OnlineChain -> sanitizer -> button evidence
    -> DecisionStick -> Watchdog -> ArmSim.step

The arm never knows where the stick came from. Ticks are paced by the wall clock and never wait on
I/O: a thread reads the port (and reconnects, with its backoff) while each tick takes whatever
has arrived (``StreamReader.poll``). ``LiveLoop`` is the loop as a library: ``tick(now, frames,
key_events)`` runs one control tick and tells every observer its ``Tick`` (``bomi trial`` and
replays use it; given the same ticks' inputs it does the same, bit for bit).

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
- a backlog (more than ``BACKLOG_FRAMES`` of a node in one tick) is never replayed into the arm:
  only the newest window's frames are fused and reach the chain, only the newest decision the
  stick (the others are counted in ``skipped``); the counters then jump, so the node settles again;
- decisions with an unknown class, a NaN or an out-of-range value are dropped before the stick
  (and counted); a button class (B1, B2) reaches the stick only once it has been decided for the
  profile's ``button_hold_s`` without a break (``bomi.gate.ButtonEvidence``);
- the safety key's standby holds the arm until its control event (its calibration event retakes
  the neutral posture);
- re-zero by the person (issue 42): a button class held for the profile's ``rezero_hold_s`` (3 s),
  then rest, retakes the neutral posture (``bomi.gate.RezeroGesture``; the button's own press acts
  as usual on the way), the arm at rest until it holds: the tick logs ``rezero``, the new offsets
  come in ``neutral``, and a replay of the session's bytes makes the same gesture again;
- the loop's own rate and overruns are measured and shown; the film (``--video``) is made in a
  process of its own and drops film frames, never ticks; a log that cannot be written (disk full)
  is given up with one warning, and control goes on.

Log (``--log L``, JSON lines, one object per control tick):
``tick``, ``t`` (wall seconds since start), ``frames`` (IMU frames read this tick), ``reconnected``
(the source reconnected since the last tick), ``rezero`` (the person's re-zero gesture completed), ``skipped``
(frames of a backlog kept from the chain this tick), ``lost`` (samples lost so far, from the
packet counters), ``stale`` (no frames: the watchdog held the arm), ``standby`` (the safety key
held the arm), ``hold`` (why the arm is held, or null: "no frames", "standby", "warming up
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
import math
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Protocol

import numpy as np

from bomi.chain import Decision, OnlineChain
from bomi.errors import BomiError
from bomi.frames import FrameParser, ImuFrame, SafetyKey, SafetyKeyEvent, imu_index
from bomi.fusion import DT, NodeFusion
from bomi.gate import Gate, GateConfig, RezeroGesture
from bomi.profiles import NEUTRAL_FUNCTION
from sim.joystick import BUTTONS, ArmCommand, JoystickState
from tasks.operators.stick import DecisionStick
from tasks.trials.displays import Display, Headless, StatusLine, TickLog

WATCHDOG_TIMEOUT_S = 0.1
LOOKAHEAD_TICKS = 1.5  # the watchdog and the gate judge a tick at its time + this many periods (see LiveLoop.tick)
BACKLOG_FRAMES = 16  # a node's frames in one tick beyond this (0.25 s of samples) are a backlog


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

    def update(self, events: Sequence[SafetyKeyEvent]) -> bool:
        """Apply new events; True if one asks for a new neutral calibration."""
        calibrate = False
        for event in events:
            if event.event == SafetyKey.STANDBY:
                self.standby = True
            elif event.event == SafetyKey.CONTROL:
                self.standby = False
            calibrate |= event.event == SafetyKey.CALIBRATION
        return calibrate


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

    def record(self) -> dict:
        """The tick as one JSON-ready log object (columns in the module docstring)."""
        out = {"tick": self.tick, "t": self.t, "frames": self.frames, "reconnected": self.reconnected,
               "rezero": self.rezero, "skipped": self.skipped, "lost": self.lost,
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

    ``chain`` (a fresh ``OnlineChain`` of the model and profile), ``arm`` (``sim.env.ArmSim`` or
    anything with ``step``/``mode``/``dt``), ``neutral`` (offsets per node index; None: taken from
    the stream once it has settled), ``assist`` (``tasks.operators.assist``: between the decided stick and the
    arm, not consulted while the arm is held), ``observers`` (called with each ``Tick`` after the arm
    has stepped: read the arm's state then), ``on_neutral`` (told the offsets once they hold).

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
        self.chain, self.arm, self.assist, self.on_neutral = chain, arm, assist, on_neutral
        self.observers = list(observers)
        profile = chain.profile
        self.functions = {cls.label: cls.function for cls in profile.classes}
        self.gate = Gate(chain.nodes, gate or GateConfig())
        self._calibration = {n.index: n.calibration for n in profile.nodes if n.index in chain.nodes}
        self.fusion = {index: NodeFusion(calibration) for index, calibration in self._calibration.items()}
        self.watchdog = watchdog or Watchdog()
        self.stick, self.safety = DecisionStick(profile), SafetySwitch()
        buttons = frozenset(f for f in self.functions.values() if f in BUTTONS)
        # a profile without a re-zero hold (0) or without a button class has no gesture
        self.rezero = RezeroGesture(math.ceil(profile.rezero_hold_s / DT - 1e-9),
                                    buttons if profile.rezero_hold_s > 0 else frozenset(), NEUTRAL_FUNCTION)
        self.summary = LiveSummary()
        self.rate = LoopRate(arm.dt)
        self.streaming = False        # every node settled once: frames go to the chain from then on
        self._neutral = None if neutral is None else {int(k): tuple(v) for k, v in neutral.items()}
        self._recalibrate = False
        self.untrusted: dict[int, str] = {}   # node -> why, after a break, until the neutral is retaken

    def _untrust(self, node: int, cause: str, counter: int | None = None) -> None:
        """A break in ``node``'s stream (``bomi.gate``): its filter started again, its warm-up rerun, nothing to
        the chain until every node has settled, and the neutral then retaken from the stream."""
        self.gate.node[node].restart(counter)
        self.fusion[node] = NodeFusion(self._calibration[node])
        self.chain.forget_decisions()
        # the first break says why (a reconnection is then also a gap in the node's frames)
        self.untrusted.setdefault(node, f"node {node} untrusted after {cause}: retaking warm-up and neutral")
        self.streaming, self._neutral, self._recalibrate = False, None, False
        self.summary.neutral = None

    def _start_streaming(self) -> None:
        self.streaming = True
        if self._neutral is None:
            self.chain.begin_neutral_calibration()
        else:
            self.chain.set_neutral(self._neutral)

    def _frames_to_chain(self, frames: Sequence[ImuFrame]) -> tuple[list[Decision], int]:
        """Gate and fuse the frames of the model's nodes and give them to the chain; of a node's backlog
        (more than BACKLOG_FRAMES this tick) only the newest window's frames (the rest: skipped)."""
        nodes = [imu_index(frame.node_id) for frame in frames]
        counts = Counter(node for node in nodes if node in self.fusion)
        keep_from = {node: count - self.chain.model.spec.window if count > BACKLOG_FRAMES else 0
                     for node, count in counts.items()}
        seen: Counter = Counter()
        decisions, skipped = [], 0
        for frame, node in zip(frames, nodes):
            gate = self.gate.node.get(node)
            if gate is None:
                continue
            seen[node] += 1
            if (cause := gate.count(frame.counter)) is not None:
                self._untrust(node, cause, frame.counter)
            if seen[node] <= keep_from[node]:
                skipped += 1
                if seen[node] == keep_from[node]:
                    gate.backlog(keep_from[node])
                continue
            if not gate.check_raw(frame.mag, frame.gyro, frame.acc):
                continue
            angles = self.fusion[node].update(frame.acc, frame.gyro, frame.mag)
            gate.fused(angles)
            if not self.streaming and self.gate.settled:
                self._start_streaming()
            if self.streaming and (made := self.chain.push_angles(node, angles, frame.gyro)) is not None:
                decisions.append(made)
        return decisions, skipped

    def tick(self, now: float, frames: Sequence[ImuFrame], key_events: Sequence[SafetyKeyEvent] = (),
             reconnected: bool = False) -> Tick:
        """One control tick (see the class docstring); returns it after telling the observers.
        ``reconnected``: the source reconnected since the last tick (every node's stream broke)."""
        chain, summary = self.chain, self.summary
        nodes = Counter(imu_index(frame.node_id) for frame in frames)
        breaks = self.gate.arrivals(now, nodes)
        if reconnected:
            breaks = dict.fromkeys(self.gate.node, "reconnect")
        for node, cause in breaks.items():
            self._untrust(node, cause)
        made, skipped = self._frames_to_chain(frames)
        decisions, dropped = [], []
        for decision in made:
            reason = refusal(decision, self.functions)
            if reason is None:
                decisions.append(decision)
            else:
                dropped.append((decision.sample_index, reason))
        if frames:
            self.watchdog.frames_arrived(now)
        if self.safety.update(key_events):   # the safety key's re-zero: as the person's gesture
            chain.forget_decisions()
            chain.begin_neutral_calibration()
            summary.neutral = None
        # judged ahead (the next tick's time, plus half a period of scheduling slack): the arm is at rest
        # before 100 ms without frames have passed (on the last tick before them), not on the first after
        ahead = now + LOOKAHEAD_TICKS * self.arm.dt
        stale = self.watchdog.expired(ahead)
        gate = self.gate.verdict(ahead)
        retaking = next(iter(self.untrusted.values()), None)
        hold = "no frames" if stale else "standby" if self.safety.standby else retaking or gate
        if chain.calibrating and gate is not None:
            self._recalibrate = True      # the neutral posture is taken from trusted samples only
        elif self._recalibrate and gate is None:
            self._recalibrate = False
            chain.begin_neutral_calibration()
        acted = decisions[-1:] if skipped else decisions     # a backlog: the newest decision only
        skipped += len(decisions) - len(acted)
        rezero = self._rezero_asked(acted, hold is not None)
        state = guarded_stick(self.stick, acted, hold is not None or rezero)
        if self.assist is not None and hold is None:
            state = self.assist(state)
        command = self.arm.step(state)
        new_neutral = None
        if summary.neutral is None and self.streaming and not chain.calibrating:
            new_neutral = summary.neutral = chain.neutral
            self.untrusted.clear()      # the neutral of the sitting now streaming holds
            self.on_neutral(new_neutral)
        tick = Tick(summary.ticks, now, len(frames), self.gate.lost, stale, self.safety.standby, chain.calibrating,
                    decisions, dropped, state, self.arm.mode.value, command, new_neutral, hold, skipped,
                    self.rate.hz, self.rate.overruns, tuple(frames), reconnected, rezero)
        summary.count(tick)
        summary.watchdog_trips = self.watchdog.trips
        for observer in self.observers:
            observer(tick)
        return tick

    def _rezero_asked(self, decisions: Sequence[Decision], hold: bool) -> bool:
        """The person's re-zero gesture completed on this tick's decisions (``bomi.gate.RezeroGesture``;
        only while the arm is free: a hold forgets a gesture begun): the neutral is taken anew, the arm
        at rest meanwhile."""
        if hold:
            self.rezero.reset()
            return False
        if not self.rezero.update(decision.function for decision in decisions):
            return False
        self.chain.forget_decisions()   # the long press's labels do not vote after the new neutral
        self.chain.begin_neutral_calibration()
        self.summary.neutral = None
        self.summary.rezeros += 1
        return True

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


def guarded_stick(stick: DecisionStick, decisions: Sequence[Decision], hold: bool) -> JoystickState:
    """The tick's stick: centred, and the last decision and any button evidence forgotten, while the
    arm is held (no fresh frames, the safety key's standby, a re-zero); else the decisions on the stick."""
    if hold:
        stick.release()
        return JoystickState()
    return stick.update(decisions)
