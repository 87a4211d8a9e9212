"""The live path's gate: whether a node's stream can be trusted to move the arm, sample by sample.

Pure: a node's raw sensor values, packet counters, fused angles and arrival times go in, a reason
to hold the arm (or None) comes out; no I/O, no clock of its own, nothing from sim/ or tasks/.

A node is trusted once its orientation filter has **settled** and while its samples stay
**plausible** and **fresh**:

- Settled, judged on the signal: over the last ``settle_samples`` fused samples the mean of
  the newer half differs from the mean of the older half by less than ``settle_change_deg`` on
  every angle. Why these numbers: from its zero state the filter's error decays as
  e(t) = e0 exp(-t / tau); the slowest term is yaw's, tau = DT / MAG_WEIGHT = 100 samples
  (1.6 s; pitch and roll: 12.5 samples, ``bomi.fusion``). Over a window of W samples ending
  with error e_end, the half means of such a decay differ by
  e_end * (2 tau / W) * (exp(W / (2 tau)) - 1)^2 (0.84 e_end for W = tau), so a difference below
  0.84 * SETTLE_TOLERANCE_DEG says the error left is below the tolerance (0.5 deg, a quarter of
  the smallest class amplitude the proportional output resolves: 10 % of a 20 deg motion). The
  sensor noise does not mask it: the fused yaw's noise is the magnetometer's heading noise
  (~0.3 deg per sample for 25 LSB on a 5,000 LSB field) times its 0.01 weight, averaged over 50
  samples: ~0.001 deg. A person swaying (P1: 0.2 deg, P4: up to 0.8 deg) can delay the verdict,
  never hasten it past the decay (a decay and a sway would have to cancel over a whole window).
  Someone moving while the stream starts is not settled until they hold still: safe.
  The half-mean test alone can be fooled while the filter is still decaying: a motion whose two
  half means differ by the opposite of the decay's (a back-and-forth head turn of +-15 deg at
  0.4 Hz passed it 2.7 s after the start) cancels it. So a node is never judged settled before
  its filter is as old as the warm-up the offline path drops (``bomi.fusion.WARMUP_S``, 12 s:
  ``filter_age_samples``), which covers the worst start: from the zero state yaw can be 180 deg
  off and, while pitch and roll settle (error x 0.92 per sample: below 0.5 deg after 71 samples),
  its magnetic reference can be as far off, so the error is at most 180 (1 + 0.01 sum_k<71
  0.99^-k) 0.99^n = 365 x 0.99^n deg: below 0.5 deg after 656 samples (10.5 s). The filter is
  created once per stream and never reset (implausible frames are kept from it): the floor
  applies to a stream's start, not to a node settling again after a defect.
- Plausible: no sensor vector all zero (acc and mag cannot read 0, 0, 0 on a node at rest or
  moving; a gyroscope can), no value at the int16 limits (-32768, 32767: saturation), no fused
  angle moving more than ``max_rate_deg_s`` between samples (600 deg/s: fast voluntary head turns
  peak near 400 deg/s), no backlog (frames the loop kept from the filter: it lags them), and no
  more frames than the node's announced period allows (``flood_factor`` x the rate over the last
  second, plus one window of burst).
- Fresh: a frame of the node within ``stale_s`` (100 ms) of now.

A **break** in a node's stream makes it untrusted from scratch, since what follows may come from
another sitting (another neutral posture, another heading, another person on the same base station):
a silence of ``break_gap_s`` (1 s: the sender's frames are never that late while its counters stay
in step, and the one-byte counter wraps every 4.1 s, so only time tells a long gap), a packet counter
repeated or jumping by more than ``max_counter_step`` (the parser delivers such a frame only once two
more follow it in step: a stream that started again), a **turn no body makes** between two samples,
or a reconnection of the source (the loop says so). The turn is the sensor's own, frame to frame, not
the fused angles' (the filter follows a new sitting's heading at 1 % a sample, a step of 0.5 deg for a
46 deg splice): the angle between two frames' accelerometer vectors (the tilt) and between their
magnetometer vectors' parts across gravity (the heading; raw, without the node's iron calibration,
which the hard-iron offset bends by a few degrees at most: the part across gravity is a quarter or
more of the field for every class of the virtual P1 at any heading), against ``max_turn_deg_s`` times the
samples between them. The bound is the gyroscope's full scale, 2000 deg/s (hardware.md; 32 deg a
sample): 2.6 times the fastest turns a head makes (group median of the maximal head velocity in
vigorous voluntary yaw rotation 780 deg/s, Grossman et al. 1988, Ann Neurol 23:4, "Frequency and
velocity of rotational head perturbations during locomotion"), a turn the sensor could not even
measure; on P1's five recorded days the head node's largest frame-to-frame turn is 22.0 deg of tilt
and 12.2 deg of heading (its 99.99th percentiles 4.2 and 5.5 deg; the shoulders' post-processed
columns, whose blocks repeat rows, aside). So another sitting spliced onto the stream with the
counters in step (a new heading, a new tilt) is a break like a restarted counter: ``check_raw`` finds
the turn and keeps the frame from the filter, the next frame's ``count`` returns the break.
``NodeGate.restart`` then forgets everything the node was trusted for, and the caller starts its
orientation filter again: the warm-up (with the 12 s floor) is rerun, and the neutral retaken
(``tasks.trials.live.LiveLoop``).

After an implausible sample the node must settle again: a full window of plausible samples that passes the settle test, and ``resume_s`` (1.6 s)
of wall time since the last implausible frame arrived (a burst can bring a whole window at
once), i.e. the signal has been plausible and steady for 1.6 s before control resumes. An implausible
frame is not given to the fusion (``NodeGate.check_raw`` says so before fusing), so a zero or
saturated frame does not bend the filter.

Buttons (``ButtonEvidence``): a button class acts only after it has been decided on
``samples`` consecutive decisions with the gate open (the profile's ``button_hold_s``).

Re-zero and recalibration (``LongPressGesture``): the person asks for their neutral posture to be
taken anew by holding a button class for the profile's ``rezero_hold_s`` (a long press, as the JACO's
own joystick gives its buttons a second meaning when held) and then coming back to rest: the first
neutral decision after the long press starts the neutral calibration, so the posture taken is the
rest, not the press. Held for ``recalibrate_hold_s`` (longer) and then rest, it asks for a
recalibration instead (``tasks.trials.recalibration``).
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from bomi.frames import SAMPLE_RATE_HZ, counter_step
from bomi.fusion import DT, MAG_WEIGHT, WARMUP_S

INT16_LIMITS = (-32768, 32767)
SETTLE_TAU_S = DT / MAG_WEIGHT        # the slowest filter time constant (yaw): 1.6 s
SETTLE_TOLERANCE_DEG = 0.5


def half_mean_ratio(window_s: float, tau_s: float) -> float:
    """Difference of the half-window means of an exponential decay, per unit of its value at the window's end."""
    x = window_s / (2.0 * tau_s)
    return (2.0 * tau_s / window_s) * math.expm1(x) ** 2


