"""The BoMI chain, batch (training, evaluation) and streaming (live and simulated runs).

Both forms share every stage: node states -> ``component_index`` -> windows -> ``features`` ->
``posteriors`` -> post-processing -> class, joystick function, proportional output nu.
Node state = neutral-subtracted (pitch, roll, yaw) + gyroscope as the recording holds it (raw LSB).

A new person's settings (``select_settings``, when a profile leaves them to "select") follow one
rule: the plain LDA (no shrinkage, no copies, no rejection) unless the person's own cross-validation
(whole holds held out) shows an extra's gain to be both large (REQUIRED_GAIN, 2 points) and steady
over the held-out holds (the simplest option within CONSISTENCY, 2, standard errors of the best,
``choose_option``), one extra at a time: shrinkage, then the smaller copies, then rejection. A
within-pass CV cannot see the drift to the next recording; gains made on a few holds did not carry to
it on development people (benchmarks/new_people_candidates.py, docs/signal_chain.md). ``bomi train``
and ``bomi evaluate`` print what was chosen, the gain and its standard error.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from operator import itemgetter

import numpy as np
from scipy.linalg import hadamard

from bomi.classifier import (NEUTRAL_LABEL, MajorityVote, Model, PostProcessing, amplitude_ranges, classify_windows,
                             fit_pipeline, model_defects, pipeline_parameters, posteriors, proportional, reject,
                             sample_amplitude, single_threaded_blas)
from bomi.errors import BomiError
from bomi.features import (NODE_STATE, FeatureSpec, WindowBuffer, feature_columns, features, run_edges,
                           single_label_windows, window_ends)
from bomi.features import window_features as batch_window_features
from bomi.frames import ImuFrame, imu_index
from bomi.fusion import NodeFusion, load_filter, neutral_offsets
from bomi.neutral import rest_spread
from bomi.passes import training_digests
from bomi.profiles import SELECT, Profile
from bomi.recording import Recording, Signal

_WIDTH = len(NODE_STATE)


# ----------------------------------------------------------------------------------------- batch
def spec_signals(spec: FeatureSpec) -> tuple[Signal, ...]:
    """The signals of every node a feature vector uses: FV1 the angles, FV2/FV3 the gyroscope too."""
    return (Signal.ANGLES,) if spec.kind == "FV1" else (Signal.ANGLES, Signal.GYRO)


def require_for(rec: Recording, spec: FeatureSpec) -> None:
    """One-line BomiError unless ``rec`` holds what a ``spec`` model reads."""
    rec.require(spec.nodes, spec_signals(spec), f"a {spec.kind} model")


def recording_neutral(rec: Recording, nodes: Sequence[int], samples: int) -> np.ndarray:
    """(len(nodes), 3) neutral offsets: mean angles of each node over the first ``samples`` rows."""
    rec.require(nodes, (Signal.ANGLES,), "the neutral-offset calibration")
    return np.stack([neutral_offsets(rec.nodes[i].angles, samples) for i in nodes])


def node_states(rec: Recording, nodes: Sequence[int], neutral: np.ndarray) -> np.ndarray:
    """(n, len(nodes) * 6): per node, angles minus its neutral offset, then the gyroscope (NaN when the
    recording has none: only FV1, which does not read it, accepts such a recording)."""
    rec.require(nodes, (Signal.ANGLES,), "the node states")
    nan = np.full((len(rec), 3), np.nan)
    return np.hstack([np.hstack([rec.nodes[i].angles - neutral[k], nan if rec.nodes[i].gyro is None else rec.nodes[i].gyro])
                      for k, i in enumerate(nodes)])


def window_features(states: np.ndarray, spec: FeatureSpec, select: np.ndarray | None = None) -> np.ndarray:
    """Features of every window (time order) of the node-state sequence (``select``: of the windows it keeps)."""
    return batch_window_features(states[:, spec.components], spec.kind, spec.window, spec.stride, select)


@dataclass
class PreparedRecording:
    """A recording cut into windows for one feature spec."""

    features: np.ndarray     # (m, F), every window in time order
    ends: np.ndarray         # (m,) index of each window's last sample
    states: np.ndarray       # (n, nodes * 6)
    labels: np.ndarray | None  # (m,) label of each window's last sample
    pure: np.ndarray | None    # (m,) window lies inside one label segment


def prepare(rec: Recording, spec: FeatureSpec, neutral_samples: int) -> PreparedRecording:
    require_for(rec, spec)
    if len(rec) < spec.window:
        raise BomiError(f"{rec.source}: {len(rec)} samples, shorter than one {spec.window}-sample window")
    states = node_states(rec, spec.nodes, recording_neutral(rec, spec.nodes, neutral_samples))
    ends = window_ends(len(rec), spec.window, spec.stride)
    labels = pure = None
    if rec.labels is not None:
        labels = rec.labels[ends]
        pure = single_label_windows(rec.labels, spec.window, spec.stride)
    return PreparedRecording(window_features(states, spec), ends, states, labels, pure)


@dataclass
class TrainingWindows:
    """The single-label windows of one recording (and the synthesised copies of its motions) to fit on."""

    features: np.ndarray     # (m, F)
    labels: np.ndarray       # (m,)
    ends: np.ndarray         # (m,) last sample of each window in the recording (a copy shares its original's)
    recorded: np.ndarray     # (m,) True for the recorded windows, False for the synthesised copies


def recorded_priors(labels: np.ndarray, recorded: np.ndarray) -> np.ndarray | None:
    """Class priors (sorted label order) from the recorded windows alone: a synthesised copy of a motion
    is another example of it, not a sign that the motion is more frequent, so the copies must not
    lower the prior of the neutral posture (which is never copied). None without copies: the class
    frequencies, scikit-learn's default (``fit_pipeline`` then fits plain LDA)."""
    if recorded.all():
        return None
    classes = np.unique(labels)
    counts = np.array([np.count_nonzero(labels[recorded] == c) for c in classes], dtype=float)
    return counts / counts.sum()


