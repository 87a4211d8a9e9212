"""User profiles (TOML): the nodes worn and where, the classes and their joystick functions, features,
window, LDA shrinkage, post-processing and the joystick layout the classes drive. ``load_profile("P1")`` resolves the shipped profiles.

Node calibration defaults: node 1 (the headset) gets hardware.md's headset constants; other nodes get
h = 0, C = identity and no mounting rotation unless their ``[nodes.calibration]`` table says otherwise.

A file is read by ``bomi.config_files``: each of its tables is a dataclass below (``_ProfileFile``),
its faults one line ``path: [section] key: ...``; ``_parse`` then checks what spans tables (nodes and
classes) and builds the ``Profile``.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bomi.classifier import AMPLITUDE_KINDS, MAX_CLASSES, NEUTRAL_LABEL, PostProcessing, ProfileIdentity
from bomi.config_files import from_table, load_toml
from bomi.files import write_text
from bomi.features import FEATURE_KINDS, FeatureSpec
from bomi.fusion import Matrix3, NodeCalibration, Vector3

PROFILE_DIR = Path(__file__).resolve().parent
# A class's function and the profile's joystick layout are names of the device the classes drive
# (the JACO's stick: sim/joystick.py, checked where a profile meets the arm, tasks/operators/stick.py); the
# chain passes them through untouched. Only the neutral class's function means something here.
NEUTRAL_FUNCTION = "neutral"
# A classifier setting left to the person's own training recording (bomi.chain.select_settings).
SELECT = "select"
DEFAULT_NEUTRAL_SAMPLES = 100  # hardware.md step 6: about 100 samples of the neutral posture
# Live: a button class (B1, B2) acts only once decided for this long without a break (bomi.gate.ButtonEvidence).
# A corrupted sample sways the decisions of the windows holding it (8 samples, 128 ms) and then the
# pitch/roll filter's decay (time constant 12.5 samples, 200 ms): 0.35 s outlasts both, and costs a
# deliberate press 0.35 s.
DEFAULT_BUTTON_HOLD_S = 0.35
# Live: a button class held this long, then rest, retakes the neutral posture (bomi.gate.LongPressGesture).
# 3 s: over eight deliberate presses' worth (DEFAULT_BUTTON_HOLD_S), so that no press meant as a mode
# change makes it, and short enough for a person who must hold a posture with effort; a profile
# sets its own ([live] rezero_hold_s; 0: no re-zero by gesture).
DEFAULT_REZERO_HOLD_S = 3.0
# Live: a button class held this long, then rest, asks for a recalibration (the calibration protocol
# once, the classifier retrained: tasks.trials.recalibration). 8 s: well past the re-zero's 3 s, so
# that a re-zero held a little long stays a re-zero, and still a hold a person can make on purpose;
# [live] recalibrate_hold_s (0: off).
DEFAULT_RECALIBRATE_HOLD_S = 8.0
# The neutral posture is held for seconds, not for hours: more than a minute of samples is a typo.
MAX_NEUTRAL_SAMPLES = 3750

@dataclass(frozen=True)
class NodeConfig:
    index: int            # 1..6, the column suffix in recordings; node 1 carries yaw in FV1
    node_id: int          # the base station's id for it (10, 11, 12, ...)
    site: str
    calibration: NodeCalibration


@dataclass(frozen=True)
class ClassConfig:
    label: int
    name: str
    function: str         # the device function the class drives, or "neutral" for c0
    node: int | None      # the node whose gamma gives the class's proportional output


@dataclass(frozen=True)
class Profile:
    name: str
    description: str
    nodes: tuple[NodeConfig, ...]
    classes: tuple[ClassConfig, ...]
    spec: FeatureSpec
    shrinkage: float | str | None
    neutral_samples: int
    post: PostProcessing
    source: str
    amplitude: str = "gamma"  # proportional output: one of bomi.classifier.AMPLITUDE_KINDS
    joystick_layout: str | None = None  # the device's layout the classes drive (None: the device's default)
    select_rejection: bool = False  # rejection threshold chosen on the training recording (post.rejection_threshold unused)
    amplitude_scales: tuple[float, ...] = ()  # training also sees every motion at these fractions of its size
    # training also sees each motion alone on its carrying node turned by +-this many degrees about
    # the neutral posture (bomi.chain.MotionCopies); 0: off
    direction_spread: float = 0.0
    # training also sees every window measured from other rests, as far as the person's own rests
    # scatter (bomi.chain.rest_offsets); [classifier] rest_offsets
    rest_offsets: bool = False
    # the assistances on unless a run says otherwise ([assist] options; names checked where the
    # profile meets the arm, tasks/operators/assist/options.py)
    assist: tuple[str, ...] = ()
    button_hold_s: float = DEFAULT_BUTTON_HOLD_S   # [live] button_hold_s
    rezero_hold_s: float = DEFAULT_REZERO_HOLD_S   # [live] rezero_hold_s (0: off)
    recalibrate_hold_s: float = DEFAULT_RECALIBRATE_HOLD_S   # [live] recalibrate_hold_s (0: off)

    @property
    def node_indices(self) -> tuple[int, ...]:
        return tuple(node.index for node in self.nodes)

    @property
    def class_nodes(self) -> dict[int, int]:
        return {cls.label: cls.node for cls in self.classes if cls.node is not None}

    @property
    def lone_class_nodes(self) -> dict[int, int]:
        """Motion class -> carrying node, for the classes that are the only one their node carries:
        there the node's direction only tells the motion from the neutral posture, not from another motion."""
        nodes = list(self.class_nodes.values())
        return {label: node for label, node in self.class_nodes.items() if nodes.count(node) == 1}

    @property
    def identity(self) -> ProfileIdentity:
        """Name + SHA-256 of what decides how a model trained for this profile moves the arm:
        nodes (index, id, calibration), classes (label, joystick function, carrying node), features,
        amplitude kind and joystick layout. Names, sites, descriptions and post-processing are left
        out: changing them does not change what a decision does."""
        content = {
            "nodes": [[n.index, n.node_id, n.calibration.hard_iron, n.calibration.soft_iron, n.calibration.mounting]
                      for n in self.nodes],
            "classes": [[c.label, c.function, c.node] for c in self.classes],
            "features": [self.spec.kind, list(self.spec.nodes), self.spec.window, self.spec.stride],
            "amplitude": self.amplitude,
            "joystick_layout": self.joystick_layout,
        }
        digest = hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()
        return ProfileIdentity(self.name, digest)


