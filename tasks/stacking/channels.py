"""How the person's stick intent reaches the arm's stick (an ``OperatorChannel``): straight
(``JoystickChannel``), or through a virtual participant's body motion and the BoMI chain
(``BomiChannel``: intent -> body motion -> base-station frames -> FrameParser -> OnlineChain ->
Decision -> joystick function with nu as deflection, a B1/B2 class pressing its button on the
rising edge).  IMU samples and control ticks share one clock."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bomi.chain import Decision, OnlineChain, train
from bomi.chain.windows import recording_neutral
from bomi.classifier import NEUTRAL_LABEL, PostProcessing
from bomi.errors import BomiError
from bomi.fusion import DT, WARMUP_S
from bomi.profiles import Profile
from bomi.recording import NodeData, Recording
from sim.kernels import clip
from sim.joystick import BUTTONS, FUNCTIONS, JoystickState, Kind, Layout, Mode
from tasks.operators.assist import Assist, profile_assist
from tasks.operators.stick import DecisionStick, arm_profile, profile_layout, rising_edge
from tasks.participants.imu_synth import Delivery
from tasks.participants.participant import (Feel, ParticipantParams, VirtualParticipant, calibration_session,
                                            load_participant, record_stream, session_recording)
from tasks.participants.receiver import Receiver
from tasks.stacking.record import DecisionTrace
from tasks.stacking.vocabulary import Controls, StickIntent


class OperatorChannel(Protocol):
    """How the person's stick intent reaches the arm's stick: straight (``JoystickChannel``) or
    through a body motion and the BoMI chain (``BomiChannel``)."""

    combine_axes: bool  # the person may push several functions at once (a 3-axis stick can)
    controls: Controls  # the layout and buttons the person has
    body_reaction: float  # s of the person's reaction the channel's body model adds after an intent

    def command(self, intent: StickIntent, t: float, t_end: float, seen: np.ndarray | None = None,
                mode: Mode = Mode.TRANSLATION) -> JoystickState:
        """The stick over the control tick [t, t_end) of task time. ``seen``: what the person saw the
        hand do since their last look (``sources.seen_velocity``: its move and its turn as fractions of
        the arm's top speeds; None on the first tick); ``mode``: the arm's mode."""

    def log_fields(self) -> dict:
        """Extra ``EpisodeLog`` fields the channel recorded (the BoMI's decisions)."""

    def begin_rezero(self) -> None:
        """Take the neutral posture anew from the samples to come (``tasks.operators.recovery``; a stick: nothing)."""

    @property
    def rezeroing(self) -> bool:
        """The neutral posture asked for is still being taken."""

    def begin_recalibration(self, t: float) -> None:
        """Perform a short calibration session from task time ``t`` and retrain on it (a stick: nothing)."""

    @property
    def recalibrating(self) -> bool:
        """The calibration session begun is still under way."""

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

    def begin_recalibration(self, t: float) -> None:
        """A stick has no classifier to retrain."""

    recalibrating = False

    def caption(self) -> None:
        """Nothing between the person and the stick to show."""
        return None


@dataclass
class LeanFeel:
    """The participant's feel for one proportional class: a wanted deflection d asks for a lean of
    zero + (most - zero) x d, within the range calibrated (``Feel.least_lean`` to ``Feel.most_lean``,
    ``most``: 1 is the class posture; a twin leans as far as its recording's holds).  ``zero`` (the
    lean at which the arm would just not move; at first the least lean) is learnt from the leans
    that worked: after correcting a move to ``lean`` for a wanted ``d``, the next move of that class
    starts from there."""

    feel: Feel
    zero: float | None = None

    def __post_init__(self) -> None:
        if self.zero is None:
            self.zero = self.feel.least_lean

    def lean_for(self, deflection: float) -> float:
        most = self.feel.most_lean
        return clip(self.zero + (most - self.zero) * deflection, self.feel.least_lean, most)

    def learn(self, lean: float, deflection: float) -> None:
        """The zero that makes ``lean_for(deflection)`` the ``lean`` that worked (at most ``max_zero`` of
        the furthest lean: the least deflection needs less than the whole range)."""
        if deflection < 1.0:
            zero = (lean - self.feel.most_lean * deflection) / (1.0 - deflection)
            self.zero = float(np.clip(zero, 0.0, self.feel.max_zero * self.feel.most_lean))

    def corrected(self, lean: float, further: bool) -> float:
        """The lean one correction of ``lean`` takes (``lean_step`` further, or less far)."""
        step = self.feel.lean_step if further else -self.feel.lean_step
        return clip(lean + step, self.feel.least_lean, self.feel.most_lean)


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


def watched_axes(layout: Layout, mode: Mode) -> dict[str, tuple[float, ...]]:
    """Per stick function of ``mode`` whose answer the person can see, its direction in
    ``sources.seen_velocity``'s (move, turn) vector: a move of the hand along its axis, or a turn about
    the vertical (the hand's heading: a tilt is not followed)."""
    axes = {function: (*map(float, axis), 0.0, 0.0, 0.0) for function, axis in layout.axes(mode, Kind.LINEAR).items()}
    axes.update({function: (0.0, 0.0, 0.0, 0.0, 0.0, float(axis[2]))
                 for function, axis in layout.axes(mode, Kind.ANGULAR).items() if abs(axis[2]) == 1.0})
    return axes


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
    From one motion into another the body goes through rest, and a motion taken up from rest starts
    a reaction time after the return has ended at the earliest (``_take_up``: the psychological
    refractory period); a lean held at its furthest for ``Feel.give_up_s`` without the arm
    answering is let go of and taken up anew (``_gives_up``).
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
        self._unanswered_since: float | None = None  # since when the furthest lean has gone unanswered
        # what _watch reads every tick, made once: per mode, the direction in ``seen`` (move, turn) each stick
        # function drives the hand along (as Python floats), and the share of a tick in the speed's smoothing
        layout = self.controls.layout
        self._watched_axes = {mode: watched_axes(layout, mode) for mode in layout.modes}
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
        self._recalibration: Recalibration | None = None  # the calibration session under way
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
        if self._recalibration is not None and self.clock_offset + t >= self._recalibration.end - 1e-9:
            self._retrain()
        if self._recalibration is None:  # (during a recalibration the participant follows its protocol's cues)
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
        if label != held and NEUTRAL_LABEL not in (label, held):
            self._take_up(NEUTRAL_LABEL, 0.0, t)   # from one motion into the next through rest
        elif label != held:
            self._take_up(label, amplitude, t)
            self._unanswered_since = None
            if label in self.feel:
                self._watched = Watched(label, amplitude, wanted)
        elif label in self.feel:
            self._watched.wanted = wanted
            if self._gives_up(label, held_amplitude, t):
                self._take_up(NEUTRAL_LABEL, 0.0, t)   # relaxes; the next look takes the posture up anew
                return
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

    def begin_recalibration(self, t: float, hold_s: float = 5.0, neutral_s: float = 5.0) -> None:
        """From task time ``t``, the participant performs the calibration protocol once
        (``calibration_order`` with one repetition, run as ``calibration_session`` runs it: each cued
        posture held ``hold_s`` once reached, ``neutral_s`` of neutral between) on their own clock;
        the recording starts with it, so its fusion first settles ``WARMUP_S`` (cut, as a session's
        warm-up is) while the participant rests at neutral.  Its frames reach the chain as they
        arrive (the arm is stopped meanwhile: the supervisor's gate) and are recorded; when the
        session ends (``recalibrating`` goes False on the first tick after it), the classifier trained on the
        recording (``bomi.chain.train``) replaces the chain's, with the recording's neutral."""
        vp, params = self.participant, self.participant.params
        settle = params.reaction_s + params.onset_s
        # the recording's first sample: the first of a counter cycle (the packet counters count
        # samples modulo 256) whose frames are all still to come
        first = 256 * (int(np.floor(max(self._asked_until, self.clock_offset + t) / DT)) // 256 + 1)
        cue = first * DT + WARMUP_S
        vp.set_intent(NEUTRAL_LABEL, 0.0, self.clock_offset + t)
        cues = [(cue, NEUTRAL_LABEL)]
        cue += neutral_s
        for label, amplitude in calibration_order(params, self.profile, repetitions=1):
            for run_label, run_amplitude, duration in ((label, amplitude, hold_s), (NEUTRAL_LABEL, 0.0, neutral_s)):
                vp.pass_time(cue)
                vp.set_intent(run_label, run_amplitude, cue)
                cues.append((cue, run_label))
                cue += settle + duration
        delivery = vp.deliveries(cue)
        self.receiver.take(delivery)
        self._asked_until = cue
        self._recalibration = Recalibration(cue, first, tuple(cues), delivery)

    @property
    def recalibrating(self) -> bool:
        return self._recalibration is not None

    def _retrain(self) -> None:
        """The recalibration's recording -> a classifier -> a chain of its own, its fusion brought up to
        date on the recording's frames and its neutral the recording's, in place of the chain."""
        recalibration, self._recalibration = self._recalibration, None
        recording = recalibration.recording(self.profile)
        chain = OnlineChain(train([recording], self.profile), self.profile)
        Receiver(chain).take(recalibration.delivery)
        nodes = chain.model.spec.nodes
        chain.set_neutral(dict(zip(nodes, recording_neutral(recording, nodes, self.profile.neutral_samples))))
        self.chain = self.receiver.chain = chain

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
        """Ask the body for ``label``'s posture at ``amplitude`` at task time ``t``.  A motion taken up
        from rest is prepared only once the return to rest has ended: the next response's selection
        waits for the previous one to be done (the psychological refractory period, Welford 1952;
        Pashler 1994's central bottleneck), so the body dwells at rest for a reaction time at least."""
        now = self.clock_offset + t
        if label != NEUTRAL_LABEL and self.participant.intent[0] == NEUTRAL_LABEL:
            now = max(now, self.participant.settled_at)
        self.participant.set_intent(label, amplitude, now)
        self._since = t

    def _gives_up(self, label: int, lean: float, t: float) -> bool:
        """The arm has not answered the class held at the furthest lean for ``Feel.give_up_s``: a person
        does not hold a lean for minutes at a machine that does not respond; they relax and try again."""
        feel = self.participant.params.feel
        if self._arm_answers(label) or lean < feel.most_lean:
            self._unanswered_since = None
            return False
        if self._unanswered_since is None:
            self._unanswered_since = t
        return t - self._unanswered_since >= feel.give_up_s

    def _arm_answers(self, label: int) -> bool:
        """Whether the arm moves for ``label`` now: the chain decided its function, deflected (what the
        person sees is the arm, not the decision: a function decided at nu 0 leaves the arm still)."""
        return self.stick.function == self._function_of[label] and self.stick.nu > 0.0

    def _watch(self, seen: np.ndarray | None, mode: Mode) -> bool:
        """Follow the arm's speed along the watched posture's direction while the arm answers that
        posture (held or already let go of); whether the person can judge it now (a move of the hand
        in ``mode``: a speed the person can see)."""
        watched = self._watched
        if watched is None or seen is None:
            return False
        function = self._function_of[watched.label]
        axis = self._watched_axes[mode].get(function)
        if axis is None:
            return False
        if self.stick.function == function:
            along = 0.0
            for v, a in zip(seen.tolist(), axis):   # np.dot's sum, in its order
                along += v * a
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
        if not self._arm_answers(label) or (judged and watched.speed < feel.too_slow * watched.wanted):
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


@dataclass(frozen=True)
class Recalibration:
    """A calibration session performed during the task (``BomiChannel.begin_recalibration``; participant time, s)."""

    end: float
    first: int  # the recording's first sample (the first of a packet counter's cycle)
    cues: tuple[tuple[float, int], ...]  # (time, class) of each cue shown
    delivery: Delivery  # every frame the session's samples sent, by the session's end

    def recording(self, profile: Profile) -> Recording:
        """The session as ``bomi record`` records it from its first cue on: every row, labelled with the
        cue on screen (the moves kept, as for the task's first calibration: ``calibrated_model``)."""
        mine = self.delivery.sample_index >= self.first
        stream = b"".join(frame for frame, keep in zip(self.delivery.frames, mine) if keep)
        full, index = record_stream(stream, profile, "recalibration")
        time = (index + self.first) * DT
        starts, classes = np.array(self.cues).T
        latest = np.searchsorted(starts - 1e-9, time, side="right") - 1
        keep = (latest >= 0) & (time < self.end)
        labels = np.where(latest >= 0, classes.astype(int)[np.maximum(latest, 0)], -1)
        nodes = {i: NodeData(d.acc[keep], d.gyro[keep], d.mag[keep], d.angles[keep]) for i, d in full.nodes.items()}
        return Recording(nodes=nodes, labels=labels[keep], time=time[keep], source=full.source)


def calibration_order(params: ParticipantParams, profile: Profile, repetitions: int = 3) -> list[tuple[int, float]]:
    """The protocol's (class, amplitude) sequence: proportional classes at both ends of the lean
    range (``Feel.least_lean``, ``Feel.most_lean``: so gamma's calibrated range spans the leans used), button classes at full range only
    (they are always pressed that way; half-range examples would bring them near neutral)."""
    functions = {cls.label: cls.function for cls in profile.classes}
    return [(label, amplitude) for _ in range(repetitions) for label in sorted(params.classes)
            for amplitude in ((params.feel.least_lean, params.feel.most_lean) if functions[label] in FUNCTIONS
                              else (1.0,))]


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
    ``bomi record`` records it (every row after the warm-up, each labelled with the cue on screen: the
    moves kept) and the LDA trained with the ``bomi train`` code (the rows before each measured
    movement onset read as the posture still held, the amplitude range from the holds)."""
    session = calibration_session(params, profile, seed, order=calibration_order(params, profile))
    return train([session_recording(session, profile, holds_only=False)], profile, post=post)