@dataclass(frozen=True)
class MotionCopies:
    """The synthesised training copies of the recorded motions (a profile's ``[classifier]`` options).

    ``scales``: every motion again at these fractions of its size. ``spread_degrees``: the motions of
    ``spread_nodes`` (class -> carrying node) again with their angle changes on that node turned by
    +-spread about each of the two axes perpendicular to the class's mean direction.
    ``rest_offsets``: every single-label window (the neutral posture's too) once more, measured from
    another rest (``rest_offsets``, below): training sees how far the person's reference moves
    between sessions. Each window copied once, so training takes about twice as long, not K times.
    """

    scales: tuple[float, ...] = ()
    spread_degrees: float = 0.0
    spread_nodes: Mapping[int, int] = field(default_factory=dict)
    rest_offsets: bool = False

    @classmethod
    def of(cls, profile: Profile) -> MotionCopies:
        return cls(profile.amplitude_scales, profile.direction_spread,
                   profile.lone_class_nodes if profile.direction_spread else {}, profile.rest_offsets)


def rest_offsets(labels: np.ndarray, angles: np.ndarray) -> np.ndarray | None:
    """(K, k) offsets of the (n, k) neutral-subtracted ``angles``: how far the reference of another
    session may lie from this recording's, in K balanced, uncorrelated +-steps.

    Motions are measured from the one rest the session calibrated on; a person never comes back to
    quite the same rest (bomi/neutral.py), so between the training's reference and a later
    session's lies the difference of two rests: on each angle a spread of sqrt(2) times the
    person's own rest-to-rest standard deviation, measured here on the rests of the recording.
    The offsets are the columns 1..k of a Hadamard matrix of order K (the smallest power of two above
    k) scaled by that spread: over the K rows every angle moves by exactly +-the spread, each mean
    zero and uncorrelated with the others, so copies taking the rows in turn (``training_windows``:
    window j the row j mod K) add that variance, and no more, to every class and no mean shift.
    None when the recording has fewer than three rests. Nothing here is tuned: the spread is the
    person's, the factor the difference of two rests."""
    spread = rest_spread(labels, angles)
    if spread is None:
        return None
    order = 1 << int(np.ceil(np.log2(len(spread) + 1)))
    return hadamard(order)[:, 1:len(spread) + 1] * (np.sqrt(2.0) * spread)


def rotated_about(vectors: np.ndarray, axis: np.ndarray, radians: float) -> np.ndarray:
    """(n, 3) vectors turned by ``radians`` about the unit ``axis`` (Rodrigues' formula)."""
    c, s = np.cos(radians), np.sin(radians)
    return vectors * c + np.cross(axis, vectors) * s + np.outer(vectors @ axis, axis) * (1.0 - c)


def _spread_angles(states: np.ndarray, labels: np.ndarray, slot: int, radians: float) -> list[np.ndarray]:
    """Copies of node ``slot``'s (n, 3) angles in ``states`` with those of the samples labelled by the
    class turned by +-radians about the two axes perpendicular to the class's mean angle change."""
    angles = states[:, slot * _WIDTH:slot * _WIDTH + 3]
    direction = angles[labels].mean(axis=0)
    direction /= np.linalg.norm(direction)
    perpendicular = np.linalg.svd(direction[None])[2][1:]   # two unit axes orthogonal to it and to each other
    copies = []
    for axis in perpendicular:
        for sign in (1.0, -1.0):
            turned = angles.copy()
            turned[labels] = rotated_about(angles[labels], axis, sign * radians)
            copies.append(turned)
    return copies


def _with_states(prepared: PreparedRecording, spec: FeatureSpec, columns: np.ndarray, values: np.ndarray,
                 windows: np.ndarray) -> np.ndarray:
    """The features of the ``windows`` (mask) of ``prepared``'s states with the state ``columns``
    replaced by (n, len(columns)) ``values``: the recorded windows' features, the columns those
    components make recomputed (each column is computed from its own component alone: the same bits
    as computing every column of the changed states, tests/test_new_person.py)."""
    position = {int(column): k for k, column in enumerate(columns)}
    which = np.flatnonzero(np.isin(spec.components, columns))   # the changed states among the components
    source = [position[int(column)] for column in spec.components[which]]
    out = prepared.features[windows]
    out[:, feature_columns(spec.kind, len(spec.components), which)] = batch_window_features(
        values[:, source], spec.kind, spec.window, spec.stride, windows)
    return out


def training_windows(rec: Recording, spec: FeatureSpec, neutral_samples: int,
                     copies: MotionCopies = MotionCopies()) -> tuple[TrainingWindows, PreparedRecording]:
    """Single-label windows, plus the ``copies`` of the motion windows.

    A smaller copy of a motion scales every node's neutral-subtracted angles and gyroscope over the
    motion's samples by the factor (the same motion made smaller: the paper's multiple-amplitude
    training); a turned copy turns the carrying node's angle change about the neutral posture (the
    same motion made in a somewhat other direction; the gyroscope, whose axes are not the angles',
    is left as recorded). Features are computed as for a recorded window. Neutral windows are not
    copied so; the rest-offset copies (``MotionCopies.rest_offsets``) take every single-label window.
    """
    prepared = prepare(rec, spec, neutral_samples)
    pure = prepared.pure
    parts = [(prepared.features[pure], prepared.labels[pure], prepared.ends[pure], True)]
    motion_samples = rec.labels != NEUTRAL_LABEL
    motion_windows = pure & (prepared.labels != NEUTRAL_LABEL)
    for scale in copies.scales:
        states = prepared.states.copy()
        states[motion_samples] *= scale
        parts.append((window_features(states, spec, motion_windows), prepared.labels[motion_windows],
                      prepared.ends[motion_windows], False))
    if copies.rest_offsets:
        angle_columns = np.array([slot * _WIDTH + axis for slot in range(len(spec.nodes)) for axis in range(3)])
        angles = prepared.states[:, angle_columns]
        offsets = rest_offsets(rec.labels, angles)
        turn = np.arange(len(pure))   # window k takes offset k mod K: each window copied once, the offsets
        for k, offset in enumerate(() if offsets is None else offsets):   # balanced within every hold
            mine = pure & (turn % len(offsets) == k)
            parts.append((_with_states(prepared, spec, angle_columns, angles + offset, mine), prepared.labels[mine],
                          prepared.ends[mine], False))
    for label, node in copies.spread_nodes.items():
        samples, windows = rec.labels == label, pure & (prepared.labels == label)
        if not samples.any():
            continue
        slot = spec.nodes.index(node)
        for angles in _spread_angles(prepared.states, samples, slot, np.radians(copies.spread_degrees)):
            parts.append((_with_states(prepared, spec, slot * _WIDTH + np.arange(3), angles, windows),
                          prepared.labels[windows],
                          prepared.ends[windows], False))
    windows = TrainingWindows(*(np.concatenate([part[k] for part in parts]) for k in range(3)),
                              np.concatenate([np.full(len(part[1]), part[3]) for part in parts]))
    return windows, prepared


