"""The human operator model: one person, the same behind the joystick and behind the BoMI.

The scripted user (``tasks.operators.planner``) knows the task; this module gives it a human's eyes and
timing, so that the only difference between the joystick and the BoMI conditions is the
interface.  Parameters: ``tasks/operators/human.toml``; sources and the one fitted value: docs/human_model.md.

- **Perception** (``Eyes``), as dm_control's composer observables: the scene is seen every
  ``glance_interval``, ``visual_delay`` late (hand, cubes, the mode on the arm's indicator,
  contact).  Where the cubes, B and the table are relative to the hand is *judged*: one error per judgement,
  std ``lateral_floor + lateral_weber x distance`` across the line of sight from the eyes and
  ``depth_ratio`` times that along it.  A judgement is made anew whenever a move of the stick
  ends, so a move ends where it was misjudged to end and the next look, from closer, brings a
  corrective sub-movement; and, during a long move, whenever a look from where the hand is now
  would be ``closer_look`` times as uncertain as the last judgement (the homing phase is watched;
  near the goal the error's floor stops further re-judging).  The held cube moves with the hand and is seen where it is.
- **Timing** (``HumanTiming``): every new move or press waits a choice reaction time, drawn once:
  an ex-Gaussian simple reaction time plus ``hick_slope x log2(n + 1)`` for the n commands the
  interface offers in the current mode (Hick-Hyman); after a grasp or a release, a look to check
  it; a move of the hand slows as it nears its goal so that it takes ``fitts_slope x log2(2D / W)``
  (Fitts), whatever the interface's top speed allows.  A channel whose
  body adds its own reaction (the BoMI participant starts moving ``reaction_s`` after an intent)
  has that part taken off: the reaction is counted once.
- **The interface as learnt** (``InterfaceModel``): how late and how fast the arm answers a move,
  learnt from what is seen; a move that would be over before its start could be seen is made as a
  pulse of the predicted length, then the person waits and looks (move-and-wait).  From the pulses
  answered, how far a pulse moves the hand (an error under half of that, within what the grasp or
  the release tolerates, is left); from every push answered, how long one has had to be held (a
  push down held that long and not answered counts toward a blocked descent).
- **Slips** (``HumanOperator``): a share of mode presses is forgotten; the person pushes the
  stick as if the mode had changed until they see the arm do something else (or nothing), then
  makes the press (the one right after noticing a slip is not forgotten).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import scipy.stats

from bomi.config_files import from_table, load_toml, positive, section_keys, within
from sim.joystick import Kind, Layout, Mode
from tasks.operators.judgement import Memory, wrapped_angle
from tasks.operators.params import OperatorParams
from tasks.operators.planner import ScriptedUser
from tasks.stacking.vocabulary import REST, Controls, StickIntent, View

DEFAULT_HUMAN_FILE = Path(__file__).with_name("human.toml")
HUMAN_STREAM = 0x4855  # the human's random streams: independent of the task's and the participant's


@dataclass(frozen=True)
class _Perception:
    glance_interval: float
    visual_delay: float
    eye: tuple[float, float, float]  # m, world
    lateral_floor: float
    lateral_weber: float
    depth_ratio: float
    closer_look: float

    def __post_init__(self) -> None:
        within(self, 0.0, math.inf, "glance_interval", "visual_delay", "lateral_floor", "lateral_weber")
        positive(self, "depth_ratio")
        within(self, 0.0, 1.0, "closer_look")


@dataclass(frozen=True)
class _Timing:
    rt_mu: float
    rt_sigma: float
    rt_tau: float
    hick_slope: float
    fitts_slope: float
    check_pause: float

    def __post_init__(self) -> None:
        within(self, 0.0, math.inf, "rt_mu", "hick_slope", "fitts_slope", "check_pause")
        positive(self, "rt_sigma", "rt_tau")


@dataclass(frozen=True)
class _Slips:
    wrong_mode_rate: float
    notice_move: float
    notice_turn_deg: float
    notice_timeout: float

    def __post_init__(self) -> None:
        within(self, 0.0, 1.0, "wrong_mode_rate")
        within(self, 0.0, math.inf, "notice_move", "notice_turn_deg", "notice_timeout")


@dataclass(frozen=True)
class HumanParams(_Slips, _Timing, _Perception):
    """Every key of the human-model file's sections (a human-model file is ``_HumanFile``)."""

    def __post_init__(self) -> None:
        for section in HumanParams.__bases__:
            section.__post_init__(self)


