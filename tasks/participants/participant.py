"""The BoMI operator's body: a virtual participant that turns intents into IMU base-station frames.

An intent ``(class_label, amplitude)`` set at a sim time becomes, after a reaction time, a
minimum-jerk move from the current posture to neutral + amplitude x (the class posture + this
session's and this repetition's offsets), held with slow sway and tremor; intent 0 returns to
a (freshly drawn) neutral. Each node's angle trajectory goes through ``tasks.participants.imu_synth`` to raw
sensor counts and base-station frames, with frame loss and bursty delivery. Parameters come
from ``tasks/participants/<name>.toml`` (schema: ``tasks.participants.params``; P1 is fitted by ``tasks.participants.twin``).
Every modelling assumption is listed in docs/virtual_participant.md.

The participant file is read by ``tasks.participants.params``; the body's pieces (moves, noise) are in
``tasks.participants.motion``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from itertools import chain

import numpy as np

from bomi.classifier import NEUTRAL_LABEL
from bomi.errors import BomiError
from bomi.frames import parse_stream, row_positions, sample_indices
from bomi.fusion import DT, WARMUP_S, NodeFusion
from bomi.profiles import Profile
from bomi.protocol import protocol_order
from bomi.recording import NodeData, Recording
from tasks.participants.imu_synth import Delivery, LinkModel, SensorNoise, deliver, synthesize_nodes
from tasks.participants.motion import ColouredNoise, PostureMove, Truth, sway_filter, tremor_filter
# the participant file's names, imported from here by the task, the CLI and the benchmarks
from tasks.participants.params import (PARTICIPANT_DIR, Feel, ParticipantParams, Protocol, check_against_profile,
                                       load_participant, parse_participant_text)

__all__ = ["PARTICIPANT_DIR", "CalibrationSession", "Feel", "ParticipantParams", "Protocol", "Session",
           "VirtualParticipant", "calibration_session", "check_against_profile", "load_participant",
           "parse_participant_text", "perform_runs", "protocol_session", "record_stream", "session_recording"]

SPASM_DRAW_S = 10.0           # spasm onsets are drawn this far ahead at a time


# ------------------------------------------------------------------------ the virtual participant
class Session(IntEnum):
    """Which of a day's sessions a virtual participant performs: the same person (the day's
    postures) with the session's own noise."""

    CALIBRATION = 1
    TASK = 2