MIN_CLASS_WINDOWS = 15   # single-label windows a class needs to be learnt (a quarter of a second of holding)


def check_training_data(recordings: Sequence[Recording], profile: Profile, spec: FeatureSpec,
                        allow_missing_classes: bool = False) -> None:
    """One-line BomiError, before any fitting, when the recordings cannot train ``profile``'s model:
    a label the profile lacks, fewer than three classes, a class of the profile missing (unless
    ``allow_missing_classes``: the model then never decides it) or held for fewer than
    MIN_CLASS_WINDOWS windows, or a signal the features read that never changes."""
    known = {cls.label: cls for cls in profile.classes}
    sources = ", ".join(rec.source for rec in recordings)
    counts: dict[int, int] = {}
    for rec in recordings:
        labels = rec.require_labels()
        unknown = sorted(set(labels.tolist()) - set(known))
        if unknown:
            raise BomiError(f"{rec.source}: label(s) {unknown} are not classes of profile {profile.name}")
        require_for(rec, spec)
        if len(rec) < spec.window:
            raise BomiError(f"{rec.source}: {len(rec)} samples, shorter than one {spec.window}-sample window")
        pure = single_label_windows(labels, spec.window, spec.stride)
        ends = window_ends(len(rec), spec.window, spec.stride)[pure]
        for label, n in zip(*np.unique(labels[ends], return_counts=True)):
            counts[int(label)] = counts.get(int(label), 0) + int(n)
        _check_signals_change(rec, spec)
    if len(counts) < 3:
        raise BomiError(f"{sources}: training needs windows of at least three classes held for {spec.window} "
                        f"samples each, found {sorted(counts) or 'none'}")
    for label, cls in sorted(known.items()):
        if allow_missing_classes and label not in counts:
            continue
        if counts.get(label, 0) < MIN_CLASS_WINDOWS:
            held = "is missing from" if label not in counts else f"has only {counts[label]} {spec.window}-sample windows in"
            raise BomiError(f"{sources}: class c{label} ({cls.name}) of profile {profile.name} {held} the "
                            f"recording(s); it needs at least {MIN_CLASS_WINDOWS} (record it, leave it out of the "
                            f"profile, or train without it with --allow-missing-classes)")


def _check_signals_change(rec: Recording, spec: FeatureSpec) -> None:
    """BomiError naming the node and signal when a component the features read is constant."""
    names = ("pitch", "roll", "yaw")
    for node in spec.nodes:
        data = rec.nodes[node]
        series = [(f"angles ({names[k]})", data.angles[:, k]) for k in range(3)]
        if spec.kind != "FV1":
            series += [(f"GYRO {axis}", data.gyro[:, k]) for k, axis in enumerate("xyz")]
        for what, values in series:
            if len(values) and np.all(values == values[0]):
                raise BomiError(f"{rec.source}: node {node} {what} is constant ({values[0]:g}) over the whole "
                                "recording: nothing to learn from it (a dead or unplugged sensor?)")


def train(recordings: Sequence[Recording], profile: Profile, spec: FeatureSpec | None = None,
          shrinkage: float | str | None = ..., post: PostProcessing | None = None,
          selection: Selection | None = None, allow_missing_classes: bool = False) -> Model:
    """Fit the classifier on the single-label windows of every recording (each with its own neutral offsets).

    ``spec``, ``shrinkage`` and ``post`` default to the profile's; what the profile leaves to
    ``select_settings`` ("select": the shrinkage, then also the smaller copies of the motions, and
    the rejection threshold) comes from ``selection``, or is chosen here on ``recordings``.
    ``allow_missing_classes``: see ``check_training_data``.
    """
    spec = spec or profile.spec
    shrinkage = profile.shrinkage if shrinkage is ... else shrinkage
    select_rejection = post is None and profile.select_rejection
    post = post or profile.post
    check_training_data(recordings, profile, spec, allow_missing_classes)
    if selection is None and (shrinkage == SELECT or select_rejection):
        selection = select_settings(recordings, profile, spec)
    if shrinkage == SELECT:
        shrinkage = selection.shrinkage
        profile = replace(profile, amplitude_scales=selection.amplitude_scales)
    if select_rejection:
        post = replace(post, rejection_threshold=selection.rejection_threshold)
    xs, ys, recorded, recorded_labels, angles = [], [], [], [], {i: [] for i in spec.nodes}
    for rec in recordings:
        windows, prepared = training_windows(rec, spec, profile.neutral_samples, MotionCopies.of(profile))
        xs.append(windows.features)
        ys.append(windows.labels)
        recorded.append(windows.recorded)
        ends = windows.ends[windows.recorded]   # amplitude ranges: the recorded motions only
        recorded_labels.append(windows.labels[windows.recorded])
        for k, i in enumerate(spec.nodes):
            angles[i].append(prepared.states[ends, k * _WIDTH:k * _WIDTH + 3])
    x, y, recorded = np.concatenate(xs), np.concatenate(ys), np.concatenate(recorded)
    sources = ", ".join(rec.source for rec in recordings)
    with np.errstate(all="ignore"):  # degenerate signals are reported below, as defects of the model
        try:
            classes, parameters = pipeline_parameters(fit_pipeline(x, y, shrinkage, recorded_priors(y, recorded)))
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise BomiError(f"{sources}: cannot train on these signals ({' '.join(str(exc).split())})") from None
        amplitude = amplitude_ranges({i: np.concatenate(a) for i, a in angles.items()}, np.concatenate(recorded_labels),
                                     profile.class_nodes, profile.amplitude)
        model = Model(classes=classes, parameters=parameters, spec=spec, amplitude=amplitude, post=post,
                      shrinkage=shrinkage, profile=profile.identity, amplitude_scales=profile.amplitude_scales,
                      cv_accuracy=None if selection is None else selection.accuracy,
                      training_runs=training_digests(recordings))
    defects = model_defects(model)
    if defects:
        more = f" (and {len(defects) - 1} more)" if len(defects) > 1 else ""
        raise BomiError(f"{sources}: cannot train a usable model: {defects[0]}{more}")
    return model