@dataclass(frozen=True)
class GateConfig:
    settle_samples: int = round(SETTLE_TAU_S / DT)                  # W = tau: 100 samples
    settle_change_deg: float = SETTLE_TOLERANCE_DEG * half_mean_ratio(SETTLE_TAU_S, SETTLE_TAU_S)
    filter_age_samples: int = round(WARMUP_S / DT)                 # 750 samples (module docstring)
    max_rate_deg_s: float = 600.0
    max_counter_step: int = 16            # as the parser's phantom guard (bomi.frames.MAX_COUNTER_GAP)
    stale_s: float = 0.1
    break_gap_s: float = 1.0              # a silence this long is a break: the node is untrusted from scratch
    max_turn_deg_s: float = 2000.0        # a sensor turning faster between two frames is a break (module docstring)
    flood_factor: float = 1.5
    rate_hz: float = SAMPLE_RATE_HZ

    @property
    def max_jump_deg(self) -> float:
        return self.max_rate_deg_s * DT

    @property
    def max_turn_deg(self) -> float:
        """The largest turn of a sensor between two consecutive samples that is not a break."""
        return self.max_turn_deg_s * DT

    @property
    def resume_s(self) -> float:
        """How long the signal must have been plausible (and steady) before control resumes."""
        return self.settle_samples * DT


