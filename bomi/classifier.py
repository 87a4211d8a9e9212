"""LDA classification, optional post-processing, and the paper's proportional output.

scikit-learn fits the classifier as a ``Pipeline``: ``StandardScaler`` (every feature on one scale,
whatever the person, sensor, unit or mounting), then ``LinearDiscriminantAnalysis``. In the plain
setting (no shrinkage, no synthesised copies) the LDA is scikit-learn's default 'svd' solver, which
itself keeps only the directions of the (within-class standardised) windows above its rank
tolerance: the plain setting is exactly plain LDA. With a shrinkage or copies, a ``PCA`` first
rotates onto the numerical rank of the standardised training windows (FV1-FV3 hold near-duplicate
columns: the statistics of an 8-sample window of a slow signal are almost equal) and the
least-squares solver works in that space; the PCA is not whitened, so that a shrinkage keeps
damping the directions of negligible variance, which whitening would weigh as much as any other
(trained so on a virtual P1 session with shrinkage 0.001, the live chain read the next session's
neutral posture as c8). Every
step is affine, so the fitted pipeline is one linear discriminant on the raw features; decisions
use it (``Model.coef``, ``Model.intercept``) through ``posteriors``, the same softmax sklearn's
``predict_proba`` computes, because sklearn's per-call input validation costs ~90 us per single
sample, more than the whole streaming budget. A model file keeps the fitted parameters of each
step (``PipelineParameters``); a loaded model composes them with the same function as the trained
one, so it predicts with exactly the same arithmetic.

Post-processing steps are separate and optional (off by default): confidence rejection (posterior
below a threshold -> the neutral class) then a majority vote over the last N decisions.
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from functools import cache

import numpy as np
from sklearn import config_context
from sklearn.decomposition import PCA
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from threadpoolctl import ThreadpoolController

from bomi.features import FeatureSpec

NEUTRAL_LABEL = 0
# Bounds of a usable model, so a file's garbled or hostile values are refused before they move
# the arm. The paper uses 9 classes (neutral, six directions, two buttons); nobody gives dozens of
# distinct motions. LDA weights of real features (degrees, deg/s) are far below 1e9; beyond it a
# score overflows. An angle change (gamma, the norm of pitch, roll and yaw changes of at most 360
# degrees each) is at most 360 * sqrt(3) degrees.
MAX_CLASSES = 64
MAX_ABS_PARAMETER = 1e9
MAX_ANGLE_CHANGE_DEG = 360.0 * 3 ** 0.5
# A vote over more decisions than 10 s of them (at the nodes' 62.5 Hz) would answer a motion
# after it is over: no setting of a usable interface.
MAX_VOTE_LENGTH = 625


@dataclass(frozen=True)
class PostProcessing:
    """Rejection threshold on the winning posterior (None = off) and majority-vote length (1 = off)."""

    rejection_threshold: float | None = None
    vote_length: int = 1

    def __post_init__(self) -> None:
        if self.rejection_threshold is not None and not 0.0 < self.rejection_threshold < 1.0:
            raise ValueError(f"rejection threshold must be in (0, 1), got {self.rejection_threshold}")
        if not 1 <= self.vote_length <= MAX_VOTE_LENGTH:
            raise ValueError(f"vote length must be in [1, {MAX_VOTE_LENGTH}] decisions (10 s), got {self.vote_length}")


AMPLITUDE_KINDS = ("gamma", "along_class")


@dataclass(frozen=True)
class AmplitudeRange:
    """The node that carries a class and its amplitude range over the class's training samples (degrees).

    ``direction`` None: the amplitude is the paper's gamma, the size of the node's angle change.
    A unit (pitch, roll, yaw) vector: the amplitude is the angle change along the class's mean
    direction, so a motion toward another class (or a return to neutral from it) has next to none.
    """

    node: int
    gamma_min: float
    gamma_max: float
    direction: tuple[float, float, float] | None = None


# PCA keeps the directions whose singular value exceeds this share of the largest (scikit-learn's own
# rank tolerance for its 'svd' LDA solver): only numerically empty directions are dropped, the
# small-variance ones that separate classes stay.
RANK_TOLERANCE = 1e-4


@dataclass(frozen=True)
class PipelineParameters:
    """The fitted parameters of StandardScaler -> PCA -> LDA, as a model file keeps them."""

    scaler_mean: np.ndarray      # (F,)
    scaler_scale: np.ndarray     # (F,)
    pca_mean: np.ndarray         # (F,) mean of the standardised features (about 0; 0 without a PCA)
    pca_components: np.ndarray   # (R, F) (the F x F identity without a PCA: the plain setting)
    lda_coef: np.ndarray         # (K, R)
    lda_intercept: np.ndarray    # (K,)

    def __post_init__(self) -> None:
        # C-ordered float64 whatever the source (sklearn's lstsq gives Fortran-ordered arrays): the
        # products in ``linear`` then sum in one order, and a loaded model predicts bit-identically
        for name in self.__dataclass_fields__:
            object.__setattr__(self, name, np.ascontiguousarray(getattr(self, name), dtype=float))

    def linear(self) -> tuple[np.ndarray, np.ndarray]:
        """The whole pipeline as one discriminant on the raw features: (coef (K, F), intercept (K,))."""
        with np.errstate(over="ignore", invalid="ignore"):  # a damaged file's overflow: model_defects names it
            projection = self.pca_components / self.scaler_scale[None, :]
            coef = self.lda_coef @ projection
            intercept = self.lda_intercept - self.lda_coef @ (projection @ self.scaler_mean
                                                              + self.pca_components @ self.pca_mean)
        return coef, intercept


@dataclass
class Model:
    """A trained classifier: everything needed to turn node states into decisions.

    ``coef`` and ``intercept`` are the pipeline's single linear discriminant (``parameters.linear()``).
    """

    classes: np.ndarray          # (K,) int labels, in sklearn's order
    parameters: PipelineParameters
    spec: FeatureSpec
    amplitude: dict[int, AmplitudeRange]
    post: PostProcessing = field(default_factory=PostProcessing)
    shrinkage: float | str | None = None
    profile: ProfileIdentity | None = None  # the profile it was trained for (None: made in memory, e.g. a CV fold)
    amplitude_scales: tuple[float, ...] = ()   # the smaller copies of the motions it was trained with
    cv_accuracy: float | None = None  # the cross-validation estimate of its settings (None: not chosen by one)
    training_runs: tuple[str, ...] = ()   # digests of the runs it was trained on (bomi.passes.training_digests)
    coef: np.ndarray = field(init=False)        # (K, F)
    intercept: np.ndarray = field(init=False)   # (K,)

    def __post_init__(self) -> None:
        self.coef, self.intercept = self.parameters.linear()


@dataclass(frozen=True)
class ProfileIdentity:
    """Which profile a model was trained for: its name and a hash of what decides how the model
    moves the arm (nodes and their calibration, classes and their joystick functions, features,
    amplitude kind, joystick layout); see bomi.profiles.Profile.identity."""

    name: str
    digest: str


def model_defects(model: Model) -> list[str]:
    """What makes ``model`` unusable or unsafe (empty when it is fine): shapes, non-finite
    parameters, and amplitude ranges that would give a class a speed out of nothing (NaN or
    infinite bounds, min >= max, a node the model does not read, the neutral class)."""
    defects = []
    classes = np.asarray(model.classes)
    if classes.ndim != 1 or classes.dtype.kind not in "iu" or len(set(classes.tolist())) != len(classes):
        return ["classes must be distinct integer labels"]
    if not 3 <= len(classes) <= MAX_CLASSES:
        defects.append(f"needs three to {MAX_CLASSES} classes, has {len(classes)}")
    shrinkage = model.shrinkage
    if not (shrinkage is None or shrinkage == "auto" or (isinstance(shrinkage, (int, float))
                                                          and not isinstance(shrinkage, bool) and 0 <= shrinkage <= 1)):
        defects.append(f"shrinkage must be a number in [0, 1], \"auto\" or absent, got {shrinkage!r}")
    if model.coef.ndim != 2 or model.coef.shape[0] != len(classes) or model.intercept.shape != (len(classes),):
        defects.append(f"coef/intercept shapes {model.coef.shape}/{model.intercept.shape} do not fit "
                       f"{len(classes)} classes")
    elif not (np.all(np.isfinite(model.coef)) and np.all(np.isfinite(model.intercept))):
        defects.append("non-finite LDA parameters (constant or degenerate training signals?)")
    elif max(np.abs(model.coef).max(initial=0.0), np.abs(model.intercept).max(initial=0.0)) > MAX_ABS_PARAMETER:
        defects.append(f"LDA parameters beyond +-{MAX_ABS_PARAMETER:g} (no real signal gives them)")
    for label, r in sorted(model.amplitude.items()):
        where = f"amplitude range of class {label}"
        if label == NEUTRAL_LABEL or label not in set(classes.tolist()):
            defects.append(f"{where}: not a motion class of the model")
        if r.node not in model.spec.nodes:
            defects.append(f"{where}: node {r.node} is not one of the model's nodes {list(model.spec.nodes)}")
        if not (np.isfinite(r.gamma_min) and np.isfinite(r.gamma_max)):
            defects.append(f"{where}: [{r.gamma_min}, {r.gamma_max}] is not finite")
        elif not r.gamma_min < r.gamma_max:
            defects.append(f"{where}: min {r.gamma_min} is not below max {r.gamma_max} (no spread in the "
                           "class's training samples)")
        elif not (r.gamma_max <= MAX_ANGLE_CHANGE_DEG
                  and r.gamma_min >= (0.0 if r.direction is None else -MAX_ANGLE_CHANGE_DEG)):
            # gamma is a size (>= 0); along a direction a class's least sample may lie behind (P1's
            # day-1 c4: -2.3 degrees), but no angle change is larger than MAX_ANGLE_CHANGE_DEG
            low = "0" if r.direction is None else f"-{MAX_ANGLE_CHANGE_DEG:.0f}"
            defects.append(f"{where}: [{r.gamma_min:g}, {r.gamma_max:g}] degrees is not an angle change "
                           f"(expected {low} <= min < max <= {MAX_ANGLE_CHANGE_DEG:.0f})")
        elif r.direction is not None and not (len(r.direction) == 3 and np.all(np.isfinite(r.direction))
                                            and abs(np.linalg.norm(r.direction) - 1.0) < 1e-6):
            defects.append(f"{where}: direction must be a finite unit 3-vector")
    return defects


@cache
def _thread_pools() -> ThreadpoolController:
    """The thread pools of the loaded libraries, looked up once (by the first fit, after scikit-learn
    and scipy have loaded theirs): ``threadpool_limits`` looks them up at every call, 5 ms."""
    return ThreadpoolController()


def single_threaded_blas() -> AbstractContextManager:
    """A context in which BLAS runs on one thread (see ``fit_pipeline``)."""
    return _thread_pools().limit(limits=1, user_api="blas")


def numerical_rank(standardised: np.ndarray) -> int:
    """How many directions of the ``standardised`` features (``StandardScaler``'s output, as
    ``fit_pipeline`` fits it) have a singular value above RANK_TOLERANCE x the largest (at least 1)."""
    # singular values as the square roots of the F x F Gram matrix's eigenvalues: one product over the
    # n windows instead of an n x F SVD (10x less work); their error (~1e-8 of the largest, from
    # squaring) is far below RANK_TOLERANCE, so only a value within that of the tolerance could count
    # otherwise. Standardised features are centred (column means ~1e-15 of their unit spread): their
    # Gram matrix is the centred one to round-off, without a centred copy of the n windows
    eigenvalues = np.linalg.eigvalsh(standardised.T @ standardised)[::-1]
    singular = np.sqrt(np.clip(eigenvalues, 0.0, None))
    return max(1, int(np.count_nonzero(singular > RANK_TOLERANCE * singular[0])))


def fit_pipeline(features: np.ndarray, labels: np.ndarray, shrinkage: float | str | None,
                 priors: np.ndarray | None = None) -> Pipeline:
    """StandardScaler -> LDA. The plain setting (no shrinkage, ``priors`` None: the class frequencies
    of ``labels``): scikit-learn's default 'svd' solver, whose predictions are plain LDA's to the last
    window (the scaling does not change them). Otherwise a PCA (a rotation onto the numerical rank, not
    whitened, so a shrinkage still damps the directions of negligible variance) between the two and
    the least-squares solver, which takes a shrinkage (on standardised features it means the same for
    every person, sensor and unit) and weighs each class's covariance by its prior (given priors
    come with synthesised copies of the motions: the 'svd' solver would pool the covariance over the
    copies, which then outweigh the recorded neutral posture).

    The PCA is computed from the F x F covariance (scikit-learn's 'covariance_eigh'), as
    ``numerical_rank`` does: on n >> F windows it is the same rotation as the n x F SVD at a tenth
    of its cost (0.4-0.6 s of a virtual participant's 1.8 s set-up); the directions it keeps have
    eigenvalues above RANK_TOLERANCE**2 = 1e-8 of the largest, where squaring loses no accuracy
    that matters.

    The steps are fitted one after the other, as ``Pipeline.fit`` fits them (each step's
    ``fit_transform`` of the previous one's output, the LDA's ``fit`` last: the same calls, so the
    same parameters to the bit, tests/test_classifier.py), so that the rank is read from the
    standardised features the PCA is fitted on rather than from a second standardisation of them,
    and the features are checked for NaN and infinities once rather than by every step (five passes
    over the n windows, each step's input made by the one before).

    BLAS runs single-threaded here, the rank's products included: on these 128 x 128 problems a busy
    2-core machine made the threaded scipy lstsq ~100x slower (0.24 s instead of 2 ms) while its
    threads waited for a core, and the threaded Gram matrix of the rank 1 s of CPU instead of 0.08 s.
    """
    (pipeline,) = fit_pipelines(features, labels, (shrinkage,), priors)
    return pipeline


def fit_pipelines(features: np.ndarray, labels: np.ndarray, shrinkages: Sequence[float | str | None],
                  priors: np.ndarray | None = None) -> list[Pipeline]:
    """``fit_pipeline`` for each of ``shrinkages`` on the same data: the scaler, and the PCA of the
    settings that have one, fitted once and shared (the same fits each pipeline would make alone, so
    the same parameters to the bit; a cross-validation fold compares the shrinkages so)."""
    if not np.isfinite(features).all():   # checked once here: each step would check its input again
        raise ValueError("the features hold NaN or infinite values")
    pipelines = []
    with single_threaded_blas(), config_context(assume_finite=True):
        scale = StandardScaler()
        standardised = scale.fit_transform(features, labels)
        pca, rotated = None, None
        for shrinkage in shrinkages:
            if shrinkage is None and priors is None:
                steps = ("passthrough", LinearDiscriminantAnalysis(solver="svd").fit(standardised, labels))
            else:
                if pca is None:
                    pca = PCA(n_components=numerical_rank(standardised), svd_solver="covariance_eigh")
                    rotated = pca.fit_transform(standardised, labels)
                lda = LinearDiscriminantAnalysis(solver="lsqr", shrinkage=shrinkage, priors=priors)
                steps = (pca, lda.fit(rotated, labels))
            pipelines.append(Pipeline([("scale", scale), ("pca", steps[0]), ("lda", steps[1])]))
    return pipelines


def pipeline_parameters(pipeline: Pipeline) -> tuple[np.ndarray, PipelineParameters]:
    """(classes, the fitted parameters of every step) of a fitted multi-class ``fit_pipeline``; a
    pipeline without a PCA keeps the identity rotation in its place."""
    scale, pca, lda = (pipeline.named_steps[name] for name in ("scale", "pca", "lda"))
    if len(lda.classes_) < 3:
        raise ValueError("need at least three classes (binary LDA has a single discriminant)")
    n_features = len(scale.mean_)
    pca_mean, components = ((np.zeros(n_features), np.eye(n_features)) if pca == "passthrough"
                            else (pca.mean_.copy(), pca.components_.copy()))
    return np.asarray(lda.classes_, dtype=np.int64), PipelineParameters(
        scale.mean_.copy(), scale.scale_.copy(), pca_mean, components, lda.coef_.copy(), lda.intercept_.copy())


def posteriors(model: Model, features: np.ndarray) -> np.ndarray:
    """(..., F) -> (..., K) class posteriors: softmax of the linear discriminant scores."""
    scores = features @ model.coef.T
    scores += model.intercept
    scores -= np.maximum.reduce(scores, axis=-1, keepdims=True)
    np.exp(scores, out=scores)
    scores /= np.add.reduce(scores, axis=-1, keepdims=True)
    return scores


def rejected(confidence: np.ndarray, threshold: float | None) -> np.ndarray:
    """Mask of decisions whose winning posterior is below ``threshold`` (none when rejection is off)."""
    if threshold is None:
        return np.zeros(np.shape(confidence), dtype=bool)
    return np.asarray(confidence) < threshold


def reject(labels: np.ndarray, confidence: np.ndarray, threshold: float | None,
           neutral: int = NEUTRAL_LABEL) -> np.ndarray:
    """Replace decisions whose posterior is below ``threshold`` with the neutral class."""
    return np.where(rejected(confidence, threshold), neutral, labels)


class MajorityVote:
    """Streaming majority over the last ``length`` labels; a tie goes to the most recent tied label."""

    def __init__(self, length: int):
        self._history: deque[int] = deque(maxlen=length)
        self._counts: dict[int, int] = {}   # of each label in the history

    def reset(self) -> None:
        """Forget every label (the next decision is voted on itself alone)."""
        self._history.clear()
        self._counts.clear()

    def push(self, label: int) -> int:
        history, counts = self._history, self._counts
        if history.maxlen == 1:   # vote off: the common case, kept cheap for the stream
            return label
        if len(history) == history.maxlen:
            counts[history[0]] -= 1   # the oldest label leaves the history
        history.append(label)
        mine = counts[label] = counts.get(label, 0) + 1
        if 2 * mine > len(history):   # more than half of the history: the most frequent label (the common case)
            return label
        best = max(counts.values())
        if counts[label] == best:   # the most recent label is among the most frequent
            return label
        return next(item for item in reversed(history) if counts[item] == best)


def majority_vote(labels: np.ndarray, length: int) -> np.ndarray:
    """Batch form of ``MajorityVote`` over a decision sequence."""
    if length == 1:
        return labels
    vote = MajorityVote(length)
    return np.array([vote.push(int(label)) for label in labels], dtype=labels.dtype)


@dataclass
class BatchDecisions:
    raw: np.ndarray          # argmax of the posteriors
    confidence: np.ndarray   # the winning posterior
    rejected: np.ndarray     # confidence below the rejection threshold
    labels: np.ndarray       # after post-processing


def classify_windows(model: Model, features: np.ndarray, post: PostProcessing | None = None) -> BatchDecisions:
    """Decisions for a sequence of windows in time order (the vote depends on the order)."""
    post = post or model.post
    prob = posteriors(model, features)
    best = prob.argmax(axis=1)
    raw = model.classes[best]
    confidence = prob[np.arange(len(prob)), best]
    labels = majority_vote(reject(raw, confidence, post.rejection_threshold), post.vote_length)
    return BatchDecisions(raw=raw, confidence=confidence, rejected=rejected(confidence, post.rejection_threshold),
                          labels=labels)


def gamma(pitch, roll, yaw):
    """sqrt(pitch^2 + roll^2 + yaw^2) of neutral-subtracted angles (floats or arrays alike)."""
    return np.sqrt(pitch * pitch + roll * roll + yaw * yaw)


def class_amplitude(angles: np.ndarray, direction: tuple[float, float, float] | None) -> np.ndarray:
    """Amplitude of (..., 3) neutral-subtracted angles: gamma, or the component along ``direction``."""
    angles = np.asarray(angles, dtype=float)
    if direction is None:
        return gamma(angles[..., 0], angles[..., 1], angles[..., 2])
    return angles @ np.asarray(direction)


def sample_amplitude(pitch: float, roll: float, yaw: float, direction: tuple[float, float, float] | None) -> float:
    """``class_amplitude`` of one sample's angles, on Python floats (the streaming chain's every
    decision), with the bits of the (3,)-array form: ``math.sqrt`` rounds correctly as ``np.sqrt``
    does, and a (3,) . (3,) product adds its terms one after the other from 0.0 (the sum written out
    here; tests/test_classifier.py checks both against ``class_amplitude``)."""
    if direction is None:
        return math.sqrt(pitch * pitch + roll * roll + yaw * yaw)
    along_pitch, along_roll, along_yaw = direction
    return 0.0 + pitch * along_pitch + roll * along_roll + yaw * along_yaw


def amplitude_ranges(angles: dict[int, np.ndarray], labels: np.ndarray, class_nodes: dict[int, int],
                     kind: str = "gamma") -> dict[int, AmplitudeRange]:
    """Per non-neutral class: min and max amplitude of its node over the class's training samples.

    ``angles`` maps node index -> (n, 3) neutral-subtracted angles per sample; ``class_nodes`` maps
    label -> node carrying it; ``kind`` is one of AMPLITUDE_KINDS ("along_class": along the unit
    mean of the class's angles).
    """
    if kind not in AMPLITUDE_KINDS:
        raise ValueError(f"amplitude kind must be one of {', '.join(AMPLITUDE_KINDS)}, got {kind!r}")
    ranges = {}
    for label, node in class_nodes.items():
        samples = angles[node][labels == label]
        if label == NEUTRAL_LABEL or len(samples) == 0:
            continue
        direction = None
        if kind == "along_class":
            mean = samples.mean(axis=0)
            direction = tuple(float(v) for v in mean / np.linalg.norm(mean))
        values = class_amplitude(samples, direction)
        ranges[label] = AmplitudeRange(node=node, gamma_min=float(values.min()), gamma_max=float(values.max()),
                                       direction=direction)
    return ranges


def proportional(gamma_value: float, amplitude: AmplitudeRange | None) -> float:
    """nu = (gamma - gamma_min) / (gamma_max - gamma_min), clipped to [0, 1]; 0 for the neutral class.

    The paper writes |gamma - gamma_min|; taken literally, a motion smaller than the least
    calibrated one would drive the arm faster the smaller it gets (and every return to neutral
    through another class's region would move the arm).  Below gamma_min the output is 0.
    """
    if amplitude is None:
        return 0.0
    span = amplitude.gamma_max - amplitude.gamma_min
    if not span > 0.0:  # a degenerate or NaN range gives no speed (model files with one are refused)
        return 0.0
    return min(1.0, max(0.0, gamma_value - amplitude.gamma_min) / span)
