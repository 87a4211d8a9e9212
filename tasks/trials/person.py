"""The live person as an action source (``tasks.stacking.sources.ActionSource``), and the safety that
holds the arm while their stream cannot be trusted (the live loop: ``tasks.trials.live``).

``LivePerson``: frames in -> gate + fusion -> ``OnlineChain`` -> sanitizer (``refusal``) -> button
evidence -> ``DecisionStick``. ``sense`` takes one tick's frames and safety-key events and prepares the
tick (``Sensed``: the decisions, and what holds the arm: the watchdog, the gate, the safety key's
standby, a break's retaken warm-up and neutral, a re-zero); ``act`` gives the decided stick.
``SafetyHold`` wraps it: the arm at rest, the stick's memory forgotten, while anything holds
(``guarded_stick``). The rules themselves: ``tasks.trials.live``'s docstring.
"""
from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from bomi.chain import Decision, OnlineChain
from bomi.frames import ImuFrame, SafetyKey, SafetyKeyEvent, imu_index
from bomi.fusion import DT, NodeFusion
from bomi.errors import BomiError
from bomi.gate import Gate, GateConfig, LongPress, LongPressGesture
from bomi.profiles import NEUTRAL_FUNCTION
from sim.joystick import BUTTONS, JoystickState
from tasks.operators.stick import DecisionStick
from tasks.trials.recalibration import Recalibration

WATCHDOG_TIMEOUT_S = 0.1
LOOKAHEAD_TICKS = 1.5  # the watchdog and the gate judge a tick at its time + this many periods (see LivePerson.sense)
BACKLOG_FRAMES = 16  # a node's frames in one tick beyond this (0.25 s of samples) are a backlog: the newest decision acts
# A backlog up to this many frames of a node is fused and decided whole, so the filter misses no sample (well
# under a tick's work). An honest stream's backlog is shorter: a second without frames is a break (bomi.gate),
# 62.5 frames. More in one tick come faster than the rate: only the newest window is fused (bounded work), the
# filter lags the rest, and the node settles again.
FUSED_BACKLOG_FRAMES = 64


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


NO_INFO: Mapping = {}   # what the live person reads of the loop's info: nothing (they watch the arm itself)


@dataclass
class Sensed:
    """What the live person's stream gave on one tick (``LivePerson.sense``): the chain's decisions the
    sanitizer passed (``decisions``) or refused (``dropped``), those that reach the stick (``acted``: of
    a backlog only the newest), frames kept from the filter and decisions from the stick (``skipped``),
    whether the watchdog expired (``stale``), what holds the arm (``hold``), whether the person's
    re-zero gesture completed (``rezero``: the arm at rest while the neutral is retaken), whether a
    recalibration holds the arm (``recalibrating``) and, on the tick its protocol ended, what came of
    it (``recalibrated``: "retrained", or why the old model stays)."""

    decisions: list[Decision]
    dropped: list[tuple[int, str]]
    acted: list[Decision]
    skipped: int
    stale: bool
    hold: str | None
    rezero: bool
    recalibrating: bool = False
    recalibrated: str | None = None

    @property
    def held(self) -> bool:
        """The arm must be at rest on this tick (``guarded_stick``)."""
        return self.hold is not None or self.rezero