def raw_defect(mag: Sequence[int], gyro: Sequence[int], acc: Sequence[int]) -> str | None:
    """Why a frame's raw values cannot come from a working sensor (None if they can)."""
    if not any(acc):
        return "accelerometer all zero"
    if not any(mag):
        return "magnetometer all zero"
    for name, values in (("magnetometer", mag), ("gyroscope", gyro), ("accelerometer", acc)):
        if any(v in INT16_LIMITS for v in values):
            return f"{name} saturated"
    return None


Vector = tuple[float, float, float]


def _dot(a: Vector, b: Vector) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _angle_deg(a: Vector, b: Vector) -> float:
    cos = _dot(a, b) / math.sqrt(_dot(a, a) * _dot(b, b))
    return math.degrees(math.acos(min(1.0, max(-1.0, cos))))


def _across(m: Vector, a: Vector) -> Vector:
    """``m``'s part across ``a`` (perpendicular to it)."""
    k = _dot(m, a) / _dot(a, a)
    return (m[0] - k * a[0], m[1] - k * a[1], m[2] - k * a[2])


def sensor_turn(before: tuple[Vector, Vector], after: tuple[Vector, Vector]) -> float:
    """How far a sensor turned between two frames' (acc, mag), in degrees: the larger of the turn of its
    accelerometer vector (the tilt) and of its magnetometer vector's part across gravity (the heading)."""
    (acc0, mag0), (acc1, mag1) = before, after
    tilt = _angle_deg(acc0, acc1)
    h0, h1 = _across(mag0, acc0), _across(mag1, acc1)
    if _dot(h0, h0) == 0.0 or _dot(h1, h1) == 0.0:
        return tilt     # a field along gravity has no heading
    return max(tilt, _angle_deg(h0, h1))


def settle_change(angles: np.ndarray) -> float:
    """Largest |mean of the newer half - mean of the older half| over the columns of (W, 3) angles."""
    half = len(angles) // 2
    return float(np.max(np.abs(angles[half:].mean(axis=0) - angles[:half].mean(axis=0))))