@dataclass
class Evaluation:
    """Scores of a model on the single-label windows of a labelled recording."""

    source: str
    truth: np.ndarray
    predicted: np.ndarray    # after post-processing (a rejected window is predicted neutral)
    rejected: np.ndarray

    @property
    def accuracy(self) -> float:
        return float(np.mean(self.predicted == self.truth))

    @property
    def rejected_share(self) -> float:
        return float(np.mean(self.rejected))

    @property
    def accepted_accuracy(self) -> float:
        """Accuracy over the windows the rejection let through."""
        accepted = ~self.rejected
        return float(np.mean(self.predicted[accepted] == self.truth[accepted])) if accepted.any() else float("nan")


def evaluate(model: Model, rec: Recording, neutral_samples: int, post: PostProcessing | None = None) -> Evaluation:
    """Decide every window in time order (as the stream does), then score the single-label ones."""
    unknown = sorted(set(rec.require_labels().tolist()) - set(model.classes.tolist()))
    if unknown:
        raise BomiError(f"{rec.source}: label(s) {unknown} are not classes of the model {model.classes.tolist()}")
    prepared = prepare(rec, model.spec, neutral_samples)
    pure = prepared.pure
    if not pure.any():
        raise BomiError(f"{rec.source}: no {model.spec.window}-sample window lies within one label; nothing to score")
    decisions = classify_windows(model, prepared.features, post)
    return Evaluation(rec.source, prepared.labels[pure], decisions.labels[pure], decisions.rejected[pure])


@dataclass(frozen=True)
class PassOut:
    """A leave-one-pass-out cross-validation: each pass decided by a model trained on the others."""

    evaluations: tuple[Evaluation, ...]

    @property
    def accuracy(self) -> float:
        """Over every held-out window of every pass (pooled)."""
        return float(np.mean(np.concatenate([ev.predicted == ev.truth for ev in self.evaluations])))

    def text(self) -> str:
        each = ", ".join(f"{100 * ev.accuracy:.2f} %" for ev in self.evaluations)
        return (f"leave-one-pass-out accuracy {100 * self.accuracy:.2f} % (each of {len(self.evaluations)} passes "
                f"decided by a model trained on the others: {each})")


def leave_one_pass_out(passes: Sequence[Recording], profile: Profile, model: Model) -> PassOut | None:
    """``model``'s settings (shrinkage, copies, post-processing) trained on all passes but one and tested
    on it, for every pass: how the classifier does on a pass it has not seen. None for one pass; a
    BomiError when the passes but one cannot train every class."""
    if len(passes) < 2:
        return None
    return PassOut(tuple(each_pass_by_the_others(passes, replace(profile, amplitude_scales=model.amplitude_scales),
                                                 model.spec, model.shrinkage, model.post)))


def each_pass_by_the_others(passes: Sequence[Recording], profile: Profile, spec: FeatureSpec,
                            shrinkage: float | str | None, post: PostProcessing) -> list[Evaluation]:
    """Each pass decided by the model of these settings trained on all the other passes."""
    evaluations = []
    for k, held_out in enumerate(passes):
        others = [p for j, p in enumerate(passes) if j != k]
        fold = train(others, profile, spec, shrinkage=shrinkage, post=post)
        evaluations.append(evaluate(fold, held_out, profile.neutral_samples, post))
    return evaluations


# ------------------------------------------------------------------------------------- streaming
@dataclass(slots=True)
class Decision:
    label: int
    name: str
    function: str            # joystick function (F, B, R, L, Rr, Lr, B1, B2) or "neutral"
    confidence: float        # posterior of the LDA's winning class (before post-processing)
    rejected: bool
    gamma: float             # the class's amplitude (deg) on the node carrying it: sqrt(p^2 + r^2 + y^2), or
                             # the change along the class's direction (profile [proportional]); 0 for neutral
    nu: float                # proportional output in [0, 1]
    sample_index: int        # index of the tick (node-1 sample) that produced it