@dataclass(frozen=True)
class _HumanFile:
    perception: _Perception
    timing: _Timing
    slips: _Slips


def load_human(path: Path | str = DEFAULT_HUMAN_FILE, overrides: Mapping[str, Any] | None = None) -> HumanParams:
    """Read and validate a human-model TOML file, with ``overrides`` (dotted keys,
    ``{"timing.fitts_slope": 0.4}``); BomiError names the file and the fault."""
    return load_toml(path, DEFAULT_HUMAN_FILE.parent, "human model", _parse_human, overrides)


def _parse_human(data: dict, source: str) -> HumanParams:
    file = from_table(_HumanFile, data)
    return HumanParams(**section_keys(file.perception, file.timing, file.slips))


# ------------------------------------------------------------------------------------ timing
def simple_reaction_time(p: HumanParams, rng: np.random.Generator) -> float:
    """One ex-Gaussian draw: normal (rt_mu, rt_sigma) plus an exponential tail of mean rt_tau."""
    return float(scipy.stats.exponnorm.rvs(p.rt_tau / p.rt_sigma, loc=p.rt_mu, scale=p.rt_sigma, random_state=rng))


def choice_time(p: HumanParams, alternatives: int, rng: np.random.Generator) -> float:
    """Hick-Hyman: a simple reaction time plus ``hick_slope`` x log2(alternatives + 1)."""
    return max(0.0, simple_reaction_time(p, rng)) + p.hick_slope * math.log2(alternatives + 1)


def fitts_time(p: HumanParams, distance: float, width: float) -> float:
    """Fitts (1954): ``fitts_slope`` x log2(2 distance / width) for a target ``width`` wide (to
    within width / 2), at least 0.  No intercept: the time before a move starts is the choice
    reaction time, counted once."""
    return p.fitts_slope * max(0.0, math.log2(2.0 * distance / width))


def alternatives(controls: Controls, mode: Mode) -> int:
    """The commands the interface offers in ``mode``: the functions that do something there and
    the mode buttons the person has."""
    return len(controls.layout.effects[mode]) + len(controls.buttons)


@dataclass
class HumanTiming:
    """``planner.Timing`` from the human model: choice reaction times drawn once per move, a check
    after a grasp or a release, Fitts' movement time.  ``body_reaction``: the part of a reaction
    the channel's body model already adds after the intent (BoMI participant: ``reaction_s``)."""

    params: HumanParams
    rng: np.random.Generator
    interface: InterfaceModel
    body_reaction: float = 0.0
    pause: float = 0.0  # no rest beyond the reaction: it is the rest

    def reaction(self, view: View, wanted: StickIntent, after: frozenset[Kind], controls: Controls) -> float:
        t = choice_time(self.params, alternatives(controls, view.mode), self.rng)
        if Kind.FINGERS in after:  # the fingers have just closed or opened: look whether it worked
            t += float(self.rng.exponential(self.params.check_pause)) if self.params.check_pause > 0 else 0.0
        return max(0.0, t - self.body_reaction)

    def pace(self, distance: float, tolerance: float) -> float:
        """The time constant of a first-order approach (speed = remaining distance / it): its
        movement time from D to within W / 2 is ``fitts_slope`` x log2(2D / W) (``fitts_time``):
        Fitts' law from a first-order approach (Crossman and Goodeve 1963)."""
        return self.params.fitts_slope / math.log(2.0)

    def hold(self, wanted: StickIntent, settle: float) -> float:
        return self.interface.hold(wanted, settle)

    @property
    def pulse_step(self) -> float:
        return self.interface.pulse_step

    @property
    def answered_hold(self) -> float:
        return self.interface.answered_hold