@dataclass
class NodeGate:
    """One node's verdict, sample by sample (see the module docstring)."""

    index: int
    config: GateConfig = field(default_factory=GateConfig)
    settled: bool = False
    defect: str | None = None            # the last implausibility, until the node has settled again
    last_defect: str | None = None       # the one before it settled
    lost: int = 0                        # samples lost, from the counters
    fused_samples: int = 0               # the filter's age: samples it has taken since the stream began
    _angles: deque = field(default_factory=deque, repr=False)
    _last_counter: int | None = field(default=None, repr=False)
    _last_angles: tuple[float, float, float] | None = field(default=None, repr=False)
    _last_arrival: float | None = field(default=None, repr=False)
    _step: int = field(default=1, repr=False)                      # counter step of the last frame
    _last_pose: tuple[Vector, Vector] | None = field(default=None, repr=False)   # the last checked frame's (acc, mag)
    _since_pose: int = field(default=0, repr=False)                # samples since it, by the counters
    _turned: str | None = field(default=None, repr=False)          # a turn no body makes, for ``count`` to return
    _defect_at: float | None = field(default=None, repr=False)     # arrival time of the last implausibility
    _arrivals: deque = field(default_factory=deque, repr=False)   # (time, frames) over the last second

    def _implausible(self, reason: str) -> None:
        self.defect = f"node {self.index}: {reason}"
        self._defect_at = self._last_arrival
        self.settled = False
        self._angles.clear()
        self._last_angles = None

    def restart(self, counter: int | None = None) -> None:
        """Untrusted from scratch after a break (module docstring): the filter's age, the settle window and
        every verdict forgotten (the samples lost so far are kept); ``counter``: the frame that showed it."""
        self.settled, self.defect, self.last_defect, self.fused_samples = False, None, None, 0
        self._angles.clear()
        self._last_angles, self._last_counter, self._step, self._defect_at = None, counter, 1, None

    def arrived(self, now: float, frames: int) -> str | None:
        """``frames`` frames of the node arrived at ``now``; too many for its rate is a flood. Returns the
        break a silence of ``break_gap_s`` or more before them is (None if none)."""
        gap = None if self._last_arrival is None else now - self._last_arrival
        self._last_arrival = now
        self._arrivals.append((now, frames))
        while self._arrivals[0][0] <= now - 1.0:
            self._arrivals.popleft()
        count = sum(n for _, n in self._arrivals)
        allowed = self.config.flood_factor * self.config.rate_hz + self.config.settle_samples // 2
        if count > allowed:
            self._implausible(f"more frames than its rate allows ({count} in 1 s)")
        if gap is not None and gap >= self.config.break_gap_s:
            return f"a {gap:.1f} s gap in its frames"
        return None

    def count(self, counter: int) -> str | None:
        """A frame's packet counter (fused or not): the break a repeated or jumping counter is, or the turn
        no body makes that ``check_raw`` found in the frame before (module docstring); else None (the
        samples the counter says were lost are counted)."""
        step = 1 if self._last_counter is None else counter_step(self._last_counter, counter)
        self._last_counter = counter
        turned, self._turned = self._turned, None
        if step == 0 or step > self.config.max_counter_step:
            return f"a packet-counter jump (a step of {step})"
        self.lost += step - 1
        self._step = step
        self._since_pose += step
        return turned

    def _turn(self, acc: Vector, mag: Vector) -> str | None:
        """The turn no body makes since the last frame that reached ``check_raw``, if this frame shows one."""
        previous, self._last_pose = self._last_pose, (acc, mag)
        samples, self._since_pose = self._since_pose, 0
        if previous is None:
            return None
        turn = sensor_turn(previous, self._last_pose)
        if turn > self.config.max_turn_deg * max(samples, 1):
            return (f"a turn of {turn:.0f} deg in {samples} sample(s) (faster than {self.config.max_turn_deg_s:g} "
                    "deg/s: no body turns so fast)")
        return None

    def backlog(self, frames: int) -> None:
        """``frames`` frames of a backlog were kept from the filter: it lags, so the node settles again."""
        self._implausible(f"a backlog ({frames} frames not fused)")

    def check_raw(self, mag, gyro, acc) -> bool:
        """A frame before fusion (its counter already ``count``-ed): False (and the node held) if it must not
        reach the filter. A turn no body makes since the last frame is a break, which the next frame's
        ``count`` returns (this one is from the new sitting: it does not reach the old filter)."""
        defect = raw_defect(mag, gyro, acc)
        if defect is not None:
            self._implausible(defect)
            return False
        # the magnetometer's raw z points against the other sensors' (hardware.md section 3: raw z negated)
        turned = self._turn((float(acc[0]), float(acc[1]), float(acc[2])), (float(mag[0]), float(mag[1]), -float(mag[2])))
        if turned is not None:
            self._turned = turned
            self._implausible(turned)
            return False
        return True

    def fused(self, angles: Sequence[float]) -> None:
        """The node's fused (pitch, roll, yaw) for the frame ``check_raw`` let through."""
        angles = (float(angles[0]), float(angles[1]), float(angles[2]))
        self.fused_samples += 1
        previous, self._last_angles = self._last_angles, angles
        if previous is not None:
            jump = max(abs(a - b) for a, b in zip(angles, previous))
            if jump > self.config.max_jump_deg * max(self._step, 1):
                self._implausible(f"angle jump in one sample ({jump:.0f} deg)")
                self._last_angles = angles
                return
        window = self._angles
        window.append(angles)
        if len(window) > self.config.settle_samples:
            window.popleft()
        if (not self.settled and len(window) == self.config.settle_samples
                and self.fused_samples >= self.config.filter_age_samples):
            if settle_change(np.array(window)) < self.config.settle_change_deg:
                self.settled = True
                self.last_defect, self.defect = self.defect, None

    @property
    def change(self) -> float | None:
        """The settle test's value (``settle_change``) over the last window; None until a window is full."""
        if len(self._angles) < self.config.settle_samples:
            return None
        return settle_change(np.array(self._angles))

    def verdict(self, now: float) -> str | None:
        """Why the node cannot be trusted at ``now`` (None if it can)."""
        if self._last_arrival is None or now - self._last_arrival >= self.config.stale_s:
            return f"no frames from node {self.index}"
        if not self.settled:
            return self.defect or f"warming up (node {self.index})"
        if self._defect_at is not None and now - self._defect_at < self.config.resume_s:
            return self.last_defect     # a burst (a backlog) can refill the window at once: wall time counts too
        return None