class OnlineChain:
    """One sample at a time: per-node fusion, then a tick with at most one Decision per node-1 sample.

    The other nodes contribute their latest state; no decision is made until every node has
    reported once and the window is full. Node states are kept as Python floats (the same IEEE
    arithmetic as the batch form's arrays) because per-sample numpy calls dominate the cost.
    ``push_many`` takes many frames at once (a simulated participant's chunk) with the same result.
    """

    def __init__(self, model: Model, profile: Profile):
        missing = set(model.spec.nodes) - set(profile.node_indices)
        if missing:
            raise BomiError(f"{profile.source}: the model needs node(s) {sorted(missing)} the profile does not define")
        self.model = model
        self.profile = profile
        self.nodes = model.spec.nodes
        self._slot = {node: k for k, node in enumerate(self.nodes)}
        calibrations = {n.index: n.calibration for n in profile.nodes}
        self._fusion = {node: NodeFusion(calibrations[node]) for node in self.nodes}
        load_filter()   # before any frame: a stream must not wait for it between two samples
        self._state = [0.0] * (len(self.nodes) * _WIDTH)
        self._components = model.spec.components.tolist()
        self._gather = itemgetter(*self._components)   # the window's components of the node states
        # per class with an amplitude: (its node's slot in the states, its direction or None, its range)
        self._amplitude = {label: (self._slot[r.node] * _WIDTH, r.direction, r)
                           for label, r in model.amplitude.items() if r.node in self._slot}
        self._classes = {cls.label: cls for cls in profile.classes}
        self._labels = model.classes.tolist()   # the LDA's classes (posterior order) as Python ints
        self._seen: set[int] = set()
        self._neutral = [(0.0, 0.0, 0.0)] * len(self.nodes)
        self._window = WindowBuffer(model.spec.window, len(self._components), model.spec.stride)
        self._vote = MajorityVote(model.post.vote_length)
        self._voting = model.post.vote_length > 1   # a vote of one is the label itself: not called per window
        self._calibration: dict[int, list] | None = None
        self.ticks = 0

    # neutral-offset calibration
    @property
    def neutral(self) -> dict[int, tuple[float, float, float]]:
        return {node: self._neutral[k] for node, k in self._slot.items()}

    def set_neutral(self, offsets: Mapping[int, Sequence[float]]) -> None:
        """Neutral (pitch, roll, yaw) per node index; the window restarts."""
        for node, offset in offsets.items():
            self._neutral[self._slot[node]] = tuple(float(v) for v in offset)
        self._window.reset()

    def forget_decisions(self) -> None:
        """The window and the majority vote start empty: after a break in the stream (another sitting,
        perhaps) no sample or label from before it takes part in a decision after it."""
        self._window.reset()
        self._vote.reset()

    def begin_neutral_calibration(self) -> None:
        """Collect the next ``profile.neutral_samples`` fused samples of every node as the neutral posture."""
        self._calibration = {node: [] for node in self.nodes}

    @property
    def calibrating(self) -> bool:
        return self._calibration is not None

    # inputs
    def push_frames(self, frames: Iterable[ImuFrame]) -> list[Decision]:
        """Frames as the parser gives them, in arrival order, through the chain: the decisions they make."""
        return [decision for frame in frames if (decision := self.push_frame(frame)) is not None]

    def push_frame(self, frame: ImuFrame) -> Decision | None:
        """One frame as the parser gives it (``push`` with its node index and raw values)."""
        return self.push(imu_index(frame.node_id), frame.acc, frame.gyro, frame.mag)

    def push(self, node: int, acc, gyro, mag) -> Decision | None:
        """Raw int16 LSB in the sensor's axes -> fusion -> ``push_angles``. Unknown nodes are ignored."""
        fusion = self._fusion.get(node)
        if fusion is None:
            return None
        return self.push_angles(node, fusion.update(acc, gyro, mag), gyro)

    def push_angles(self, node: int, angles: Sequence[float], gyro: Sequence[float]) -> Decision | None:
        """Already-fused (pitch, roll, yaw) and gyro of one node (e.g. replaying a published recording)."""
        slot = self._slot.get(node)
        if slot is None:
            return None
        if self._calibration is not None:
            return self._collect_neutral(node, angles)
        base = slot * _WIDTH
        neutral = self._neutral[slot]
        state = self._state
        state[base] = float(angles[0]) - neutral[0]
        state[base + 1] = float(angles[1]) - neutral[1]
        state[base + 2] = float(angles[2]) - neutral[2]
        state[base + 3], state[base + 4], state[base + 5] = float(gyro[0]), float(gyro[1]), float(gyro[2])
        self._seen.add(node)
        if node != self.nodes[0] or len(self._seen) < len(self.nodes):
            return None
        return self._tick()

    def _collect_neutral(self, node: int, angles: Sequence[float]) -> None:
        samples = self._calibration[node]
        samples.append(tuple(angles))
        if all(len(s) >= self.profile.neutral_samples for s in self._calibration.values()):
            offsets = {n: neutral_offsets(np.array(s)) for n, s in self._calibration.items()}
            self._calibration = None
            self.set_neutral(offsets)

    def push_many(self, node: np.ndarray, acc: np.ndarray, gyro: np.ndarray, mag: np.ndarray
                  ) -> tuple[np.ndarray, list[Decision]]:
        """``push`` of n frames in arrival order ((n,) node indices, (n, 3) raw values each), stage by
        stage over all of them: each node's fusion by ``NodeFusion.update_many``, the node states at
        every tick, the windows (``WindowBuffer.push_many``), features, posteriors and vote of every
        full window at once. Returns the positions of the frames that made a decision and the
        decisions: what n calls of ``push`` return, to the bit (tests/test_chain_batch.py). A neutral
        calibration under way takes its frames one by one, as ``push`` does."""
        n, first = len(node), 0
        while self._calibration is not None and first < n:
            self.push(int(node[first]), acc[first].tolist(), gyro[first].tolist(), mag[first].tolist())
            first += 1
        node, acc, gyro, mag = node[first:], acc[first:], gyro[first:], mag[first:]
        previous = np.array(self._state).reshape(len(self.nodes), _WIDTH)
        per_node, opened = [], -1   # opened: the position from which every node has reported
        for slot, index in enumerate(self.nodes):
            mine = np.flatnonzero(node == index)
            states = np.empty((len(mine) + 1, _WIDTH))   # row 0: the state before these frames
            states[0] = previous[slot]
            if len(mine):
                states[1:, 3:] = gyro_mine = gyro[mine]
                states[1:, :3] = self._fusion[index].update_many(acc[mine], gyro_mine, mag[mine])
                states[1:, :3] -= self._neutral[slot]
                if index not in self._seen:
                    opened = max(opened, int(mine[0]))
                    self._seen.add(index)
            elif index not in self._seen:
                opened = len(node)
            per_node.append((mine, states))
        self._state = np.concatenate([states[-1] for _, states in per_node]).tolist()
        lead = per_node[0][0]
        ticking = lead[lead >= opened]
        states = np.hstack([states[np.searchsorted(mine, ticking, side="right")] for mine, states in per_node])
        indices = self.ticks + np.arange(len(ticking))
        self.ticks += len(ticking)
        vectors, made = self._window.push_many(states[:, self._components], self.model.spec.kind)
        return ticking[made] + first, self._decide_many(vectors, states[made], indices[made].tolist())

    def _tick(self) -> Decision | None:
        index = self.ticks
        self.ticks += 1
        state = self._state
        window = self._window.push(np.array(self._gather(state), dtype=float))
        if window is None:
            return None
        prob = posteriors(self.model, features(self.model.spec.kind, window[None]))[0]
        best = int(prob.argmax())
        return self._decide(best, float(prob[best]), state, index)

    def _decide_many(self, vectors: np.ndarray, states: np.ndarray, indices: Sequence[int]) -> list[Decision]:
        """``_decide`` of w full windows' (w, F) feature ``vectors`` at node states ``states`` (w rows), in
        order. Each window's scores a product of its own ((1, F) x (F, K), stacked as (w, 1, F)), as
        ``_tick``'s: one product over all the windows would sum in another order (other bits). The
        winners and the node states are read out of the arrays once, as Python numbers."""
        prob = posteriors(self.model, vectors[:, None, :])[:, 0]
        best = prob.argmax(axis=1)
        confidence = prob[np.arange(len(best)), best]
        decide = self._decide
        return [decide(*decision) for decision in zip(best.tolist(), confidence.tolist(), states.tolist(), indices)]

    def _decide(self, best: int, confidence: float, state: Sequence[float], index: int) -> Decision:
        """The decision of tick ``index`` from the window's winning class (its position ``best`` among the
        model's classes, its posterior ``confidence``) and the node states then (Python floats)."""
        threshold = self.model.post.rejection_threshold
        is_rejected = threshold is not None and confidence < threshold
        label = NEUTRAL_LABEL if is_rejected else self._labels[best]
        if self._voting:
            label = self._vote.push(label)
        cls = self._classes[label]
        amplitude = self._amplitude.get(label)
        if amplitude is None:
            return Decision(label, cls.name, cls.function, confidence, is_rejected, 0.0, 0.0, index)
        base, direction, calibrated = amplitude
        g = sample_amplitude(state[base], state[base + 1], state[base + 2], direction)
        return Decision(label, cls.name, cls.function, confidence, is_rejected, g, proportional(g, calibrated), index)