def load_profile(path_or_name: str | Path, overrides: Mapping[str, Any] | None = None) -> Profile:
    """Load and validate a profile file, or a shipped one by name (P1, P4, P5); ``overrides``: dotted
    keys set before validation (``{"post_processing.rejection_threshold": 0.99}``)."""
    return load_toml(path_or_name, PROFILE_DIR, "profile", _parse, overrides)


def profile_document(profile: Profile) -> dict:
    """The TOML document ``load_profile`` reads back as ``profile`` (all but its ``source``)."""
    classifier = {"shrinkage": "none" if profile.shrinkage is None else profile.shrinkage}
    if profile.amplitude_scales:
        classifier["amplitude_scales"] = list(profile.amplitude_scales)
    if profile.direction_spread:
        classifier["direction_spread"] = profile.direction_spread
    if profile.rest_offsets:
        classifier["rest_offsets"] = True
    post: dict[str, Any] = {"vote_length": profile.post.vote_length}
    if profile.select_rejection or profile.post.rejection_threshold is not None:
        post["rejection_threshold"] = SELECT if profile.select_rejection else profile.post.rejection_threshold
    doc: dict[str, Any] = {
        "name": profile.name, "description": profile.description,
        "features": {"vector": profile.spec.kind, "window": profile.spec.window, "stride": profile.spec.stride},
        "classifier": classifier, "neutral": {"samples": profile.neutral_samples},
        "proportional": {"amplitude": profile.amplitude}, "post_processing": post}
    if profile.joystick_layout is not None:
        doc["joystick"] = {"layout": profile.joystick_layout}
    if profile.assist:
        doc["assist"] = {"options": list(profile.assist)}
    live = {key: value for key, value, default in (("button_hold_s", profile.button_hold_s, DEFAULT_BUTTON_HOLD_S),
                                                   ("rezero_hold_s", profile.rezero_hold_s, DEFAULT_REZERO_HOLD_S),
                                                   ("recalibrate_hold_s", profile.recalibrate_hold_s,
                                                    DEFAULT_RECALIBRATE_HOLD_S))
            if value != default}
    if live:
        doc["live"] = live
    doc["nodes"] = [{"index": n.index, "node_id": n.node_id, "site": n.site,
                     "calibration": {"hard_iron": list(n.calibration.hard_iron),
                                     "soft_iron": [list(row) for row in n.calibration.soft_iron],
                                     "mounting": [list(row) for row in n.calibration.mounting]}}
                    for n in profile.nodes]
    doc["classes"] = [{"label": c.label, "name": c.name, "function": c.function} | ({} if c.node is None else {"node": c.node})
                      for c in profile.classes]
    return doc


