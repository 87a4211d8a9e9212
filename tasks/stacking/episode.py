"""One episode: the one loop that advances simulated time at the 60 Hz control rate.

Joystick channel: planner intent -> JoystickState -> arm.
BoMI channel: planner intent -> virtual participant (body motion) -> base-station frames ->
FrameParser -> OnlineChain -> Decision -> joystick function with nu as deflection (a B1/B2 class
presses its button on the rising edge) -> arm.  IMU samples and control ticks share one clock.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Protocol

import numpy as np

from bomi.chain import Decision, OnlineChain, train
from bomi.classifier import NEUTRAL_LABEL, PostProcessing
from bomi.frames import SAMPLE_PERIOD_S
from bomi.errors import BomiError
from bomi.fusion import DT, WARMUP_S
from bomi.profiles import Profile
from sim.env import ArmSim
from sim.kernels import clip
from sim.joystick import BUTTONS, FUNCTIONS, JoystickState, Kind, Layout, Mode, combined
from sim.render import FrameRenderer, VideoWriter, describe, site_colour
from tasks.stacking import failures, metrics
from tasks.operators.assist import NONE, Assist, Assistance, AutomaticSwitch, assist_label, profile_assist
from tasks.operators.human import HumanOperator, load_human
from tasks.participants.imu_synth import Delivery
from tasks.participants.participant import (Feel, ParticipantParams, VirtualParticipant, calibration_session, load_participant,
                               session_recording)
from tasks.participants.receiver import Receiver
from tasks.operators.planner import (DEFAULT_OPERATOR_FILE, NO_HUMAN_MODEL, NO_RECOVERY, Controls, Memory, OperatorParams,
                           Phase, ScriptedUser, StickIntent, View, load_operator)
from tasks.operators.recovery import RecoveryEvent, Supervisor
from tasks.stacking.task import StackingTask, TaskConfig
from tasks.operators.stick import DecisionStick, arm_profile, profile_layout, rising_edge

OPERATORS = ("joystick", "bomi")
_MODE_VALUE = {mode: mode.value for mode in Mode}  # what a log records of a mode and a stage, looked up
_STAGE_VALUE = {None: "", **{phase: phase.value for phase in Phase}}


@dataclass
class DecisionTrace:
    """One entry per classifier decision."""

    t: np.ndarray
    intended: np.ndarray  # class label the participant was performing
    decided: np.ndarray  # class label the chain output
    gamma: np.ndarray
    nu: np.ndarray
    lean: np.ndarray | None = None  # the participant's intended lean (0-1 of their range; 0 at neutral)
    body_deg: np.ndarray | None = None  # the body's true angle from the neutral the chain calibrated (deg)


@dataclass
class EpisodeLog:
    """Everything an episode records; metrics and figures are computed from it."""

    operator: str
    participant: str
    seed: int
    controls: str  # the layout and buttons the operator had (Controls.label)
    t: np.ndarray  # (N,) control ticks
    hand_pos: np.ndarray  # (N, 3)
    intended_dir: np.ndarray  # (N, 3) unit direction the person wanted, zero when resting
    mode: list[str]
    presses: int
    cube_pos: np.ndarray  # (N, K, 3)
    touching: np.ndarray  # (N, K)
    target_pos: np.ndarray  # (3,) B on the table top
    success: bool
    completion_time: float | None
    failure: str | None
    wall_time: float
    cpu_time: float  # this process's CPU seconds: the speed on one core, whatever else runs
    pushing: np.ndarray | None = None  # (N,) the person held a stick function (not a button, not at rest)
    decisions: DecisionTrace | None = None
    class_names: tuple[str, ...] = ()
    neutral: int = 0
    allowance: int = 0  # decisions after an intent change that belong to the transition
    sample_period: float = SAMPLE_PERIOD_S
    amplitude: str = "gamma"  # what the decisions' amplitude is: the profile's [proportional] amplitude
    goals: tuple[str, ...] = ()  # per control tick: the scripted user's step (planner Goal.step, plain words)
    stages: tuple[str, ...] = ()  # per control tick: the stage of the step's approach (planner Phase value, or "")
    assist: str = NONE  # the assistances on (tasks.operators.assist.assist_label)
    automatic: tuple[AutomaticSwitch, ...] = ()  # the mode switches the assistance made
    grasp_helps: int = 0  # closes the grasp help started
    commanded: np.ndarray | None = None  # (N, 3) hand velocity the stick commanded the arm (m/s, world)
    recovery: str = NO_RECOVERY  # the recovery actions on (RecoveryParams.label)
    recoveries: tuple[RecoveryEvent, ...] = ()  # the recovery actions taken (tasks.operators.recovery)


# allowances (s) at which the excused accuracy is also given: its curve shows what excusing buys
ALLOWANCE_CURVE_S = tuple(round(0.1 * k, 1) for k in range(16))
WRONG_GOAL_WINDOW_S = 1.0  # an automatic switch the user's own press undoes this soon chose the wrong mode


def summarize(log: EpisodeLog) -> dict:
    """The per-episode metrics as a JSON-ready dict."""
    sim_time = float(log.t[-1]) if len(log.t) else 0.0
    out = {
        "operator": log.operator,
        "participant": log.participant,
        "seed": log.seed,
        "layout": log.controls,
        "success": bool(log.success),
        "completion_time": log.completion_time,
        "failure": log.failure,
        "sim_time": sim_time,
        "wall_time": log.wall_time,
        "cpu_time": log.cpu_time,
        "realtime_factor": sim_time / log.wall_time if log.wall_time > 0 else None,
        "realtime_factor_cpu": sim_time / log.cpu_time if log.cpu_time > 0 else None,
        "assist": log.assist,
        "mode_switches": metrics.user_mode_switches(log.mode, [s.tick for s in log.automatic]),
        "automatic_switches": len(log.automatic),
        "wrong_goal_switches": metrics.wrong_goal_switches(log.t, log.mode, [s.tick for s in log.automatic],
                                                           WRONG_GOAL_WINDOW_S),
        "refused_switches": sum(s.refused for s in log.automatic),
        "undone_switches": sum(s.undone for s in log.automatic),
        "grasp_helps": log.grasp_helps,
        "button_presses": log.presses,
        "unintended_displacement_mm": metrics.unintended_displacement_mm(log.hand_pos, log.intended_dir),
        "cube_drops": metrics.cube_drops(log.cube_pos[:, :, 2], log.touching),
        "stuck": failures.summary(log),  # the longest span without progress and its mechanism
        "recovery": log.recovery,
        "recoveries": [{"action": e.action.value, "start_s": e.start_s, "end_s": e.end_s, "obeyed": e.obeyed}
                       for e in log.recoveries],
    }
    d = log.decisions
    if d is None:
        return out
    errors = metrics.misclassified(d.intended, d.decided, log.allowance, log.neutral)
    wild = metrics.irrelevant(d.intended, d.decided, log.neutral)
    onsets = metrics.onset_latencies(d.intended, d.decided, log.neutral)
    latency_ms = metrics.recognised(onsets) * 1000.0 * log.sample_period
    curve = np.round(np.array(ALLOWANCE_CURVE_S) / log.sample_period).astype(int)
    out.update({
        "decisions": int(len(d.t)),
        "decisions_intended_active": int(np.sum(d.intended != log.neutral)),
        "decisions_emitted_active": int(np.sum(d.decided != log.neutral)),
        "accuracy_all_decisions": metrics.accuracy_all_decisions(d.intended, d.decided),
        "accuracy_excused_transitions": metrics.accuracy_excused_transitions(d.intended, d.decided, log.allowance,
                                                                             log.neutral),
        "excused_share": metrics.excused_share(d.intended, d.decided, log.allowance, log.neutral),
        "excused_allowance_samples": log.allowance,
        "excused_allowance_ms": 1000.0 * log.allowance * log.sample_period,
        "accuracy_vs_allowance": {"allowance_s": list(ALLOWANCE_CURVE_S),
                                  "accuracy": metrics.accuracy_vs_allowance(d.intended, d.decided, curve).tolist()},
        "misclassified": int(errors.sum()),
        "longest_error_run_ms": metrics.longest_error_run_ms(errors, log.sample_period),
        **{f"errors_{k}": v for k, v in metrics.error_destinations(d.decided, errors, log.neutral).items()},
        "irrelevant_decisions": int(wild.sum()),
        "irrelevant_runs": len(metrics.runs(wild)),
        "irrelevant_per_min": metrics.per_minute(len(metrics.runs(wild)), len(d.t), log.sample_period),
        "irrelevant_longest_run_ms": metrics.longest_error_run_ms(wild, log.sample_period),
        "latency_onsets_ms": latency_ms.tolist(),
        "onsets": len(onsets),
        "onsets_unrecognised": sum(n is None for n in onsets),  # the intent ended before the chain output it
        "latency_ms_median": float(np.median(latency_ms)) if latency_ms.size else None,
        "latency_ms_p90": float(np.percentile(latency_ms, 90)) if latency_ms.size else None,
        "latency_ms_max": float(latency_ms.max()) if latency_ms.size else None,
    })
    return out


class OperatorChannel(Protocol):
    """How the person's stick intent reaches the arm's stick: straight (``JoystickChannel``) or
    through a body motion and the BoMI chain (``BomiChannel``)."""

    combine_axes: bool  # the person may push several functions at once (a 3-axis stick can)
    controls: Controls  # the layout and buttons the person has
    body_reaction: float  # s of the person's reaction the channel's body model adds after an intent

    def command(self, intent: StickIntent, t: float, t_end: float, seen: np.ndarray | None = None,
                mode: Mode = Mode.TRANSLATION) -> JoystickState:
        """The stick over the control tick [t, t_end) of task time. ``seen``: the hand's velocity as
        a fraction of full speed (None on the first tick); ``mode``: the arm's mode."""

    def log_fields(self) -> dict:
        """Extra ``EpisodeLog`` fields the channel recorded (the BoMI's decisions)."""

    def begin_rezero(self) -> None:
        """Take the neutral posture anew from the samples to come (``tasks.operators.recovery``; a stick: nothing)."""

    @property
    def rezeroing(self) -> bool:
        """The neutral posture asked for is still being taken."""

    def caption(self) -> str | None:
        """A line for the film about what happens between the person and the stick (None: nothing)."""