# ---------------------------------------------------------------- settings chosen on the training data
N_FOLDS = 3   # the paper's protocol holds every motion three times


def hold_folds(labels: np.ndarray, n_folds: int = N_FOLDS) -> np.ndarray:
    """Fold id per sample: whole holds dealt out to the folds, class by class.

    The k-th hold of a class (the neutral posture included) goes to fold k mod ``n_folds``, so a
    fold holds out whole repetitions of the protocol. A class held fewer than ``n_folds`` times has
    each of its holds cut into ``n_folds`` consecutive chunks instead, so that every fold still
    trains on every class.
    """
    edges = run_edges(labels)
    starts, lengths = edges[:-1], np.diff(edges)
    hold_labels = labels[starts]
    folds = np.empty(len(labels), dtype=int)
    for label in np.unique(hold_labels):
        holds = np.flatnonzero(hold_labels == label)
        for k, j in enumerate(holds):
            rows = slice(starts[j], starts[j] + lengths[j])
            if len(holds) >= n_folds:
                folds[rows] = k % n_folds
            else:
                folds[rows] = np.arange(lengths[j]) * n_folds // lengths[j]
    return folds


@dataclass(frozen=True)
class Candidate:
    """One classifier setting a cross-validation compares: LDA shrinkage and smaller training copies."""

    shrinkage: float | str | None = None
    amplitude_scales: tuple[float, ...] = ()

    @property
    def plain(self) -> bool:
        return self.shrinkage is None and not self.amplitude_scales

    def __str__(self) -> str:
        if self.plain:
            return "plain"
        parts = [] if self.shrinkage is None else [f"shrinkage {self.shrinkage}"]
        if self.amplitude_scales:
            parts.append("copies at " + ", ".join(f"{s:g}" for s in self.amplitude_scales))
        return " + ".join(parts)


PLAIN = Candidate()


@dataclass
class CrossValidation:
    """Held-out windows of a cross-validation: truth and posteriors of each."""

    classes: np.ndarray
    truth: np.ndarray
    prob: np.ndarray
    holds: np.ndarray        # per window, its held-out hold (one class held once; its part in one fold when the
                             # hold was cut into chunks), an id unique over the recordings

    @property
    def accuracy(self) -> float:
        return self.accuracy_rejecting(None)

    def decided(self, threshold: float | None = None) -> np.ndarray:
        """Per window: the class decided, a window whose winning posterior is below ``threshold`` neutral."""
        return reject(self.classes[self.prob.argmax(axis=1)], self.prob.max(axis=1), threshold)

    def correct(self, threshold: float | None = None) -> np.ndarray:
        """Per window: decided right (``decided``)."""
        return self.decided(threshold) == self.truth

    def accuracy_rejecting(self, threshold: float | None) -> float:
        return float(np.mean(self.correct(threshold)))

    def hold_scores(self, threshold: float | None = None) -> HoldScores:
        """Per held-out hold (sorted ids): windows decided right (rejecting below ``threshold``), and windows."""
        _, index = np.unique(self.holds, return_inverse=True)
        return HoldScores(np.bincount(index, weights=self.correct(threshold)), np.bincount(index).astype(float))


@dataclass(frozen=True)
class HoldScores:
    """One setting's cross-validation, counted per held-out hold: the hold is the unit a gain is judged
    on, because the windows of one hold are not independent (they share one posture, one drift, one
    glitch): a gain that comes from a few holds says little about the next recording."""

    correct: np.ndarray      # (holds,) windows decided right
    windows: np.ndarray      # (holds,) windows

    @property
    def accuracy(self) -> float:
        return float(self.correct.sum() / self.windows.sum())

    def gain_over(self, base: HoldScores) -> tuple[float, float]:
        """Accuracy gained over ``base`` (the same holds) and its standard error, the holds as the
        sampled units: the pooled gain G = sum_h w_h d_h (d_h the gain on hold h, w_h its share of
        the windows) has variance H/(H-1) sum_h w_h^2 (d_h - G)^2 (the cluster, or ratio-estimator,
        variance)."""
        total = self.windows.sum()
        gain = float((self.correct - base.correct).sum() / total)
        weights = self.windows / total
        deviations = (self.correct - base.correct) / self.windows - gain
        holds = len(weights)
        se = float(np.sqrt(holds / (holds - 1) * np.sum((weights * deviations) ** 2))) if holds > 1 else float("inf")
        return gain, se


def cross_validate(recordings: Sequence[Recording], profile: Profile, spec: FeatureSpec,
                   candidates: Sequence[Candidate]) -> list[CrossValidation]:
    """Cross-validation within each recording holding out whole holds (``hold_folds``), pooled; one
    result per candidate. Training folds use the recording's own neutral calibration (no
    re-referencing), the candidate's smaller copies and the profile's turned copies of the motions;
    windows straddling a label change or a fold boundary are left out of both sides.
    """
    with single_threaded_blas():  # many small products: see classifier.fit_pipeline
        parts = [_cross_validate(rec, profile, spec, candidates) for rec in recordings]
    classes = np.unique(np.concatenate([rec.require_labels() for rec in recordings]))
    offsets = N_FOLDS * np.cumsum([0] + [len(rec) for rec in recordings])   # unique hold ids over the recordings
    results = []
    for k in range(len(candidates)):
        pieces = [_align(piece, classes, offset) for part, offset in zip(parts, offsets) for piece in part[k]]
        if not pieces:
            raise BomiError(f"{recordings[0].source}: too little data for a {N_FOLDS}-fold cross-validation")
        results.append(CrossValidation(classes, *(np.concatenate([p[j] for p in pieces]) for j in range(3))))
    return results