def save_profile(path: str | Path, profile: Profile, *, overwrite: bool = False) -> None:
    """Write ``profile`` as a TOML file (atomically; an existing file only with ``overwrite``)."""
    import tomli_w

    header = f"# profile written by bomi from: {profile.source}\n"
    write_text(path, header + tomli_w.dumps(profile_document(profile)), overwrite=overwrite)


# ------------------------------------------------------------------- the file's tables (bomi.config_files)
@dataclass(frozen=True)
class _Calibration:
    """[nodes.calibration]: what is absent is the node's default (``NodeCalibration.default_for``)."""

    hard_iron: Vector3 | None = None
    soft_iron: Matrix3 | None = None
    mounting: Matrix3 | None = None


@dataclass(frozen=True)
class _Node:
    index: int
    node_id: int
    site: str
    calibration: _Calibration = _Calibration()

    def __post_init__(self) -> None:
        if not 1 <= self.index <= 6:
            raise ValueError(f"index: must be in 1..6, got {self.index}")

    def config(self, where: str) -> NodeConfig:
        """The node, its calibration completed by the defaults (``where``: the table's name in errors)."""
        default = NodeCalibration.default_for(self.index)
        given = self.calibration
        try:
            calibration = NodeCalibration(
                hard_iron=default.hard_iron if given.hard_iron is None else given.hard_iron,
                soft_iron=default.soft_iron if given.soft_iron is None else given.soft_iron,
                mounting=default.mounting if given.mounting is None else given.mounting)
        except ValueError as exc:
            raise ValueError(f"[{where}.calibration] {exc}") from None
        return NodeConfig(self.index, self.node_id, self.site, calibration)


@dataclass(frozen=True)
class _Class:
    label: int
    name: str
    function: str
    node: int | None = None   # the node that carries a motion class

    def __post_init__(self) -> None:
        if self.label < 0:
            raise ValueError(f"label: must be >= 0, got {self.label}")
        if self.function != NEUTRAL_FUNCTION and self.node is None:
            raise ValueError("node: a motion class needs 'node' (the node that carries it)")


@dataclass(frozen=True)
class _Features:
    vector: str = "FV3"
    window: int = 8
    stride: int = 1

    def __post_init__(self) -> None:
        if self.vector not in FEATURE_KINDS:
            raise ValueError(f"vector: must be one of {', '.join(FEATURE_KINDS)}, got {self.vector!r}")