@dataclass
class InterfaceModel:
    """What the person has learnt of how the arm answers the stick, from what they saw (an internal
    forward model; adaptation to a feedback delay): how long after a move starts the hand is seen to
    move (``onset``, 0 at first: a stick is expected to answer at once), and how fast it goes for a
    deflection, per function (``gain``: seen peak speed / (``full_speed`` x deflection), 1 at first),
    both from the hand's motion along the way the function pushes it (a misread's or a slip's is not its answer).
    A move so short that it would be over before its start can be seen (its time at the expected
    speed below ``onset``) cannot be steered by watching: it is made as a pulse of the length the
    model predicts, then the person waits for the hand to settle and looks again (move-and-wait,
    Ferrell 1965; Sheridan and Ferrell 1963).  Through a stick that answers at once ``onset`` is the
    visual delay and no move is that short; through a laggy channel the small corrections become
    pulses.  Also learnt: how far the hand went for the pulses it answered (``pulse_step``: the planner
    leaves an error under half of it where the task tolerates it) and how long a push had been held
    when it was seen answered (``answered_hold``: a push down held that long and not answered counts
    toward a stalled descent).  No parameter of its own: the operator file's ``learning_rate``,
    ``full_speed``, ``still_speed``, ``max_wait``."""

    learning_rate: float
    full_speed: float  # m/s at full deflection, as the person has seen it
    still_speed: float  # m/s: the hand is seen at rest below this
    max_onset: float  # s: the longest onset learnt (the operator's max_wait)
    onset: float = 0.0
    gain: dict[str, float] = field(default_factory=dict)
    pulse_step: float = 0.0  # m: how far the hand went for the pulses it answered, a running mean (0 at first: as little as wanted)
    answered_hold: float = 0.0  # s: how long the pushes it answered had been held when it was seen answering them
    # the last move: (start, function, deflection, hold, hand, the unit direction the function moves the hand)
    _move: tuple[float, str, float, float, np.ndarray, np.ndarray] | None = None
    _seen_onset: float | None = None  # when the hand was first seen moving since that move started
    _peak: float = 0.0  # the fastest the hand was seen going since
    _last: View | None = None

    def hold(self, wanted: StickIntent, settle: float) -> float:
        """The pulse length for a move of the hand (inf: steer it by watching)."""
        if not wanted.deflection or wanted.remaining <= 0:
            return math.inf
        function, deflection = max(wanted.deflection.items(), key=lambda item: item[1])
        expected = self.gain.get(function, 1.0) * self.full_speed * deflection
        travel = wanted.remaining / expected
        if travel >= self.onset:
            return math.inf
        return max(0.0, self.onset - settle) + travel

    def observe(self, seen: View, current: StickIntent, started: float, hold: float, layout: Layout) -> None:
        """One glance: the move held now (``current``, begun at ``started``, held ``hold`` at most, its
        functions those of ``layout`` in the mode seen).  What is learnt of a move is how fast the hand
        goes the way it was pushed: a hand moved another way (a misread, a slip) is not its answer."""
        last, self._last = self._last, seen
        if current.remaining > 0 and (self._move is None or started != self._move[0]):
            self._learn(seen)
            function, deflection = max(current.deflection.items(), key=lambda item: item[1])
            self._move = (started, function, deflection, hold, seen.hand_pos,
                          np.asarray(layout.effects[seen.mode][function].axis, dtype=float))
            self._seen_onset, self._peak = None, 0.0
            return
        speed = 0.0 if self._move is None or last is None or seen.t <= last.t else \
            float(np.dot(seen.hand_pos - last.hand_pos, self._move[5])) / (seen.t - last.t)
        if self._move is not None and speed > self.still_speed:
            if self._seen_onset is None:
                self._seen_onset = seen.t - self._move[0]
            self._peak = max(self._peak, speed)

    def _learn(self, now: View) -> None:
        """A new move begins (the hand at rest ``now``): learn from the last one.  A pulse the hand
        was never seen to answer says the onset is longer than that; one it answered, how far the
        pulse moves the hand (``pulse_step``); any move it answered, how long a push has had to be held
        to be answered (``answered_hold``); any other move that did not move the hand (pushed into the
        table, in the wrong mode) says nothing."""
        if self._move is None:
            return
        start, function, deflection, hold, hand, direction = self._move
        pulse = math.isfinite(hold)
        rate = self.learning_rate
        if self._seen_onset is not None:
            seen = self._seen_onset
            self.answered_hold = (1 - rate) * self.answered_hold + rate * min(hold, seen)
            if pulse:
                went = abs(float(np.dot(now.hand_pos - hand, direction)))
                self.pulse_step = (1 - rate) * self.pulse_step + rate * went
            seen_gain = self._peak / (self.full_speed * deflection)
            self.gain[function] = (1 - rate) * self.gain.get(function, 1.0) + rate * seen_gain
        elif pulse:
            seen = now.t - start
        else:
            return
        self.onset = (1 - rate) * self.onset + rate * min(seen, self.max_onset)