class VirtualParticipant:
    """A streaming source of base-station bytes driven by intents (see the module docstring).

    ``seed`` fixes the person on that day: the day's posture offsets (``day_postures``), the same
    in every ``session``.  The seed and ``session`` together fix the rest: repetition offsets,
    sway, tremor, spasms, sensor noise, frame loss and delivery times, independent between the
    calibration and the task (separate ``numpy.random.SeedSequence`` children of the seed).
    """

    def __init__(self, params: ParticipantParams, profile: Profile, seed: int,
                 noise: SensorNoise = SensorNoise(), link: LinkModel = LinkModel(), session: Session = Session.TASK):
        check_against_profile(params, profile)
        self.params, self.profile, self.noise, self.link = params, profile, noise, link
        # child 0 of the seed: the person; child ``session``: that session's noise, one generator
        # per purpose (and per node for sensors and link), each drawn in sample order: the output
        # does not depend on how the caller slices time into advance() calls
        children = np.random.SeedSequence(seed).spawn(1 + max(Session))
        person = np.random.default_rng(children[0])
        # (the timing and evoked-spasm generators come after the others: the others' streams are those of a
        # participant without variable timing or evoked spasms, whose output is unchanged by them)
        n = len(profile.nodes)
        body, sway, tremor, spasm, *per_node, timing, evoked = (np.random.default_rng(s) for s in
                                                                children[session].spawn(6 + 2 * n))
        self._rng, self._spasm_rng, self._timing_rng, self._evoked_rng = body, spasm, timing, evoked
        self._sensor_rngs = per_node[:n]
        self._link_rngs = {node.index: rng for node, rng in zip(profile.nodes, per_node[n:])}
        channels = params.n_nodes * 3
        self._sway = ColouredNoise(*sway_filter(), channels, sway)
        self._tremor = ColouredNoise(*tremor_filter(params.tremor_spectrum), channels, tremor)
        self._day_posture = {label: np.exp(person.normal(0.0, m.day_gain_log_std)) * m.posture_deg
                             + person.normal(0.0, m.day_std_deg) for label, m in params.classes.items()}
        self._rest_offset: np.ndarray | None = None   # the last rest's offset from the neutral (_target)
        self._excursion: np.ndarray | None = None     # the class posture held now, offsets included (_target)
        rest = self._target(NEUTRAL_LABEL, 0.0)
        self._moves: list[PostureMove] = [PostureMove(0.0, params.onset_s, rest, rest, NEUTRAL_LABEL, 0.0)]
        self._starts = np.array([0.0])          # each move's t0
        n_spasm_nodes = len(params.spasm.nodes) if params.spasm else 0
        self._spasm_onsets = np.empty(0)
        self._spasm_sizes = np.empty((0, n_spasm_nodes, 3))
        self._spasm_until = 0.0                 # spasm onsets are drawn up to this time
        self._evoked: list[tuple[float, float, np.ndarray]] = []   # evoked spasms: (onset, duration, peak (nodes, 3))
        self._generated = 0                     # samples generated so far (sample k at time k * DT)
        self._passed = 0                        # samples whose time has passed (``pass_time``), made or not
        self._last_angles: np.ndarray | None = None     # (nodes, 3) angles of the last sample
        self._last_arrival: dict[int, float] = {}
        self._pending = _merge()              # generated frames in arrival order ...
        self._returned = 0                      # ... of which those before this one were returned
        self._truth: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []

    # -- intents
    def _target(self, label: int, amplitude: float) -> np.ndarray:
        """A fresh repetition's posture: the session's neutral + amplitude x (day posture + repetition offset);
        a rest's offset keeps ``rest_carry`` of the last rest's (none: drawn anew); a lean corrected within the
        class held keeps its posture, with a repetition error scaled by the correction's share of the lean."""
        neutral = self.params.neutral
        if label == NEUTRAL_LABEL:
            fresh = self._rng.normal(0.0, neutral.rep_std_deg)
            carry = self.params.rest_carry
            if carry is not None and self._rest_offset is not None:
                # a rest keeps part of the previous rest's offset (an AR(1) of the rests, whose spread
                # stays rep_std): a person returns near where they rested last (P1's five days, twin.py)
                fresh = carry * self._rest_offset + np.sqrt(1.0 - carry ** 2) * fresh
            self._rest_offset = fresh
            return neutral.posture_deg + fresh
        error = self._rng.normal(0.0, self.params.classes[label].rep_std_deg)
        held_label, held_amplitude = self.intent
        if held_label == label and min(held_amplitude, amplitude) > 0.0 and self._excursion is not None:
            # a correction of the lean held: the posture kept, an error in proportion to how far the
            # correction moves (signal-dependent motor noise: Harris & Wolpert 1998; Schmidt et al. 1979)
            excursion = self._excursion + error * abs(amplitude - held_amplitude) / amplitude
        else:
            excursion = self._day_posture[label] + error
        self._excursion = excursion
        return neutral.posture_deg + amplitude * self.params.max_amplitude * excursion

    @property
    def day_postures(self) -> dict[int, np.ndarray]:
        """The day's posture of each class, (nodes, 3) degrees: the person, shared by the sessions of a seed."""
        return {label: posture.copy() for label, posture in self._day_posture.items()}

    @property
    def spasm_onsets(self) -> np.ndarray:
        """Onset times (s) of the spasm bursts drawn so far."""
        return self._spasm_onsets.copy()

    @property
    def time_s(self) -> float:
        """Sim time up to which samples are made (or passed: ``pass_time``)."""
        return max(self._generated, self._passed) * DT

    def pass_time(self, t_end: float) -> None:
        """Let sim time pass to ``t_end`` without making its samples yet: an intent set from now on
        acts after them, exactly as if ``deliveries(t_end)`` had been called, and the next call that
        makes samples makes them all in one pass (a whole protocol: one synthesis, not one per cue)."""
        self._passed = max(self._passed, _samples_until(t_end))

    @property
    def moves(self) -> tuple[PostureMove, ...]:
        """Every move so far, the first the initial (still) posture."""
        return tuple(self._moves)

    @property
    def intent(self) -> tuple[int, float]:
        return self._moves[-1].label, self._moves[-1].amplitude

    @property
    def settled_at(self) -> float:
        """Sim time at which the latest move ends (the posture asked for last is reached)."""
        last = self._moves[-1]
        return last.t0 + last.duration

    def set_intent(self, label: int, amplitude: float, t: float) -> float | None:
        """From sim time ``t``: move (after the reaction time) to ``label``'s posture at ``amplitude`` in [0, 1]
        (up to ``Feel.most_lean``);
        the time the move ends (the posture reached).

        Setting the intent already in force does nothing (the posture is held) and returns None.
        """
        if label != NEUTRAL_LABEL and label not in self.params.classes:
            raise ValueError(f"participant {self.params.name} has no class {label}")
        most = max(1.0, self.params.feel.most_lean)
        if not 0.0 <= amplitude <= most:
            raise ValueError(f"amplitude must be in [0, {most:g}], got {amplitude}")
        if (label, amplitude) == self.intent or (label == NEUTRAL_LABEL and self.intent[0] == NEUTRAL_LABEL):
            return None
        params = self.params
        reaction = self._varied(params.reaction_s, params.reaction_sd_s)
        duration = self._varied(params.onset_s, params.onset_sd_s)
        t0 = max(t + reaction, self.time_s, self._moves[-1].t0)
        t = np.array([t0])
        start = self._moves[self._move_index(t)[0]].at(t)[0]
        target = self._target(label, amplitude)
        self._moves.append(PostureMove(t0, duration, start, target, label, amplitude))
        self._starts = np.append(self._starts, t0)
        evoked = params.evoked_spasm
        if evoked is not None and label in evoked.classes and self._evoked_rng.uniform() < evoked.probability:
            length, share = self._evoked_rng.uniform(*evoked.duration_s), self._evoked_rng.uniform(*evoked.undo_share)
            self._evoked.append((t0 + duration, length, -share * (target - start)))
        return t0 + duration

    def _varied(self, mean: float, sd: float) -> float:
        """A reaction time or a move's duration: ``mean`` itself when ``sd`` is 0, else a gamma draw of that
        mean and SD (positive and skewed to the slow side, as reaction times are)."""
        if sd == 0.0 or mean == 0.0:
            return mean
        return float(self._timing_rng.gamma((mean / sd) ** 2, sd ** 2 / mean))

    def _move_index(self, t: np.ndarray) -> np.ndarray:
        """Index of the move in force at each time of ``t``."""
        return np.maximum(np.searchsorted(self._starts, t, side="right") - 1, 0)

    def _holding(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """At the increasing times ``t``: the deliberate posture (no sway/tremor/spasm), the std of the sway and
        of the tremor while holding (each blended from the old to the new class over each move), all
        (n, nodes, 3), and the intent's (n,) label and amplitude; one pass per move in force."""
        posture, sway, tremor = np.empty((3, len(t), self.params.n_nodes, 3))
        label, amplitude = np.empty(len(t), dtype=int), np.empty(len(t))
        which = self._move_index(t)
        cuts = [] if which[0] == which[-1] else (np.flatnonzero(which[1:] != which[:-1]) + 1).tolist()  # (which rises)
        for first, end in zip([0, *cuts], [*cuts, len(t)]):
            k, rows = int(which[first]), slice(first, end)
            move = self._moves[k]
            old, new = self.params.motion(self._moves[max(k - 1, 0)].label), self.params.motion(move.label)
            label[rows], amplitude[rows] = move.label, move.amplitude
            if (t[first] - move.t0) / move.duration >= 1.0:   # the move done: progress 1.0 from here on (t rises)
                posture[rows], sway[rows], tremor[rows] = move.done, new.sway_std_deg, new.tremor_std_deg
                continue                                      # (the blend's bits at 1.0: 0 * old + new)
            progress = move.progress(t[rows])
            posture[rows] = move.posture(progress)
            blend = progress[:, None, None]
            sway[rows] = (1 - blend) * old.sway_std_deg[None] + blend * new.sway_std_deg[None]
            tremor[rows] = (1 - blend) * old.tremor_std_deg[None] + blend * new.tremor_std_deg[None]
        return posture, sway, tremor, label, amplitude

    def _spasms(self, t: np.ndarray) -> np.ndarray:
        """Spasms over the samples at ``t``, (n, nodes, 3): the background bursts and those set off by moves."""
        out = self._bursts(t)
        beat_hz = self.params.evoked_spasm.beat_hz if self.params.evoked_spasm else 0.0
        for onset, duration, peak in self._evoked:
            if onset <= t[-1] and onset + duration >= t[0]:
                phase = (t - onset) / duration
                active = (phase >= 0) & (phase <= 1)
                course = raised_cosine(phase[active])
                if beat_hz > 0:   # clonic: full beats at beat_hz within the spasm's course
                    course = course * raised_cosine(beat_hz * (t[active] - onset))
                out[active] += course[:, None, None] * peak[None]
        return out

    def _bursts(self, t: np.ndarray) -> np.ndarray:
        """The background spasm bursts over the samples at ``t``, (n, nodes, 3)."""
        out = np.zeros((len(t), self.params.n_nodes, 3))
        spasm = self.params.spasm
        if spasm is None or spasm.rate_per_s == 0 or len(t) == 0:
            return out
        while self._spasm_until < t[-1]:
            n_new = self._spasm_rng.poisson(spasm.rate_per_s * SPASM_DRAW_S)
            onsets = np.sort(self._spasm_rng.uniform(self._spasm_until, self._spasm_until + SPASM_DRAW_S, n_new))
            size = self._spasm_rng.uniform(-1.0, 1.0, (n_new, len(spasm.nodes), 3))
            size *= spasm.max_deg / np.maximum(np.abs(size).max(axis=(1, 2), keepdims=True), 1e-9)
            size *= self._spasm_rng.uniform(0.3, 1.0, (n_new, 1, 1))
            self._spasm_onsets = np.concatenate([self._spasm_onsets, onsets])
            self._spasm_sizes = np.concatenate([self._spasm_sizes, size])
            self._spasm_until += SPASM_DRAW_S
        nodes = np.array(spasm.nodes) - 1
        recent = slice(np.searchsorted(self._spasm_onsets, t[0] - spasm.duration_s),
                       np.searchsorted(self._spasm_onsets, t[-1], side="right"))
        for onset, size in zip(self._spasm_onsets[recent], self._spasm_sizes[recent]):
            phase = (t - onset) / spasm.duration_s
            active = (phase >= 0) & (phase <= 1)
            if active.any():
                out[np.ix_(np.flatnonzero(active), nodes)] += raised_cosine(phase[active])[:, None, None] * size[None]
        return out

    # -- output
    def _generate(self, t_end: float) -> None:
        n_total = max(_samples_until(t_end), self._passed)
        n = n_total - self._generated
        if n <= 0:
            return
        index = np.arange(self._generated, n_total)
        t = index * DT
        shape = (n, self.params.n_nodes, 3)
        posture, sway, tremor, label, amplitude = self._holding(t)
        angles = (posture + self._sway.next(n).reshape(shape) * sway
                  + self._tremor.next(n).reshape(shape) * tremor + self._spasms(t))
        raws = synthesize_nodes(angles, [node.calibration for node in self.profile.nodes], self._sensor_rngs,
                                self.noise, previous_deg=self._last_angles)
        self._last_angles = angles[-1]
        raw = {node.index: r for node, r in zip(self.profile.nodes, raws)}
        fresh = deliver(raw, index, t, self._link_rngs, self.link, not_before_s=self._last_arrival)
        backwards = fresh.node_index[::-1]   # in arrival order: a node's last frame is its latest
        for node in self._link_rngs:
            mine = backwards == node
            if mine.any():
                self._last_arrival[node] = float(fresh.arrival_s[len(mine) - 1 - int(mine.argmax())])
        self._pending, self._returned = _merge(self._pending.rows(self._returned), fresh), 0
        self._truth.append((t, label, amplitude, angles))
        self._generated = n_total

    def deliveries(self, t_end: float) -> Delivery:
        """The frames that reach the host by sim time ``t_end`` (and were not returned before)."""
        self._generate(t_end)
        # the pending frames from ``_returned`` on have not been returned: a cursor, not a split of the rest every call
        start = self._returned
        self._returned = max(int(np.searchsorted(self._pending.arrival_s, t_end, side="right")), start)
        return self._pending.rows(start, self._returned)

    def advance(self, t_end: float) -> bytes:
        """The base-station bytes that arrive by sim time ``t_end`` (and were not returned before)."""
        return self.deliveries(t_end).stream()

    def flush(self) -> Delivery:
        """Every frame generated but not yet returned, whatever its arrival time (end of a session)."""
        rest = self._pending.rows(self._returned)
        self._pending, self._returned = _merge(), 0
        return rest

    def truth(self) -> Truth:
        """Ground truth of every sample generated so far (the body's intent and angles, not the chain's)."""
        if not self._truth:
            return Truth(np.empty(0), np.empty(0, int), np.empty(0), np.empty((0, self.params.n_nodes, 3)))
        t, label, amp, angles = (np.concatenate(parts) for parts in zip(*self._truth))
        return Truth(t, label, amp, angles)


def raised_cosine(phase: np.ndarray) -> np.ndarray:
    """A spasm's course over its duration (phase 0 to 1): 0, up to 1 at the middle, back to 0."""
    return 0.5 * (1 - np.cos(2 * np.pi * phase))


def _samples_until(t_end: float) -> int:
    """How many samples (sample k at time k * DT) are taken by sim time ``t_end``."""
    return math.floor(t_end / DT + 1e-9) + 1


def _merge(*parts: Delivery) -> Delivery:
    """Deliveries in one arrival order (stable: earlier parts first on ties); no parts: nothing."""
    parts = tuple(part for part in parts if part.frames)
    if len(parts) < 2:   # nothing to merge (an empty delivery, or the one part as it is)
        return parts[0] if parts else Delivery(np.empty(0), np.empty(0, int), np.empty(0, int), [])
    arrival = np.concatenate([p.arrival_s for p in parts])
    node, sample = (np.concatenate([getattr(p, name) for p in parts]) for name in ("node_index", "sample_index"))
    frames = list(chain.from_iterable(p.frames for p in parts))
    if (arrival[1:] >= arrival[:-1]).all():   # in order already (the stable sort would keep it so)
        return Delivery(arrival, node, sample, frames)
    order = np.argsort(arrival, kind="stable")
    return Delivery(arrival[order], node[order], sample[order], [frames[i] for i in order])


# ------------------------------------------------------------------------- calibration protocol
@dataclass(frozen=True)
class CalibrationSession:
    """The paper's calibration protocol performed by a virtual participant.

    Per generated sample (n,): ``cue`` is the class asked for (0 between motions), ``holding``
    is True while the cued posture is reached and held (the published recordings keep only
    these samples), ``recorded`` is False during the warm-up that lets the fusion settle.
    ``delivery`` is every frame the base station sent, in arrival order; ``moves`` the true
    timing of each move the cues set off.
    """

    participant: str
    seed: int
    delivery: Delivery
    truth: Truth
    cue: np.ndarray
    holding: np.ndarray
    recorded: np.ndarray
    moves: np.ndarray    # (cues that moved the body, 3): the cue's time, the move's start and its end (s)


def calibration_session(params: ParticipantParams, profile: Profile, seed: int, repetitions: int = 3,
                        hold_s: float = 5.0, neutral_s: float = 5.0, amplitudes: Sequence[float] = (1.0,),
                        order: Sequence[tuple[int, float]] | None = None, warmup_s: float = WARMUP_S,
                        noise: SensorNoise = SensorNoise(), link: LinkModel = LinkModel(),
                        session: Session = Session.CALIBRATION) -> CalibrationSession:
    """Run the protocol: neutral, then each cued motion held ``hold_s`` with ``neutral_s`` of neutral between;
    ``session``: which of the seed's day's sessions (``Session.TASK``: a second recording of the same day).

    The participant needs ``reaction_s + onset_s`` after each cue to reach the posture; the
    hold (and the neutral) lasts ``hold_s`` (``neutral_s``) from then. ``order`` overrides the
    default (label, amplitude) sequence.
    """
    motions = list(order) if order is not None else protocol_order(sorted(params.classes), repetitions, amplitudes)
    runs = [(NEUTRAL_LABEL, 0.0, neutral_s)]
    for label, amplitude in motions:
        runs += [(label, amplitude, hold_s), (NEUTRAL_LABEL, 0.0, neutral_s)]
    return perform_runs(params, profile, seed, runs, warmup_s, noise, link, session)


def protocol_session(params: ParticipantParams, profile: Profile, seed: int, protocol: Protocol,
                     warmup_s: float = WARMUP_S) -> CalibrationSession:
    """A recording's protocol performed: the same runs, each as long as it was recorded. In a
    holds-only recording a run is the hold; in a continuous one it also holds the participant's
    move after the cue (``reaction_s + onset_s``), so the hold is that much shorter."""
    settle = 0.0 if protocol.holds_only else params.reaction_s + params.onset_s
    runs = [(label, 0.0 if label == NEUTRAL_LABEL else 1.0, max(duration - (settle if k else 0.0), DT))
            for k, (label, duration) in enumerate(zip(protocol.labels, protocol.durations_s))]
    return perform_runs(params, profile, seed, runs, warmup_s)


def perform_runs(params: ParticipantParams, profile: Profile, seed: int, runs: Sequence[tuple[int, float, float]],
                 warmup_s: float = WARMUP_S, noise: SensorNoise = SensorNoise(), link: LinkModel = LinkModel(),
                 session: Session = Session.CALIBRATION) -> CalibrationSession:
    """Runs of (class, amplitude, hold s): the first held from the end of the warm-up, each next one
    cued when the previous hold ends and held ``hold`` s once reached (``reaction_s + onset_s`` after the cue)."""
    vp = VirtualParticipant(params, profile, seed, noise, link, session)
    settle = params.reaction_s + params.onset_s
    (first, first_amp, first_s), *rest = runs
    cues: list[tuple[float, int]] = [(0.0, first)]
    if first != NEUTRAL_LABEL:
        vp.set_intent(first, first_amp, 0.0)
    holds: list[tuple[float, float, int]] = [(warmup_s, warmup_s + first_s, first)]
    moves: list[tuple[float, float, float]] = []
    t = warmup_s + first_s
    for cue_label, cue_amp, duration in rest:
        vp.pass_time(t)
        reached = vp.set_intent(cue_label, cue_amp, t)
        cues.append((t, cue_label))
        begin, end = t + settle, t + settle + duration
        if reached is not None:
            moves.append((t, vp.moves[-1].t0, reached))
            if reached > begin + 1e-9:   # a slow draw of a variable timing: the hold starts once it is reached
                begin = min(reached, end)
        holds.append((begin, end, cue_label))
        t += settle + duration
    delivery = _merge(vp.deliveries(t), vp.flush())   # the whole session synthesised in one pass
    truth = vp.truth()
    keep = np.arange(len(truth.time_s)) <= int(np.floor(t / DT + 1e-9))   # the samples up to t, as generated
    truth = Truth(truth.time_s[keep], truth.intent[keep], truth.amplitude[keep], truth.angles[keep])
    # each sample's latest cue, and the latest hold begun by then (the holds follow one another,
    # each ``settle`` after the previous one's end): one search over the samples, not a pass per cue
    starts, labels = np.array(cues).T
    latest = np.searchsorted(starts, truth.time_s, side="right") - 1
    cue = np.where(latest >= 0, labels.astype(int)[latest], NEUTRAL_LABEL)
    begun, ends = np.array([hold[:2] for hold in holds]).T
    latest = np.searchsorted(begun, truth.time_s, side="right") - 1
    holding = (latest >= 0) & (truth.time_s < ends[latest])
    return CalibrationSession(params.name, seed, delivery, truth, cue, holding, truth.time_s >= warmup_s,
                              np.array(moves).reshape(-1, 3))


# ------------------------------------------------------------------------------ recording it
def record_stream(stream: bytes, profile: Profile, source: str) -> tuple[Recording, np.ndarray]:
    """Parse base-station bytes into fused rows exactly as ``bomi record`` does; also each row's sample index.

    The whole stream at once, by the batch forms of the live steps: the frames a ``FrameParser``
    delivers (``parse_stream``), rows as ``RowAssembler`` pairs them by arrival, a lost frame's
    node repeating its previous sample (``row_positions``), each frame in a row fused once, in
    order, by the node's ``NodeFusion`` (``update_many``: the frames before a node's first row are
    never fused, as ``FusedRows`` never sees them). The sample index of a row (to label it) is that
    of its newest frame, from the unwrapped packet counters (``sample_indices``).
    """
    ids = tuple(node.node_id for node in profile.nodes)
    frames = parse_stream(stream)
    frames = frames[np.isin(frames["node_id"], ids)]
    rows = row_positions(frames["node_id"], ids)
    if not len(rows):
        raise BomiError(f"{source}: no complete row of nodes {list(profile.node_indices)} in the stream")
    nodes = {}
    for k, node in enumerate(profile.nodes):
        used, row_frame = np.unique(rows[:, k], return_inverse=True)   # each frame once, in arrival order
        mine = frames[used]
        acc, gyro, mag = (mine[name].astype(float) for name in ("acc", "gyro", "mag"))
        angles = NodeFusion(node.calibration).update_many(acc, gyro, mag)
        nodes[node.index] = NodeData(acc[row_frame], gyro[row_frame], mag[row_frame], angles[row_frame])
    indices = sample_indices(frames["node_id"], frames["counter"])[rows].max(axis=1)
    return Recording(nodes=nodes, labels=None, time=indices * DT, source=source), indices


def session_recording(session: CalibrationSession, profile: Profile, holds_only: bool = True) -> Recording:
    """The session as ``bomi record`` would record it, labelled with the cue; warm-up cut.

    ``holds_only`` keeps just the held postures, like the published (post-processed) recordings;
    otherwise every row after the warm-up is kept, transitions labelled with their cue.
    """
    source = f"virtual {session.participant} (seed {session.seed})"
    full, index = record_stream(session.delivery.stream(), profile, source)
    keep = session.recorded[index] & (session.holding[index] if holds_only else True)
    nodes = {i: NodeData(d.acc[keep], d.gyro[keep], d.mag[keep], d.angles[keep]) for i, d in full.nodes.items()}
    return Recording(nodes=nodes, labels=session.cue[index][keep], time=full.time[keep], source=source)
