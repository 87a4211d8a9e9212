"""Synthesised training copies of the recorded motions: smaller, turned, and measured from other rests."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import hadamard

from bomi.chain.holds import as_held
from bomi.chain.windows import NODE_WIDTH, PreparedRecording, TrainingWindows, prepare, window_features
from bomi.classifier import NEUTRAL_LABEL
from bomi.features import FeatureSpec, feature_columns
from bomi.features import window_features as batch_window_features
from bomi.neutral import rest_spread
from bomi.profiles import Profile
from bomi.recording import Recording


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
    angles = states[:, slot * NODE_WIDTH:slot * NODE_WIDTH + 3]
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
    Where the recording keeps its moves, a window is labelled by the posture held (``holds.as_held``):
    the rows between a cue and the person's measured movement onset are the posture before the cue.
    """
    rec = as_held(rec, spec.nodes)
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
        angle_columns = np.array([slot * NODE_WIDTH + axis for slot in range(len(spec.nodes)) for axis in range(3)])
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
            parts.append((_with_states(prepared, spec, slot * NODE_WIDTH + np.arange(3), angles, windows),
                          prepared.labels[windows],
                          prepared.ends[windows], False))
    windows = TrainingWindows(*(np.concatenate([part[k] for part in parts]) for k in range(3)),
                              np.concatenate([np.full(len(part[1]), part[3]) for part in parts]))
    return windows, prepared