class JoystickChannel:
    """The person's decision goes straight to the stick (a stick may combine axes).  ``controls``:
    the able-bodied baseline's stick; by default a real 3-axis JACO stick with both buttons, for a
    like-for-like comparison the layout and buttons a BoMI profile gives (``profile_controls``)."""

    combine_axes = True
    body_reaction = 0.0  # the hand on the stick adds no reaction of its own to the person's

    def __init__(self, controls: Controls = Controls()) -> None:
        self.controls = controls
        self._button: str | None = None

    def command(self, intent: StickIntent, t: float, t_end: float, seen: np.ndarray | None = None,
                mode: Mode = Mode.TRANSLATION) -> JoystickState:
        pressed = rising_edge(intent.button, self._button)
        self._button = intent.button
        return JoystickState(dict(intent.deflection), pressed)

    def log_fields(self) -> dict:
        return {}

    def begin_rezero(self) -> None:
        """A stick has no neutral posture to take anew."""

    rezeroing = False

    def caption(self) -> None:
        """Nothing between the person and the stick to show."""
        return None


@dataclass
class LeanFeel:
    """The participant's feel for one proportional class: a wanted deflection d asks for a lean of
    zero + (1 - zero) x d, never below the least lean calibrated (``Feel.least_lean``).  ``zero``
    (the lean at which the arm would just not move; at first the least lean) is learnt from the
    leans that worked: after correcting a move to ``lean`` for a wanted ``d``, the next move of that
    class starts from there."""

    feel: Feel
    zero: float | None = None

    def __post_init__(self) -> None:
        if self.zero is None:
            self.zero = self.feel.least_lean

    def lean_for(self, deflection: float) -> float:
        return clip(self.zero + (1.0 - self.zero) * deflection, self.feel.least_lean, 1.0)

    def learn(self, lean: float, deflection: float) -> None:
        if deflection < 1.0:
            self.zero = float(np.clip((lean - deflection) / (1.0 - deflection), 0.0, self.feel.max_zero))

    def corrected(self, lean: float, further: bool) -> float:
        """The lean one correction of ``lean`` takes (``lean_step`` further, or less far)."""
        step = self.feel.lean_step if further else -self.feel.lean_step
        return clip(lean + step, self.feel.least_lean, 1.0)