@dataclass(frozen=True)
class _Classifier:
    shrinkage: float | str = "none"
    amplitude_scales: tuple[float, ...] = ()
    direction_spread: float = 0.0
    rest_offsets: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.shrinkage, str) and self.shrinkage not in ("auto", "none", SELECT):
            raise ValueError(f"shrinkage: must be \"{SELECT}\", \"auto\", \"none\" or a number in [0, 1], "
                             f"got {self.shrinkage!r}")
        if not isinstance(self.shrinkage, str) and not 0.0 <= self.shrinkage <= 1.0:
            raise ValueError(f"shrinkage: must be in [0, 1], got {self.shrinkage}")
        if not all(0.0 < v < 1.0 for v in self.amplitude_scales):
            raise ValueError(f"amplitude_scales: must be fractions in (0, 1), got {list(self.amplitude_scales)!r}")
        if not 0.0 <= self.direction_spread <= 89.0:
            raise ValueError(f"direction_spread: must be in [0, 89] degrees, got {self.direction_spread}")


@dataclass(frozen=True)
class _Neutral:
    samples: int = DEFAULT_NEUTRAL_SAMPLES

    def __post_init__(self) -> None:
        if not 1 <= self.samples <= MAX_NEUTRAL_SAMPLES:
            raise ValueError(f"samples: must be in [1, {MAX_NEUTRAL_SAMPLES}] (a minute at 62.5 Hz), "
                             f"got {self.samples}")


@dataclass(frozen=True)
class _Proportional:
    amplitude: str = "gamma"

    def __post_init__(self) -> None:
        if self.amplitude not in AMPLITUDE_KINDS:
            raise ValueError(f"amplitude: must be one of {', '.join(AMPLITUDE_KINDS)}, got {self.amplitude!r}")


@dataclass(frozen=True)
class _PostProcessing:
    rejection_threshold: float | str | None = None   # or SELECT: chosen on the training recording
    vote_length: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.rejection_threshold, str) and self.rejection_threshold != SELECT:
            raise ValueError(f"rejection_threshold: must be a number in (0, 1) or \"{SELECT}\", "
                             f"got {self.rejection_threshold!r}")

    def post(self) -> PostProcessing:
        threshold = None if self.rejection_threshold == SELECT else self.rejection_threshold
        return PostProcessing(rejection_threshold=threshold, vote_length=self.vote_length)


@dataclass(frozen=True)
class _Joystick:
    layout: str | None = None


@dataclass(frozen=True)
class _Assist:
    options: tuple[str, ...] = ()


@dataclass(frozen=True)
class _Live:
    button_hold_s: float = DEFAULT_BUTTON_HOLD_S
    rezero_hold_s: float = DEFAULT_REZERO_HOLD_S
    recalibrate_hold_s: float = DEFAULT_RECALIBRATE_HOLD_S

    def __post_init__(self) -> None:
        if not 0.0 <= self.button_hold_s <= 10.0:
            raise ValueError(f"button_hold_s: must be in [0, 10] s, got {self.button_hold_s}")
        if not 0.0 <= self.rezero_hold_s <= 60.0:
            raise ValueError(f"rezero_hold_s: must be in [0, 60] s, got {self.rezero_hold_s}")
        if 0.0 < self.rezero_hold_s <= self.button_hold_s:
            raise ValueError(f"rezero_hold_s: {self.rezero_hold_s:g} s must be longer than button_hold_s "
                             f"({self.button_hold_s:g} s), or 0 (off): a press would re-zero")
        if not 0.0 <= self.recalibrate_hold_s <= 60.0:
            raise ValueError(f"recalibrate_hold_s: must be in [0, 60] s, got {self.recalibrate_hold_s}")
        if 0.0 < self.recalibrate_hold_s <= max(self.rezero_hold_s, self.button_hold_s):
            raise ValueError(f"recalibrate_hold_s: {self.recalibrate_hold_s:g} s must be longer than rezero_hold_s "
                             f"({self.rezero_hold_s:g} s) and button_hold_s ({self.button_hold_s:g} s), or 0 (off)")