class LivePerson:
    """The person at the base station as an action source (``tasks.stacking.sources.ActionSource``):
    frames in -> gate -> fusion -> chain -> sanitizer -> button evidence -> the stick.

    ``sense(now, frames, key_events, reconnected)`` takes one tick's stream (see ``LiveLoop``) and
    prepares the tick (``Sensed``, also kept in ``sensed``); ``act(info)`` then gives the decided stick
    (``info`` is not read: the person watches the arm with their own eyes), ``release`` forgets the
    last decision and any button evidence (a hold: ``guarded_stick``). ``neutral_taken`` (after the
    arm's step) gives the neutral offsets on the tick they take effect. ``dt``: the control period
    (the watchdog and the gate judge a tick ahead by it)."""

    def __init__(self, chain: OnlineChain, dt: float, *, neutral: Mapping[int, Sequence[float]] | None = None,
                 gate: GateConfig | None = None, watchdog: Watchdog | None = None):
        self.chain, self.dt = chain, dt
        profile = chain.profile
        self.functions = {cls.label: cls.function for cls in profile.classes}
        self.gate = Gate(chain.nodes, gate or GateConfig())
        self._calibration = {n.index: n.calibration for n in profile.nodes if n.index in chain.nodes}
        self.fusion = {index: NodeFusion(calibration) for index, calibration in self._calibration.items()}
        self.watchdog = watchdog or Watchdog()
        self.stick, self.safety = DecisionStick(profile), SafetySwitch()
        buttons = frozenset(f for f in self.functions.values() if f in BUTTONS)
        # a profile without a button class has no long press; a hold of 0 turns its gesture off
        self.long_press = LongPressGesture(_samples(profile.rezero_hold_s), _samples(profile.recalibrate_hold_s),
                                           buttons, NEUTRAL_FUNCTION)
        self.recalibration: Recalibration | None = None   # the protocol under way
        self.streaming = False        # every node settled once: frames go to the chain from then on
        self._neutral = None if neutral is None else {int(k): tuple(v) for k, v in neutral.items()}
        self._recalibrate = False
        self.untrusted: dict[int, str] = {}   # node -> why, after a break, until the neutral is retaken
        self.offsets: dict[int, tuple[float, float, float]] | None = None   # the neutral that holds (None: being taken)
        self.rezeros = 0   # neutral postures retaken at the person's gesture
        self.recalibrations = 0   # classifiers retrained at the person's gesture
        self.sensed: Sensed | None = None

    def _untrust(self, node: int, cause: str, counter: int | None = None) -> None:
        """A break in ``node``'s stream (``bomi.gate``): its filter started again, its warm-up rerun, nothing to
        the chain until every node has settled, and the neutral then retaken from the stream."""
        self.gate.node[node].restart(counter)
        self.fusion[node] = NodeFusion(self._calibration[node])
        self.chain.forget_decisions()
        # the first break says why (a reconnection is then also a gap in the node's frames)
        self.untrusted.setdefault(node, f"node {node} untrusted after {cause}: retaking warm-up and neutral")
        self.streaming, self._neutral, self._recalibrate = False, None, False
        self.offsets = None

    def _start_streaming(self) -> None:
        self.streaming = True
        if self._neutral is None:
            self.chain.begin_neutral_calibration()
        else:
            self.chain.set_neutral(self._neutral)

    def _frames_to_chain(self, frames: Sequence[ImuFrame]) -> tuple[list[Decision], int, bool]:
        """Gate and fuse the frames of the model's nodes and give them to the chain: the decisions, the
        frames kept from the filter and whether the frames are a backlog (a node's beyond BACKLOG_FRAMES). Of
        a backlog beyond FUSED_BACKLOG_FRAMES only the newest window's frames are fused."""
        nodes = [imu_index(frame.node_id) for frame in frames]
        counts = Counter(node for node in nodes if node in self.fusion)
        keep_from = {node: count - self.chain.model.spec.window if count > FUSED_BACKLOG_FRAMES else 0
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
            if self.recalibration is not None:
                self.recalibration.fused(frame, angles)
            if not self.streaming and self.gate.settled:
                self._start_streaming()
            if self.streaming and (made := self.chain.push_angles(node, angles, frame.gyro)) is not None:
                decisions.append(made)
        return decisions, skipped, max(counts.values(), default=0) > BACKLOG_FRAMES

    def sense(self, now: float, frames: Sequence[ImuFrame], key_events: Sequence[SafetyKeyEvent] = (),
              reconnected: bool = False) -> Sensed:
        """One tick's stream at ``now`` (``LiveLoop.tick``): breaks, gate, fusion, chain, sanitizer, the safety
        key, the watchdog, and the decisions for the stick; kept in ``sensed`` for ``act``."""
        chain = self.chain
        nodes = Counter(imu_index(frame.node_id) for frame in frames)
        breaks = self.gate.arrivals(now, nodes)
        if reconnected:
            breaks = dict.fromkeys(self.gate.node, "reconnect")
        for node, cause in breaks.items():
            self._untrust(node, cause)
        made, skipped, backlog = self._frames_to_chain(frames)
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
            self.offsets = None
        # judged ahead (the next tick's time, plus half a period of scheduling slack): the arm is at rest
        # before 100 ms without frames have passed (on the last tick before them), not on the first after
        ahead = now + LOOKAHEAD_TICKS * self.dt
        stale = self.watchdog.expired(ahead)
        gate = self.gate.verdict(ahead)
        retaking = next(iter(self.untrusted.values()), None)
        hold = "no frames" if stale else "standby" if self.safety.standby else retaking or gate
        if chain.calibrating and gate is not None:
            self._recalibrate = True      # the neutral posture is taken from trusted samples only
        elif self._recalibrate and gate is None:
            self._recalibrate = False
            chain.begin_neutral_calibration()
        acted = decisions[-1:] if backlog else decisions     # a backlog: the newest decision only
        skipped += len(decisions) - len(acted)
        recalibrated = None
        if self.recalibration is not None:   # the protocol's motions are no commands
            acted = []
            hold, recalibrated = self._recalibrating(now, hold)
        rezero = self._long_press(acted, hold is not None, now)
        if self.recalibration is not None and hold is None:   # asked for on this tick
            hold = self.recalibration.hold_text(now)
        self.sensed = Sensed(decisions, dropped, acted, skipped, stale, hold, rezero,
                             self.recalibration is not None, recalibrated)
        return self.sensed

    def act(self, info: Mapping = NO_INFO) -> JoystickState:
        """The stick of the tick ``sense`` prepared: its decisions on the ``DecisionStick``."""
        return self.stick.update(self.sensed.acted)

    def release(self) -> None:
        self.stick.release()

    def neutral_taken(self) -> dict[int, tuple[float, float, float]] | None:
        """The neutral offsets, on the tick they take effect (the stream's calibration ended, or the given
        offsets set); then the sitting now streaming is trusted again."""
        if self.offsets is not None or not self.streaming or self.chain.calibrating:
            return None
        self.offsets = self.chain.neutral
        self.untrusted.clear()
        return self.offsets

    def _long_press(self, decisions: Sequence[Decision], hold: bool, now: float) -> bool:
        """The person's long press completed on this tick's decisions (``bomi.gate.LongPressGesture``; only
        while the arm is free: a hold forgets a press begun). A re-zero (True): the neutral is taken anew,
        the arm at rest meanwhile. A recalibration: its protocol starts now (``_recalibrating``)."""
        if hold:
            self.long_press.reset()
            return False
        asked = self.long_press.update(decision.function for decision in decisions)
        if asked is None:
            return False
        self.chain.forget_decisions()   # the long press's labels do not vote after it
        if asked is LongPress.RECALIBRATE:
            self.recalibration = Recalibration.begin(self.chain.profile, self.chain.model, now)
            return False
        self.chain.begin_neutral_calibration()
        self.offsets = None
        self.rezeros += 1
        return True

    def _recalibrating(self, now: float, hold: str | None) -> tuple[str | None, str | None]:
        """A tick of the recalibration under way: (what holds the arm, what came of it once it ended). A
        stream the loop cannot trust ends it at once, the old model kept; at the protocol's end the
        retrained chain takes the old one's place (its neutral logged as a new neutral)."""
        recalibration = self.recalibration
        if hold is not None:
            self.recalibration = None
            return hold, f"given up: {hold}"
        recalibration.take(now)
        if not recalibration.over(now):
            return recalibration.hold_text(now), None
        self.recalibration = None
        try:
            chain = recalibration.retrained()
        except BomiError as exc:
            self.chain.forget_decisions()
            return None, f"old model kept: {exc}"
        self.chain, self.offsets = chain, None
        self.recalibrations += 1
        return None, "retrained"


def _samples(seconds: float) -> int:
    """A hold of ``seconds`` in decisions (one per sample); 0 stays 0 (off)."""
    return math.ceil(seconds / DT - 1e-9)


class SafetyHold:
    """The live loop's safety hold around the live person (an ``ActionSource`` itself): the arm at rest,
    and the person's last decision and button evidence forgotten, while the gate, the watchdog, the
    safety key's standby or a re-zero holds it (``guarded_stick``)."""

    def __init__(self, person: LivePerson):
        self.person = person

    def act(self, info: Mapping = NO_INFO) -> JoystickState:
        return guarded_stick(self.person, info, self.person.sensed.held)


def guarded_stick(source: LivePerson, info: Mapping, hold: bool) -> JoystickState:
    """The tick's stick: centred, and the person's last decision and any button evidence forgotten, while
    the arm is held (no fresh frames, the safety key's standby, a re-zero); else the person's stick."""
    if hold:
        source.release()
        return JoystickState()
    return source.act(info)