@dataclass
class Watched:
    """The proportional posture the participant took up last, and what they have seen the arm do
    with it: its speed along the posture's direction while the arm answers it (smoothed), including
    after they let go of it (the arm answers late)."""

    label: int
    lean: float
    wanted: float  # the deflection the lean was meant to give
    speed: float = 0.0
    judged: bool = False  # let go of and seen too fast: already taught the feel a lesser lean


def profile_controls(profile: Profile) -> Controls:
    """The controls a profile's classes give the scripted user: its joystick layout and the mode
    buttons it has a class for.  The user needs every direction of the layout, and B1 unless the
    profile switches the modes automatically (``[assist] options`` auto-mode): without a button the
    user rests and waits for the switch (docs/task.md, "Without a mode button")."""
    layout = profile_layout(profile)
    functions = {cls.function for cls in profile.classes}
    needed = (*layout.functions, *(() if Assist.AUTO_MODE in profile_assist(profile) else ("B1",)))
    missing = [f for f in needed if f not in functions]
    if missing:
        without = " (or, without B1, [assist] options = [\"auto-mode\"])" if "B1" in missing else ""
        raise BomiError(f"{profile.source}: profile {profile.name} has no class for {', '.join(missing)}; "
                        f"the scripted stacking user with the {layout.name} layout needs {', '.join(needed)}{without}")
    return Controls(layout, tuple(b for b in BUTTONS if b in functions))


