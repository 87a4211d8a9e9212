"""Training preparation: node states from a recording, cut into windows for one feature spec.

Node state = neutral-subtracted (pitch, roll, yaw) + gyroscope as the recording holds it (raw LSB).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bomi.errors import BomiError
from bomi.features import NODE_STATE, FeatureSpec, single_label_windows, window_ends
from bomi.features import window_features as batch_window_features
from bomi.fusion import neutral_offsets
from bomi.recording import Recording, Signal

NODE_WIDTH = len(NODE_STATE)   # columns per node in the node states


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

