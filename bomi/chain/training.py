"""Training: the checks on the recordings before any fitting, and the fit of the classifier."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from bomi.chain.copies import MotionCopies, training_windows
from bomi.chain.holds import MoveAllowances
from bomi.chain.selection import Selection, select_settings
from bomi.chain.windows import NODE_WIDTH, recorded_priors, require_for
from bomi.classifier import (Model, PostProcessing, amplitude_ranges, fit_pipeline, model_defects,
                             pipeline_parameters)
from bomi.errors import BomiError
from bomi.features import FeatureSpec, single_label_windows, window_ends
from bomi.passes import training_digests
from bomi.profiles import SELECT, Profile
from bomi.recording import Recording


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


def _on_hold(rec: Recording, spec: FeatureSpec) -> np.ndarray:
    """(n,) True at the rows where the person holds the cued posture: every row of a recording that keeps
    only its holds; where it keeps its moves, all but those from a cue to its move's measured offset
    (``MoveAllowances``). The amplitude range is the one of the postures held (hardware.md: taken during
    calibration), not of the way into them, whose windows would set gamma_min near 0 (any lean would
    then drive the arm)."""
    allowances = MoveAllowances.of(rec, spec.nodes)
    return np.ones(len(rec), dtype=bool) if allowances is None else allowances.on_hold(len(rec))


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
        held = windows.recorded & _on_hold(rec, spec)[windows.ends]
        ends = windows.ends[held]   # amplitude ranges: the recorded motions only, as held
        recorded_labels.append(windows.labels[held])
        for k, i in enumerate(spec.nodes):
            angles[i].append(prepared.states[ends, k * NODE_WIDTH:k * NODE_WIDTH + 3])
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