def participant_controls(participant: str | ParticipantParams) -> Controls:
    """The controls of a participant's BoMI profile (what a like-for-like joystick baseline gets)."""
    params = participant if isinstance(participant, ParticipantParams) else load_participant(participant)
    return profile_controls(arm_profile(params.profile))


class BomiChannel:
    """The person's decision becomes a body motion; the stick is whatever the chain decides.

    Participant time runs ``clock_offset`` seconds ahead of the task: the warm-up and the neutral-offset
    calibration happen before the task's clock starts.  One class at a time: the participant
    holds a posture for as long as the same function is wanted, starting from the lean their feel
    gives for the wanted deflection and correcting it while watching the arm (``_corrected_lean``).
    """

    combine_axes = False

    def __init__(self, participant: VirtualParticipant, chain: OnlineChain, profile: Profile,
                 calibrate: bool = True):
        """``calibrate``: warm up and take the neutral posture here, on ``chain``, before the task's
        clock starts (False: the frames go elsewhere, e.g. a live loop that calibrates itself)."""
        self.participant, self.chain, self.profile = participant, chain, profile
        self.receiver = Receiver(chain)
        self.controls = profile_controls(profile)
        self._label_of = {cls.function: cls.label for cls in profile.classes}
        self._function_of = {cls.label: cls.function for cls in profile.classes}
        self._since = 0.0  # when the posture held now was taken up (or last changed)
        # the participant's feel for each stick-direction class (how far to lean for how fast)
        self.feel = {cls.label: LeanFeel(participant.params.feel) for cls in profile.classes
                     if cls.function in FUNCTIONS}
        self._watched: Watched | None = None  # the proportional posture taken up last
        # what _watch reads every tick, made once: per mode, the hand axis each stick function moves along
        # (as Python floats), and the share of a tick in the speed's smoothing
        layout = self.controls.layout
        self._linear_axes = {mode: {function: tuple(float(v) for v in axis)
                                    for function, axis in layout.axes(mode, Kind.LINEAR).items()}
                             for mode in layout.modes}
        self._smoothing = min(1.0, DT / participant.params.feel.speed_smoothing_s)
        # how long the person waits for a posture (or a change of lean) to take effect before
        # leaning further: reaction + the body's move + a second of watching
        self._patience = participant.params.reaction_s + participant.params.onset_s + participant.params.feel.watch_s
        # the body starts moving reaction_s after an intent: that much of the person's reaction is here
        self.body_reaction = participant.params.reaction_s
        self._decided: int | None = None  # the label of the chain's latest decision
        self.stick = DecisionStick(profile)
        self._rows: list[tuple[int, int, float, float]] = []  # (sample, decided label, gamma, nu)
        self._queue: list[Delivery] = []  # generated frames, those from _next_frame on not yet arrived
        self._next_frame = 0              # in the first delivery of the queue
        # An intent set at t moves the body from t + reaction_s: samples may be made that far ahead.
        self._lookahead = 0.95 * participant.params.reaction_s
        self._asked_until = -np.inf
        self.clock_offset = 0.0
        if not calibrate:
            return
        self.receiver.take(participant.deliveries(WARMUP_S))
        self.receiver.until(WARMUP_S)
        chain.begin_neutral_calibration()
        t = WARMUP_S
        while chain.calibrating:
            t += 0.1
            self.receiver.take(participant.deliveries(t))
            self.receiver.until(t)
        self.clock_offset = t

    def _made(self, now: float, t_end: float) -> Delivery | None:
        """A new chunk of the participant's frames when frames of samples not made yet could arrive by
        ``t_end``: samples are made in chunks as long as the lookahead allows (each chunk costs a call
        of the synthesis: fewer, longer chunks; the same samples, frames and arrival times, as a chunk's
        samples do not depend on where it was cut)."""
        if t_end <= self._asked_until:
            return None
        self._asked_until = max(t_end, now + self._lookahead)
        return self.participant.deliveries(self._asked_until)

    def arrived(self, now: float, t_end: float) -> bytes:
        """The bytes of the frames arriving by ``t_end`` (for a receiver of its own: a live loop)."""
        made = self._made(now, t_end)
        if made is not None:
            self._queue.append(made)
        arrived = []
        while self._queue:   # (Delivery.until's split, kept as an index: no slicing of the rest every tick)
            first = self._queue[0]
            end = max(int(np.searchsorted(first.arrival_s, t_end, side="right")), self._next_frame)
            arrived += first.frames[self._next_frame:end]
            if end < len(first.frames):
                self._next_frame = end
                break
            self._queue.pop(0)
            self._next_frame = 0
        return b"".join(arrived)

    def intent_class(self, intent: StickIntent) -> tuple[int, float]:
        """(class label, amplitude) the participant performs for the person's intent."""
        if intent.button is not None:
            return self._label_of[intent.button], 1.0
        if not intent.deflection:
            return NEUTRAL_LABEL, 0.0
        (function, deflection), = intent.deflection.items()
        label = self._label_of[function]
        feel = self.feel.get(label) or LeanFeel(self.participant.params.feel)
        return label, feel.lean_for(float(deflection))

    def command(self, intent: StickIntent, t: float, t_end: float, seen: np.ndarray | None = None,
                mode: Mode = Mode.TRANSLATION) -> JoystickState:
        """``seen``: the hand's velocity as a fraction of full speed, in the arm's ``mode``: what the
        participant watches to judge whether to lean further or less."""
        self.perform(intent, t, seen, mode)
        made = self._made(self.clock_offset + t, self.clock_offset + t_end)
        if made is not None:
            self.receiver.take(made)
        decided = self.receiver.until(self.clock_offset + t_end)
        if not decided:
            return self.answered(decided)
        self._rows += [(sample, decision.label, decision.gamma, decision.nu) for sample, decision in decided]
        return self.answered([decision for _, decision in decided])

    def answered(self, decisions: list[Decision]) -> JoystickState:
        """The chain's ``decisions`` reach the stick (what the participant then sees the arm answer)."""
        if decisions:
            self._decided = decisions[-1].label
        return self.stick.update(decisions)

    def perform(self, intent: StickIntent, t: float, seen: np.ndarray | None = None,
                mode: Mode = Mode.TRANSLATION) -> None:
        """The posture the participant takes up (or the lean they correct) at task time ``t`` for the
        person's ``intent``, having seen the hand move at ``seen`` in ``mode``."""
        label, amplitude = self.intent_class(intent)
        held, held_amplitude = self.participant.intent
        wanted = float(next(iter(intent.deflection.values()), 0.0))
        judged = self._watch(seen, mode)
        if label != held:
            self._take_up(label, amplitude, t)
            if label in self.feel:
                self._watched = Watched(label, amplitude, wanted)
        elif label in self.feel:
            self._watched.wanted = wanted
            lean = self._corrected_lean(label, held_amplitude, t, judged)
            if lean != held_amplitude:
                self._take_up(label, lean, t)
                self._watched.lean = lean
                self.feel[label].learn(lean, wanted)
        self._learn_from_overshoot(label)

    def begin_rezero(self) -> None:
        """The chain takes the neutral posture anew from the next samples (the person holds still)."""
        self.chain.begin_neutral_calibration()

    @property
    def rezeroing(self) -> bool:
        return self.chain.calibrating

    def caption(self) -> str:
        """The class the participant performs and the class the chain decided last (for the film)."""
        intended, decided = self.participant.intent[0], self._decided
        relation = "=" if decided == intended else "\u2260"  # not equal
        return f"BoMI  intended {self._class_text(intended)} {relation} decided {self._class_text(decided)}"

    def _class_text(self, label: int | None) -> str:
        if label is None:
            return "nothing yet"
        cls = next(c for c in self.profile.classes if c.label == label)
        return f"c{label} {cls.function} ({cls.name.split(' (')[0]})"

    def _take_up(self, label: int, amplitude: float, t: float) -> None:
        self.participant.set_intent(label, amplitude, self.clock_offset + t)
        self._since = t

    def _watch(self, seen: np.ndarray | None, mode: Mode) -> bool:
        """Follow the arm's speed along the watched posture's direction while the arm answers that
        posture (held or already let go of); whether the person can judge it now (a move of the hand
        in ``mode``: a speed the person can see)."""
        watched = self._watched
        if watched is None or seen is None:
            return False
        function = self._function_of[watched.label]
        axis = self._linear_axes[mode].get(function)
        if axis is None:
            return False
        if self.stick.function == function:
            (x, y, z), (ax, ay, az) = seen.tolist(), axis
            along = 0.0 + x * ax + y * ay + z * az   # np.dot's sum of a (3,) . (3,) product, in its order
            watched.speed += (along - watched.speed) * self._smoothing
        return True

    def _corrected_lean(self, label: int, lean: float, t: float, judged: bool) -> float:
        """The lean the participant holds now in the proportional class ``label``: further when the
        chain has not answered the posture for a while or (``judged``: a speed they can see) when
        the arm goes much slower than wanted; less far when it goes much faster.  Each correction
        is given the patience to take effect."""
        if t - self._since <= self._patience:
            return lean
        feel, watched = self.participant.params.feel, self._watched
        answered = self.stick.function == self._function_of[label]
        if not answered or (judged and watched.speed < feel.too_slow * watched.wanted):
            return self.feel[label].corrected(lean, further=True)
        if judged and watched.speed > feel.too_fast * watched.wanted:
            return self.feel[label].corrected(lean, further=False)
        return lean

    def _learn_from_overshoot(self, held: int) -> None:
        """A posture let go of while the arm, still answering it, went much faster than wanted (the
        arm answers the body late: it overshoots the goal): the next move of that class leans less."""
        watched = self._watched
        if watched is None or watched.label == held or watched.judged:
            return
        if watched.speed > self.participant.params.feel.too_fast * watched.wanted:
            feel = self.feel[watched.label]
            feel.learn(feel.corrected(watched.lean, further=False), watched.wanted)
            watched.judged = True

    def log_fields(self) -> dict:
        truth = self.participant.truth()
        rows = np.array(self._rows, dtype=float).reshape(-1, 4)
        samples = rows[:, 0].astype(int)
        trace = DecisionTrace(t=samples * DT - self.clock_offset, intended=truth.intent[samples].astype(int),
                              decided=rows[:, 1].astype(int), gamma=rows[:, 2], nu=rows[:, 3],
                              lean=truth.amplitude[samples], body_deg=self._body_deg(truth, samples))
        names = tuple(cls.function for cls in sorted(self.profile.classes, key=lambda c: c.label))
        return {"decisions": trace, "class_names": names, "neutral": NEUTRAL_LABEL,
                "allowance": self.transition_samples, "sample_period": DT, "amplitude": self.profile.amplitude}

    def _body_deg(self, truth, samples: np.ndarray) -> np.ndarray:
        """At each of ``samples``: how far the body's true angles are from their mean over the neutral
        calibration (norm over the nodes' angles, deg): the body's true move from the neutral the chain took."""
        calibration = (truth.time_s >= WARMUP_S) & (truth.time_s < self.clock_offset)
        if not calibration.any():  # calibrated elsewhere (a live loop): no neutral known here
            return np.full(len(samples), np.nan)
        neutral = truth.angles[calibration].mean(axis=0)
        return np.linalg.norm((truth.angles[samples] - neutral).reshape(len(samples), -1), axis=1)

    @property
    def transition_samples(self) -> int:
        """Samples after a motion onset that belong to the transition: the body's move, then a
        full window and the vote."""
        move = int(np.ceil(self.participant.params.onset_s / DT))
        return move + self.chain.model.spec.window + self.chain.model.post.vote_length