# ------------------------------------------------------------------------------------ perception
def judgement_error(p: HumanParams, hand: np.ndarray, distance: float, rng: np.random.Generator) -> np.ndarray:
    """Error (3,) of one judgement of where something ``distance`` away from the ``hand`` is,
    relative to the hand: std lateral_floor + lateral_weber x distance across the line of sight
    from the eyes, ``depth_ratio`` times that along it."""
    sight = hand - p.eye
    sight = sight / np.linalg.norm(sight)
    z = rng.standard_normal(3)
    along = float(np.dot(z, sight))
    return judgement_sigma(p, distance) * ((z - along * sight) + p.depth_ratio * along * sight)


def judgement_sigma(p: HumanParams, distance: float) -> float:
    """Std (m) across the line of sight of a judgement made from ``distance``."""
    return p.lateral_floor + p.lateral_weber * distance


def landmark_distance(view: View) -> float:
    """How far the hand is from the nearest thing it may be going to: a cube it does not hold, or B."""
    points = [pos for pos, touch in zip(view.cube_pos, view.touching) if not touch]
    points.append(np.r_[view.target_xy, view.table_z])
    return float(min(np.linalg.norm(np.asarray(q) - view.hand_pos) for q in points))


class Eyes:
    """What the person sees: the view ``visual_delay`` old, once per ``glance_interval``, with the
    cubes (but the held one), B and the table top displaced by the current judgement error: one error for all,
    so whether a cube rests on the table, at B or on the other cube is seen as it is."""

    def __init__(self, params: HumanParams, rng: np.random.Generator):
        self.params, self.rng = params, rng
        self._frames: deque[View] = deque()
        self._next_glance = -math.inf
        self._error: np.ndarray | None = None  # None: judge anew at the next glance
        self._judged_sigma = math.inf  # the error std of the current judgement (judgement_sigma)

    def rejudge(self) -> None:
        self._error = None

    def see(self, view: View) -> View | None:
        """The judged view when a glance is due at ``view.t``, else None."""
        self._frames.append(view)
        while len(self._frames) > 1 and self._frames[1].t <= view.t - self.params.visual_delay + 1e-9:
            self._frames.popleft()
        if view.t + 1e-9 < self._next_glance:
            return None
        self._next_glance = view.t + self.params.glance_interval
        seen = self._frames[0]
        distance = landmark_distance(seen)
        sigma = judgement_sigma(self.params, distance)
        if self._error is None or sigma < self.params.closer_look * self._judged_sigma:
            self._error = judgement_error(self.params, seen.hand_pos, distance, self.rng)
            self._judged_sigma = sigma
        e = self._error
        cubes = tuple(pos if touch else pos + e for pos, touch in zip(seen.cube_pos, seen.touching))
        return replace(seen, cube_pos=cubes, target_xy=seen.target_xy + e[:2], table_z=seen.table_z + e[2])