def _align(piece: tuple, classes: np.ndarray, offset: int) -> tuple:
    """(truth, the fold model's classes, posteriors over them, holds) -> (truth, posteriors over
    ``classes``, holds numbered over the recordings)."""
    truth, fold_classes, prob, holds = piece
    full = np.zeros((len(prob), len(classes)))
    full[:, np.searchsorted(classes, fold_classes)] = prob
    return truth, full, holds + offset


def _cross_validate(rec: Recording, profile: Profile, spec: FeatureSpec,
                    candidates: Sequence[Candidate]) -> list[list[tuple]]:
    labels = rec.require_labels()
    folds, n_folds = hold_folds(labels), N_FOLDS
    hold_starts = np.maximum.accumulate(np.where(np.diff(labels, prepend=labels[0] - 1) != 0, np.arange(len(labels)), 0))
    parts: list[list[tuple]] = [[] for _ in candidates]
    inside = single_label_windows(labels * n_folds + folds, spec.window, spec.stride)  # not across a fold boundary
    by_scales = {}
    for scales in dict.fromkeys(c.amplitude_scales for c in candidates):
        copies = replace(MotionCopies.of(profile), scales=scales)
        by_scales[scales] = training_windows(rec, spec, profile.neutral_samples, copies)
    for candidate, part in zip(candidates, parts):
        windows, prepared = by_scales[candidate.amplitude_scales]
        train_fold = np.where(inside[(windows.ends - (spec.window - 1)) // spec.stride], folds[windows.ends], -1)
        for k in range(n_folds):
            fit_rows = (train_fold >= 0) & (train_fold != k)
            test_rows = inside & prepared.pure & (folds[prepared.ends] == k)
            if len(np.unique(windows.labels[fit_rows])) < 3 or not test_rows.any():
                continue   # a fold without enough classes to fit, or nothing to test: left out
            classes, parameters = pipeline_parameters(fit_pipeline(
                windows.features[fit_rows], windows.labels[fit_rows], candidate.shrinkage,
                recorded_priors(windows.labels[fit_rows], windows.recorded[fit_rows])))
            model = Model(classes=classes, parameters=parameters, spec=spec, amplitude={})
            part.append((prepared.labels[test_rows], model.classes, posteriors(model, prepared.features[test_rows]),
                         hold_starts[prepared.ends[test_rows]] * n_folds + k))
    return parts


SHRINKAGE_GRID: tuple[float | str | None, ...] = (None, 1e-3, 1e-2, 1e-1, "auto")
THRESHOLD_GRID = (0.5, 0.9, 0.99, 0.999, 0.9999)
# The rule every extra (a shrinkage, the smaller copies, a rejection threshold) passes, one extra at a
# time (``choose_option``): of the options, simplest first, take the simplest whose cross-validation is
# within CONSISTENCY standard errors of the best one's (the standard error of their paired difference,
# the held-out holds as units: ``HoldScores.gain_over``); and leave the first option (plain, or what is
# chosen before) only for a gain of at least REQUIRED_GAIN. With CONSISTENCY = 1 this is the "one
# standard error rule" of model selection (Hastie, Tibshirani & Friedman, section 7.10); 2 is the
# conventional level of a one-sided test at about 2.5 %, chosen a priori: a gain must be plain over the
# holds, not the work of a few of them (one glitch, one repetition's odd posture), which does not carry
# to the next recording. The margin, set on development people 0-16 (at 1 point, person 2 took
# shrinkage 0.1 + copies for +1.09 points of CV and lost 7.6 points on pass 2), stands for what a
# cross-validation within one recording cannot see: the drift to the next one. Development people
# 100-139 and 200-299 (benchmarks/new_people_candidates.py, docs/signal_chain.md) show both are needed.
REQUIRED_GAIN = 0.02
CONSISTENCY = 2.0


def choose_option(options: Sequence[HoldScores], consistency: float = CONSISTENCY,
                  required_gain: float = REQUIRED_GAIN) -> int:
    """Index of the option (simplest first, each scored on the same held-out holds) the rule above
    takes: the simplest within ``consistency`` standard errors of the best (the first best on a tie),
    unless it gains less than ``required_gain`` over the first option, which is then kept. (0: the best,
    the rule before the standard errors; other values only to replay it, benchmarks/new_people_candidates.py.)"""
    best = max(range(len(options)), key=lambda i: options[i].accuracy)

    def within(i: int) -> bool:
        gain, se = options[best].gain_over(options[i])
        return i == best or gain <= consistency * se

    chosen = next(i for i in range(len(options)) if within(i))
    return chosen if options[chosen].gain_over(options[0])[0] >= required_gain else 0


@dataclass
class Selection:
    """Settings chosen on the training recording(s) alone, with the cross-validation behind the choice."""

    shrinkage: float | str | None
    amplitude_scales: tuple[float, ...]
    rejection_threshold: float | None
    accuracy: float | None             # the cross-validation estimate of the chosen settings (None: no CV)
    plain_accuracy: float | None       # ... and of the plain setting
    candidates: dict[str, float]       # every candidate setting -> its CV accuracy
    reason: str = ""                   # why, in one line
    held_out: tuple[np.ndarray, np.ndarray] | None = None   # the chosen settings' CV: (truth, decided) per window

    @property
    def candidate(self) -> Candidate:
        return Candidate(self.shrinkage, self.amplitude_scales)

    def describe(self) -> str:
        chosen = str(self.candidate)
        if self.rejection_threshold is not None:
            chosen = ("" if self.candidate.plain else chosen + " + ") + f"rejection below {self.rejection_threshold}"
        return chosen

    def explain(self) -> str:
        return f"settings chosen on the training recording: {self.describe()} ({self.reason})"


def choose_candidate(candidates: Sequence[Candidate], scores: Mapping[str, HoldScores],
                     consistency: float = CONSISTENCY) -> Candidate:
    """``choose_option`` twice, one extra at a time: among PLAIN and the shrinkages alone (in the order
    of SHRINKAGE_GRID: none, growing, then Ledoit-Wolf's, estimated from the data), then between what
    is so chosen and the same with the smaller copies. A shrinkage that did not earn its place alone
    does not come in with the copies (a joint gain of the two can fit the training pass alone:
    confirmation 10200, two people lost 8-10 points on pass 2 that way)."""
    alone = [c for c in candidates if not c.amplitude_scales]
    chosen = alone[choose_option([scores[str(c)] for c in alone], consistency)]
    copied = next((c for c in candidates if c.amplitude_scales and c.shrinkage == chosen.shrinkage), None)
    if copied is not None and choose_option([scores[str(chosen)], scores[str(copied)]], consistency):
        chosen = copied
    return chosen


def choose_threshold(base: HoldScores, rejecting: Mapping[float, HoldScores],
                     consistency: float = CONSISTENCY) -> float | None:
    """``choose_option`` among no rejection (``base``) and the thresholds of ``rejecting`` (threshold ->
    the chosen setting's CV rejecting below it), the lowest (rejecting least) first: the threshold, or None."""
    thresholds = sorted(rejecting)
    chosen = choose_option([base] + [rejecting[t] for t in thresholds], consistency)
    return thresholds[chosen - 1] if chosen else None


def settings_candidates(profile: Profile) -> list[Candidate]:
    """The settings a cross-validation compares for ``profile``: every shrinkage of SHRINKAGE_GRID,
    alone and with the profile's smaller copies (when it has any); PLAIN first."""
    scales = (((),) + ((profile.amplitude_scales,) if profile.amplitude_scales else ()))
    return [Candidate(s, c) for c in scales for s in SHRINKAGE_GRID]


def select_settings(recordings: Sequence[Recording], profile: Profile, spec: FeatureSpec) -> Selection:
    """The plain setting (no shrinkage, no copies, no rejection), to which an extra is added only when
    the cross-validation (``cross_validate``) shows a gain large and steady over the held-out holds
    (``choose_option``), one extra at a time: first a shrinkage of SHRINKAGE_GRID; then the profile's
    smaller copies of the motions (with the shrinkage chosen); then a rejection threshold of
    THRESHOLD_GRID (a rejected window counts as decided neutral). Without enough data for the CV: plain."""
    # The turned copies (direction_spread) stand for how a motion's direction changes from one day to
    # another, which a cross-validation within the recording cannot see (it is chosen across days):
    # the settings are compared without them.
    candidates = settings_candidates(profile)
    try:
        results = cross_validate(recordings, replace(profile, direction_spread=0.0), spec, candidates)
    except BomiError as exc:
        return Selection(None, (), None, None, None, {}, f"{exc}: plain settings")
    return choose_settings(candidates, results, profile.select_rejection)


def rest_offset_scores(passes: Sequence[Recording], profile: Profile) -> tuple[HoldScores, HoldScores]:
    """Each pass read by the model of the others, without and with the rest-offset copies (the
    profile's plain LDA and smaller copies: the copies' own effect), scored per hold."""
    scores = []
    for on in (False, True):
        correct, windows = [], []
        for result in each_pass_by_the_others(passes, replace(profile, rest_offsets=on), profile.spec, None,
                                              PostProcessing()):
            holds = run_edges(result.truth)   # the scored windows, in time order: a run of one label is a hold
            correct.append(np.add.reduceat(result.predicted == result.truth, holds[:-1]))
            windows.append(np.diff(holds))
        scores.append(HoldScores(np.concatenate(correct), np.concatenate(windows)))
    return scores[0], scores[1]


def choose_rest_offsets(passes: Sequence[Recording], profile: Profile) -> tuple[bool, str]:
    """Whether the rest-offset copies (``MotionCopies.rest_offsets``) earn their place for this person,
    and why in one line. A cross-validation within one recording cannot tell (its folds share one
    reference); passes calibrated each on its own rest can (``rest_offset_scores``), judged by
    ``choose_option``'s rule, its standard errors without its margin: REQUIRED_GAIN stands for the
    drift to the next recording that a cross-validation within one cannot see, and the other pass
    shows it. One pass: no evidence, no copies."""
    if len(passes) < 2:
        return False, "no rest-offset copies: one pass, nothing to judge them on"
    without, with_copies = rest_offset_scores(passes, profile)
    chosen = choose_option([without, with_copies], required_gain=0.0) == 1
    gain, se = with_copies.gain_over(without)
    return chosen, (f"{'' if chosen else 'no '}rest-offset copies: each pass read by the others' model "
                    f"{100 * without.accuracy:.2f} % without, {100 * with_copies.accuracy:.2f} % with "
                    f"({100 * gain:+.2f} +- {100 * se:.2f} points over {len(without.windows)} holds: they come in "
                    f"for a gain of {CONSISTENCY:g} standard errors)")


def choose_settings(candidates: Sequence[Candidate], results: Sequence[CrossValidation],
                    select_rejection: bool) -> Selection:
    """The settings ``select_settings`` chooses from the cross-validation ``results`` of ``candidates``."""
    scores = {str(c): r.hold_scores() for c, r in zip(candidates, results)}
    chosen = choose_candidate(candidates, scores)
    result = results[candidates.index(chosen)]
    threshold = None
    if select_rejection:
        rejecting = {t: result.hold_scores(t) for t in THRESHOLD_GRID}
        threshold = choose_threshold(scores[str(chosen)], rejecting)
        scores.update({f"{chosen} + rejection below {t}": v for t, v in rejecting.items()})
    plain = scores[str(PLAIN)]
    final = result.hold_scores(threshold)
    gain, se = final.gain_over(plain)
    runner = max((k for k in scores if k != str(PLAIN)), key=lambda k: scores[k].accuracy, default=None)
    reason = (f"{N_FOLDS}-fold CV holding out whole holds, over {len(result.truth)} windows in {len(final.windows)} "
              f"holds: plain {100 * plain.accuracy:.2f} %, chosen {100 * final.accuracy:.2f} % "
              f"({100 * gain:+.2f} +- {100 * se:.2f} points); an extra comes in only for a gain of {100 * REQUIRED_GAIN:g} "
              f"point(s) and of {CONSISTENCY:g} standard errors over the holds, the simplest within that of the best")
    if runner is not None and final.accuracy == plain.accuracy:
        runner_gain, runner_se = scores[runner].gain_over(plain)
        reason += (f"; best extra {runner}: {100 * scores[runner].accuracy:.2f} % "
                   f"({100 * runner_gain:+.2f} +- {100 * runner_se:.2f} points)")
    return Selection(chosen.shrinkage, chosen.amplitude_scales, threshold, final.accuracy, plain.accuracy,
                     {k: v.accuracy for k, v in scores.items()}, reason, (result.truth, result.decided(threshold)))