def calibration_order(params: ParticipantParams, profile: Profile, repetitions: int = 3) -> list[tuple[int, float]]:
    """The protocol's (class, amplitude) sequence: proportional classes at both ends of the body
    range (so gamma's calibrated range spans the leans used), button classes at full range only
    (they are always pressed that way; half-range examples would bring them near neutral)."""
    functions = {cls.label: cls.function for cls in profile.classes}
    return [(label, amplitude) for _ in range(repetitions) for label in sorted(params.classes)
            for amplitude in ((params.feel.least_lean, 1.0) if functions[label] in FUNCTIONS else (1.0,))]


def calibrated_channel(participant: str | ParticipantParams, seed: int, post: PostProcessing | None = None,
                       profile: Profile | None = None) -> BomiChannel:
    """The paper's order: the participant performs the calibration protocol, the chain records
    it and trains the LDA with the ``bomi train`` code (``bomi.chain.train``), then the task.
    ``post`` overrides the profile's post-processing (rejection, majority vote); ``profile``
    replaces the participant's own one (an edited copy of it)."""
    params = participant if isinstance(participant, ParticipantParams) else load_participant(participant)
    profile = profile or arm_profile(params.profile)
    model = calibrated_model(params, profile, seed, post)
    return BomiChannel(VirtualParticipant(params, profile, seed), OnlineChain(model, profile), profile)