@dataclass(frozen=True)
class _ProfileFile:
    """A profile file as written: its top-level keys and tables."""

    name: str
    nodes: tuple[_Node, ...]
    classes: tuple[_Class, ...]
    description: str = ""
    features: _Features = _Features()
    classifier: _Classifier = _Classifier()
    neutral: _Neutral = _Neutral()
    proportional: _Proportional = _Proportional()
    post_processing: _PostProcessing = _PostProcessing()
    joystick: _Joystick = _Joystick()
    assist: _Assist = _Assist()
    live: _Live = _Live()


def _parse(data: dict, source: str) -> Profile:
    file = from_table(_ProfileFile, data)
    nodes = _parse_nodes(file.nodes)
    indices = tuple(node.index for node in nodes)
    classes = _parse_classes(file.classes, set(indices))
    features = file.features
    try:
        spec = FeatureSpec(kind=features.vector, nodes=indices, window=features.window, stride=features.stride)
    except ValueError as exc:
        raise ValueError(f"[features] {exc}") from None
    try:
        post = file.post_processing.post()
    except ValueError as exc:
        raise ValueError(f"[post_processing] {exc}") from None
    classifier = file.classifier
    return Profile(name=file.name, description=file.description, nodes=nodes, classes=classes, spec=spec,
                   shrinkage=None if classifier.shrinkage == "none" else classifier.shrinkage,
                   amplitude_scales=classifier.amplitude_scales, direction_spread=classifier.direction_spread,
                   rest_offsets=classifier.rest_offsets, neutral_samples=file.neutral.samples,
                   post=post, select_rejection=file.post_processing.rejection_threshold == SELECT,
                   source=source, amplitude=file.proportional.amplitude, joystick_layout=file.joystick.layout,
                   assist=file.assist.options, button_hold_s=file.live.button_hold_s,
                   rezero_hold_s=file.live.rezero_hold_s, recalibrate_hold_s=file.live.recalibrate_hold_s)


def _parse_nodes(tables: tuple[_Node, ...]) -> tuple[NodeConfig, ...]:
    nodes = [table.config(f"nodes[{k}]") for k, table in enumerate(tables)]
    indices = [node.index for node in nodes]
    if not nodes or len(set(indices)) != len(indices) or len({n.node_id for n in nodes}) != len(nodes):
        raise ValueError("[[nodes]]: need at least one node, with distinct index and node_id")
    if indices != sorted(indices):
        raise ValueError("[[nodes]]: list them in increasing index (the first one carries yaw in FV1)")
    return tuple(nodes)


def _parse_classes(tables: tuple[_Class, ...], node_indices: set[int]) -> tuple[ClassConfig, ...]:
    """The classes in label order: distinct labels, at least three, exactly one neutral (label 0)."""
    for k, cls in enumerate(tables):
        if cls.node is not None and cls.node not in node_indices:
            raise ValueError(f"[classes[{k}]] node: {cls.node} is not one of the profile's nodes "
                             f"{sorted(node_indices)}")
    classes = tuple(ClassConfig(label=c.label, name=c.name, function=c.function, node=c.node) for c in tables)
    labels = [cls.label for cls in classes]
    if len(set(labels)) != len(labels):
        raise ValueError("[[classes]]: duplicate label")
    if not 3 <= len(classes) <= MAX_CLASSES:
        raise ValueError(f"[[classes]]: need three to {MAX_CLASSES} classes (neutral and at least two motions), "
                         f"got {len(classes)}")
    neutral = [cls for cls in classes if cls.function == NEUTRAL_FUNCTION]
    if len(neutral) != 1 or neutral[0].label != NEUTRAL_LABEL:
        raise ValueError(f"[[classes]]: exactly one class, label {NEUTRAL_LABEL}, must have function \"neutral\"")
    return tuple(sorted(classes, key=lambda c: c.label))