@dataclass
class Gate:
    """Every node of a model: the arm may move only while all are trusted."""

    nodes: Sequence[int]
    config: GateConfig = field(default_factory=GateConfig)
    node: dict[int, NodeGate] = field(init=False)

    def __post_init__(self) -> None:
        self.node = {index: NodeGate(index, self.config) for index in self.nodes}

    @property
    def settled(self) -> bool:
        return all(gate.settled for gate in self.node.values())

    @property
    def lost(self) -> int:
        return sum(gate.lost for gate in self.node.values())

    def arrivals(self, now: float, counts: Mapping[int, int]) -> dict[int, str]:
        """Frames per node arrived at ``now``: the breaks they end (node -> cause; ``NodeGate.arrived``)."""
        breaks = {}
        for index, count in counts.items():
            if index in self.node and count and (cause := self.node[index].arrived(now, count)) is not None:
                breaks[index] = cause
        return breaks

    def verdict(self, now: float) -> str | None:
        """The first reason (node order) to hold the arm at ``now``; None when every node is trusted."""
        return next((reason for gate in self.node.values() if (reason := gate.verdict(now)) is not None), None)


@dataclass
class ButtonEvidence:
    """A button class reaches the stick only once decided ``samples`` times in a row (module docstring)."""

    samples: int
    buttons: frozenset[str]
    _function: str | None = None
    _run: int = 0

    @classmethod
    def held_for(cls, seconds: float, buttons: Iterable[str]) -> ButtonEvidence:
        """The evidence of a hold of ``seconds`` (a profile's ``button_hold_s``): that many samples'
        decisions, at least one."""
        return cls(max(1, math.ceil(seconds / DT - 1e-9)), frozenset(buttons))

    def reset(self) -> None:
        self._function, self._run = None, 0

    def admit(self, functions: Iterable[str]) -> list[bool]:
        """For each decided function in order: may it reach the stick?"""
        out = []
        for function in functions:
            if function in self.buttons:
                self._run = self._run + 1 if function == self._function else 1
                out.append(self._run >= self.samples)
            else:
                self._run = 0
                out.append(True)
            self._function = function
        return out


class LongPress(Enum):
    """What a button class held long, then rest, asks of the live loop (``LongPressGesture``)."""

    REZERO = "rezero"              # the neutral posture taken anew
    RECALIBRATE = "recalibrate"    # the calibration protocol performed once and the classifier retrained


@dataclass
class LongPressGesture:
    """A button class decided ``rezero`` times in a row, then the neutral class: a re-zero; decided
    ``recalibrate`` times in a row, then the neutral class: a recalibration (module docstring). 0 turns
    a gesture off; the recalibration's hold is the longer one."""

    rezero: int
    recalibrate: int
    buttons: frozenset[str]
    neutral: str
    _function: str | None = None
    _run: int = 0
    _longest: int = 0   # the longest run of one button since the last neutral decision

    def reset(self) -> None:
        self._function, self._run, self._longest = None, 0, 0

    def update(self, functions: Iterable[str]) -> LongPress | None:
        """The decided functions in order: the gesture one of them completes (the last, if two do)."""
        asked = None
        for function in functions:
            if function in self.buttons:
                self._run = self._run + 1 if function == self._function else 1
                self._longest = max(self._longest, self._run)
            else:
                self._run = 0
                if function == self.neutral:
                    asked = self._asked() or asked
                    self._longest = 0
            self._function = function
        return asked

    def _asked(self) -> LongPress | None:
        if 0 < self.recalibrate <= self._longest:
            return LongPress.RECALIBRATE
        if 0 < self.rezero <= self._longest:
            return LongPress.REZERO
        return None