def calibrated_model(params: ParticipantParams, profile: Profile, seed: int, post: PostProcessing | None = None):
    """The participant performs the calibration protocol; its base-station stream is recorded as
    ``bomi record`` records it and the LDA trained with the ``bomi train`` code."""
    session = calibration_session(params, profile, seed, order=calibration_order(params, profile))
    return train([session_recording(session, profile)], profile, post=post)


def intended_direction(mode: Mode, intent: StickIntent, layout: Layout) -> tuple[float, float, float]:
    """Unit hand direction the person wants this tick (zero unless moving the hand in ``mode`` of
    ``layout``), on Python floats (``norm`` and the division of the combined array, bit for bit)."""
    x, y, z = combined(intent.deflection, layout.axes(mode, Kind.LINEAR))
    length = math.sqrt(x * x + y * y + z * z)
    return (x / length, y / length, z / length) if length > 0 else (x, y, z)


def operator_user(params: OperatorParams, channel: OperatorChannel, seed: int) -> ScriptedUser | HumanOperator:
    """The person at the controls: the scripted user, inside the human operator model when the
    operator file names one (``[human] model``)."""
    if params.human_model == NO_HUMAN_MODEL:
        return ScriptedUser(params, combine_axes=channel.combine_axes, memory=Memory(controls=channel.controls))
    return HumanOperator(load_human(params.human_model), params, channel.combine_axes, channel.controls, seed,
                         channel.body_reaction)