# ------------------------------------------------------------------------------------ the person
@dataclass(frozen=True)
class Slip:
    """A forgotten mode press: the mode the person believes in, and the arm as it was then."""

    believed: Mode
    since: float
    hand: np.ndarray
    yaw: float
    tilt: np.ndarray
    closure: float


class HumanOperator:
    """The scripted user with the human model's eyes, timing and slips (``stick_intent`` like
    ``ScriptedUser.stick_intent``, called every control tick with the true view)."""

    def __init__(self, params: HumanParams, operator: OperatorParams, combine_axes: bool, controls: Controls,
                 seed: int, body_reaction: float = 0.0):
        eyes_rng, timing_rng, slip_rng = (np.random.default_rng(s)
                                          for s in np.random.SeedSequence([seed, HUMAN_STREAM]).spawn(3))
        self.params, self.controls, self._rng = params, controls, slip_rng
        self.interface = InterfaceModel(operator.learning_rate, operator.full_speed, operator.still_speed,
                                        operator.max_wait)
        self.timing = HumanTiming(params, timing_rng, self.interface, body_reaction)
        self.user = ScriptedUser(operator, combine_axes=combine_axes, memory=Memory(controls=controls),
                                 timing=self.timing)
        self.eyes = Eyes(params, eyes_rng)
        self.intent = REST
        self.slip: Slip | None = None
        self.slips: list[tuple[float, float]] = []  # (start, noticed) of every wrong-mode episode
        self._just_noticed = False  # a slip was noticed and the press not made yet

    def stick_intent(self, view: View) -> StickIntent:
        seen = self.eyes.see(view)
        if seen is None:
            return self.intent
        if self.slip is not None:
            if self._noticed(seen):
                self.slips.append((self.slip.since, seen.t))
                self.slip, self._just_noticed = None, True
            else:
                seen = replace(seen, mode=self.slip.believed)
        intent = self.user.stick_intent(seen)
        new_press = intent.button is not None and intent.button != self.intent.button
        if new_press and self.slip is None and not self._just_noticed \
                and self._rng.random() < self.params.wrong_mode_rate:
            # the press is forgotten: the person goes on as if the mode had changed
            self.slip = Slip(self.controls.layout.after(seen.mode, intent.button), seen.t, seen.hand_pos,
                             seen.hand_yaw, seen.hand_tilt, seen.closure)
            intent = replace(REST, goal=intent.goal)
        elif new_press:
            self._just_noticed = False
        if self.intent.deflection and not intent.functions & self.intent.functions:
            self.eyes.rejudge()  # a move of the stick ends: the person looks again from where the hand is
        self.interface.observe(seen, self.user.current, self.user.started, self.user.hold, self.controls.layout)
        self.intent = intent
        return intent

    def resume(self, view: View) -> None:
        """Take the task up again after a recovery (``ScriptedUser.resume``), from rest and a new look."""
        self.user.resume(view)
        self.intent, self.slip = REST, None
        self.eyes.rejudge()

    def back_off(self, view: View) -> None:
        """Lift the hand and plan afresh (``ScriptedUser.back_off``), from a new look."""
        self.user.back_off(view)
        self.resume(view)

    def _noticed(self, seen: View) -> bool:
        """The arm did something the person did not expect, or nothing for ``notice_timeout``."""
        s, p = self.slip, self.params
        yaw = wrapped_angle(seen.hand_yaw - s.yaw, 2 * math.pi)
        turned = max(abs(yaw), float(np.max(np.abs(seen.hand_tilt - s.tilt))))
        changed = (np.linalg.norm(seen.hand_pos - s.hand) > p.notice_move or math.degrees(turned) > p.notice_turn_deg
                   or abs(seen.closure - s.closure) > 0.05)
        pushed_since = None if self.user.current.is_rest else self.user.started
        stuck = pushed_since is not None and seen.t - max(pushed_since, s.since) > p.notice_timeout
        return changed or stuck