@cache
def process_arm(layout: Layout) -> ArmSim:
    """The arm of this process's episodes with joystick ``layout`` (a module constant of
    ``sim.joystick``), built once: every episode's task resets it (``ArmSim.reset``: MuJoCo's data,
    controller, joystick and counters), so an episode's record does not depend on the ones run
    before it in the process (tests/test_engine.py runs them in both orders), and a sweep's worker
    compiles the scene and the arm's kinematics once, not once per episode."""
    return ArmSim(layout=layout)


def run_episode(channel: OperatorChannel, *, operator: str, participant: str, seed: int,
                operator_file: Path | str | OperatorParams = DEFAULT_OPERATOR_FILE, task_config: TaskConfig = TaskConfig(),
                video: Path | None = None, video_speedup: float = 4.0, sim: ArmSim | None = None,
                on_tick: Callable[[float], None] | None = None, assist: frozenset[Assist] = frozenset()) -> EpisodeLog:
    """Advance the task at the control rate until success or failure; optionally film it
    (played ``video_speedup`` times faster than simulated time).  ``operator_file``: the scripted
    user's parameters, or the file they are read from. ``on_tick`` is told the simulated time
    after every tick (a progress bar). ``assist``: the assistances between the channel's stick and
    the arm (tasks.operators.assist)."""
    if not channel.controls.buttons and Assist.AUTO_MODE not in assist:
        raise BomiError(f"the controls {channel.controls.label} change mode only by the automatic mode switching: "
                        f"the scripted user needs --assist {Assist.AUTO_MODE.value}")
    sim = sim or process_arm(channel.controls.layout)
    if sim.layout is not channel.controls.layout:
        raise ValueError(f"the arm has the {sim.layout.name} joystick layout, the operator's controls the "
                         f"{channel.controls.layout.name} one")
    task = StackingTask(sim, task_config)
    task.reset(seed)
    params = operator_file if isinstance(operator_file, OperatorParams) else load_operator(operator_file)
    user = operator_user(params, channel, seed)
    supervisor = Supervisor(params.recovery, user, channel, task.target_pos) if params.recovery.actions else None
    assistance = Assistance(assist, channel.controls.layout, channel.controls.buttons) if assist else None
    seen_ticks: list[tuple[View, StickIntent]] = []  # what the person saw and wanted, tick by tick (both immutable)
    film = _Film(sim, video, video_speedup) if video is not None else None
    seen_scale, previous = sim.dt * sim.config.control.full_speed, None
    commanded: list[np.ndarray] = []  # the hand velocity each tick's stick commanded
    started, started_cpu = time.perf_counter(), time.process_time()
    try:
        while True:
            view = task.view()
            intent = user.stick_intent(view) if supervisor is None else supervisor.intent(view)
            seen = None if previous is None else (view.hand_pos - previous) / seen_scale
            previous = view.hand_pos
            state = channel.command(intent, view.t, view.t + sim.dt, seen, view.mode)
            if assistance is not None:
                state = assistance.step(view, state, sim)
            if supervisor is not None:
                state = supervisor.state(intent, state)
            seen_ticks.append((view, intent))
            commanded.append(sim.step(state).linear)
            if on_tick is not None:
                on_tick(sim.time)
            if film is not None:
                film.tick(view.t, describe(sim.mode, state, sim.layout), channel.caption(), str(intent.goal),
                          assistance.caption(view.t) if assistance is not None else None)
            outcome = task.outcome()
            if outcome.done:
                break
    finally:
        if film is not None:
            film.close()
    views, intents = zip(*seen_ticks)
    return EpisodeLog(
        operator=operator, participant=participant, seed=seed, controls=channel.controls.label,
        t=np.array([view.t for view in views]), hand_pos=np.array([view.hand_pos for view in views]),
        intended_dir=np.array([intended_direction(view.mode, intent, sim.layout) for view, intent in seen_ticks]
                              ).reshape(-1, 3),
        mode=[_MODE_VALUE[view.mode] for view in views], presses=sim.button_presses,
        cube_pos=np.array([view.cube_pos for view in views]),
        touching=np.array([view.touching for view in views], dtype=bool), target_pos=task.target_pos.copy(),
        goals=tuple(intent.goal.step for intent in intents),
        stages=tuple(_STAGE_VALUE[intent.goal.phase] for intent in intents),
        pushing=np.array([bool(intent.deflection) for intent in intents], dtype=bool),
        success=outcome.success, completion_time=outcome.completion_time, failure=outcome.failure,
        wall_time=time.perf_counter() - started, cpu_time=time.process_time() - started_cpu,
        assist=assist_label(frozenset(assist)),
        automatic=tuple(assistance.switches) if assistance is not None else (),
        grasp_helps=assistance.grasp_helps if assistance is not None else 0,
        commanded=np.array(commanded).reshape(-1, 3), recovery=params.recovery.label,
        recoveries=tuple(supervisor.events) if supervisor is not None else (), **channel.log_fields())


class _Film:
    """Every n-th control tick rendered into an MP4, with a caption (time and film speed, mode and
    stick, what the BoMI was asked and decided, the user's goal, the assistance's last switch) and a
    legend of the discs A and B."""

    def __init__(self, sim: ArmSim, path: Path, speedup: float):
        render = sim.config.render
        self.sim, self.speedup = sim, speedup
        self.every = max(1, round(speedup * sim.config.physics.control_hz / render.fps))
        self.renderer = FrameRenderer(sim.model, render.camera, render.width, render.height)
        self.writer = VideoWriter(Path(path), render.fps)
        self.legend = (("A: where the cubes start", site_colour(sim.model, "location_a", "table")),
                       ("B: the target, stack them here", site_colour(sim.model, "location_b", "table")))
        self.ticks = 0

    def tick(self, t: float, command: str, channel: str | None, goal: str, assist: str | None = None) -> None:
        if self.ticks % self.every == 0:
            lines = (f"{t:6.1f} s (film {self.speedup:g}x)  {command}", *filter(None, [channel]), f"goal: {goal}",
                     *filter(None, [assist]))
            self.writer.append(self.renderer.render(self.sim.data, lines, self.legend))
        self.ticks += 1

    def close(self) -> None:
        self.writer.close()
        self.renderer.close()
