"""User profiles (TOML): the nodes worn and where, the classes and their joystick functions, features,
window, LDA shrinkage, post-processing and the joystick layout the classes drive. ``load_profile("P1")`` resolves the shipped profiles.

Node calibration defaults: node 1 (the headset) gets hardware.md's headset constants; other nodes get
h = 0, C = identity and no mounting rotation unless their ``[nodes.calibration]`` table says otherwise.
"""
from __future__ import annotations

from collections.abc import Mapping
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bomi.classifier import AMPLITUDE_KINDS, MAX_CLASSES, NEUTRAL_LABEL, PostProcessing, ProfileIdentity
from bomi.config_files import check_table, load_toml, number, typed
from bomi.files import write_text
from bomi.features import FEATURE_KINDS, FeatureSpec
from bomi.fusion import NodeCalibration

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
# Live: a button class held this long, then rest, retakes the neutral posture (bomi.gate.RezeroGesture).
# 3 s: over eight deliberate presses' worth (DEFAULT_BUTTON_HOLD_S), so that no press meant as a mode
# change makes it, and short enough for a person who must hold a posture with effort; a profile
# sets its own ([live] rezero_hold_s; 0: no re-zero by gesture).
DEFAULT_REZERO_HOLD_S = 3.0
# The neutral posture is held for seconds, not for hours: more than a minute of samples is a typo.
MAX_NEUTRAL_SAMPLES = 3750

_TOP_KEYS = {"name", "description", "nodes", "classes", "features", "classifier", "neutral", "proportional",
             "post_processing", "joystick", "assist", "live"}
_NODE_KEYS = {"index", "node_id", "site", "calibration"}
_CALIBRATION_KEYS = {"hard_iron", "soft_iron", "mounting"}
_CLASS_KEYS = {"label", "name", "function", "node"}


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
    # profile meets the arm, tasks/operators/assist.py)
    assist: tuple[str, ...] = ()
    button_hold_s: float = DEFAULT_BUTTON_HOLD_S   # [live] button_hold_s
    rezero_hold_s: float = DEFAULT_REZERO_HOLD_S   # [live] rezero_hold_s (0: off)

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
                                                   ("rezero_hold_s", profile.rezero_hold_s, DEFAULT_REZERO_HOLD_S))
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


def _section(data: dict, name: str, allowed: set[str]) -> dict:
    """An optional top-level table (empty when absent) with its keys checked."""
    return check_table(typed(data, name, dict, "profile", {}), name, allowed)


def _parse(data: dict, source: str) -> Profile:
    check_table(data, "profile", _TOP_KEYS)
    nodes = _parse_nodes(typed(data, "nodes", list, "profile"))
    indices = [node.index for node in nodes]
    classes = _parse_classes(typed(data, "classes", list, "profile"), set(indices))
    joystick = _section(data, "joystick", {"layout"})
    classifier = _section(data, "classifier", {"shrinkage", "amplitude_scales", "direction_spread", "rest_offsets"})
    post, select_rejection = _parse_post(_section(data, "post_processing", {"rejection_threshold", "vote_length"}))
    return Profile(name=typed(data, "name", str, "profile"), description=typed(data, "description", str, "profile", ""),
                   nodes=nodes, classes=classes, spec=_parse_spec(_section(data, "features", {"vector", "window", "stride"}),
                                                                  tuple(indices)),
                   shrinkage=_parse_shrinkage(classifier), amplitude_scales=_parse_amplitude_scales(classifier),
                   direction_spread=number(classifier, "direction_spread", "classifier", 0.0, 89.0, default=0.0),
                   rest_offsets=typed(classifier, "rest_offsets", bool, "classifier", False),
                   neutral_samples=_parse_neutral_samples(_section(data, "neutral", {"samples"})),
                   post=post, select_rejection=select_rejection,
                   source=source, amplitude=_parse_amplitude(_section(data, "proportional", {"amplitude"})),
                   joystick_layout=typed(joystick, "layout", str, "joystick", None),
                   assist=_parse_assist(_section(data, "assist", {"options"})),
                   **_parse_live(_section(data, "live", {"button_hold_s", "rezero_hold_s"})))


def _parse_live(live: dict) -> dict:
    button_hold_s = number(live, "button_hold_s", "live", 0.0, 10.0, default=DEFAULT_BUTTON_HOLD_S)
    rezero_hold_s = number(live, "rezero_hold_s", "live", 0.0, 60.0, default=DEFAULT_REZERO_HOLD_S)
    if 0.0 < rezero_hold_s <= button_hold_s:
        raise ValueError(f"[live] rezero_hold_s ({rezero_hold_s:g} s) must be longer than button_hold_s "
                        f"({button_hold_s:g} s), or 0 (off): a press would re-zero")
    return {"button_hold_s": button_hold_s, "rezero_hold_s": rezero_hold_s}


def _parse_nodes(tables: list) -> tuple[NodeConfig, ...]:
    nodes = tuple(_parse_node(t, f"nodes[{k}]") for k, t in enumerate(tables))
    indices = [node.index for node in nodes]
    if not nodes or len(set(indices)) != len(indices) or len({n.node_id for n in nodes}) != len(nodes):
        raise ValueError("nodes: need at least one node, with distinct index and node_id")
    if indices != sorted(indices):
        raise ValueError("nodes: list them in increasing index (the first one carries yaw in FV1)")
    return nodes


def _parse_classes(tables: list, node_indices: set[int]) -> tuple[ClassConfig, ...]:
    """The classes in label order: distinct labels, at least three, exactly one neutral (label 0)."""
    classes = tuple(_parse_class(t, f"classes[{k}]", node_indices) for k, t in enumerate(tables))
    labels = [cls.label for cls in classes]
    if len(set(labels)) != len(labels):
        raise ValueError("classes: duplicate label")
    if not 3 <= len(classes) <= MAX_CLASSES:
        raise ValueError(f"classes: need three to {MAX_CLASSES} classes (neutral and at least two motions), "
                         f"got {len(classes)}")
    neutral = [cls for cls in classes if cls.function == NEUTRAL_FUNCTION]
    if len(neutral) != 1 or neutral[0].label != NEUTRAL_LABEL:
        raise ValueError(f"classes: exactly one class, label {NEUTRAL_LABEL}, must have function \"neutral\"")
    return tuple(sorted(classes, key=lambda c: c.label))


def _parse_spec(features: dict, nodes: tuple[int, ...]) -> FeatureSpec:
    kind = typed(features, "vector", str, "features", "FV3")
    if kind not in FEATURE_KINDS:
        raise ValueError(f"features: vector must be one of {', '.join(FEATURE_KINDS)}, got {kind!r}")
    return FeatureSpec(kind=kind, nodes=nodes, window=typed(features, "window", int, "features", 8),
                       stride=typed(features, "stride", int, "features", 1))


def _parse_shrinkage(classifier: dict) -> float | str | None:
    shrinkage = typed(classifier, "shrinkage", (str, float, int), "classifier", "none")
    if isinstance(shrinkage, str):
        if shrinkage not in ("auto", "none", SELECT):
            raise ValueError(f"classifier: shrinkage must be \"{SELECT}\", \"auto\", \"none\" or a number in [0, 1], "
                             f"got {shrinkage!r}")
        return None if shrinkage == "none" else shrinkage
    if not 0.0 <= shrinkage <= 1.0:
        raise ValueError(f"classifier: shrinkage must be in [0, 1], got {shrinkage}")
    return shrinkage


def _parse_amplitude_scales(classifier: dict) -> tuple[float, ...]:
    scales = typed(classifier, "amplitude_scales", list, "classifier", [])
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 < v < 1.0 for v in scales):
        raise ValueError(f"classifier: amplitude_scales must be fractions in (0, 1), got {scales!r}")
    return tuple(float(v) for v in scales)


def _parse_neutral_samples(neutral: dict) -> int:
    samples = typed(neutral, "samples", int, "neutral", DEFAULT_NEUTRAL_SAMPLES)
    if not 1 <= samples <= MAX_NEUTRAL_SAMPLES:
        raise ValueError(f"neutral: samples must be in [1, {MAX_NEUTRAL_SAMPLES}] (a minute at 62.5 Hz), got {samples}")
    return samples


def _parse_amplitude(proportional: dict) -> str:
    amplitude = typed(proportional, "amplitude", str, "proportional", "gamma")
    if amplitude not in AMPLITUDE_KINDS:
        raise ValueError(f"proportional: amplitude must be one of {', '.join(AMPLITUDE_KINDS)}, got {amplitude!r}")
    return amplitude


def _parse_post(post: dict) -> tuple[PostProcessing, bool]:
    """The post-processing, and whether its rejection threshold is left to the training recording."""
    threshold = typed(post, "rejection_threshold", (float, int, str), "post_processing", None)
    if isinstance(threshold, str) and threshold != SELECT:
        raise ValueError(f"post_processing: rejection_threshold must be a number in (0, 1) or \"{SELECT}\", "
                         f"got {threshold!r}")
    return (PostProcessing(rejection_threshold=None if threshold == SELECT else threshold,
                           vote_length=typed(post, "vote_length", int, "post_processing", 1)), threshold == SELECT)


def _parse_assist(assist: dict) -> tuple[str, ...]:
    options = typed(assist, "options", list, "assist", [])
    if not all(isinstance(name, str) for name in options):
        raise ValueError(f"assist: options must be a list of names, got {options!r}")
    return tuple(options)


def _parse_node(table: Any, where: str) -> NodeConfig:
    check_table(table, where, _NODE_KEYS)
    index = typed(table, "index", int, where)
    if not 1 <= index <= 6:
        raise ValueError(f"{where}: index must be in 1..6, got {index}")
    default = NodeCalibration.default_for(index)
    calibration = check_table(typed(table, "calibration", dict, where, {}), f"{where}.calibration", _CALIBRATION_KEYS)
    try:
        cal = NodeCalibration(hard_iron=calibration.get("hard_iron", default.hard_iron),
                              soft_iron=calibration.get("soft_iron", default.soft_iron),
                              mounting=calibration.get("mounting", default.mounting))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}.calibration: {exc}") from None
    return NodeConfig(index=index, node_id=typed(table, "node_id", int, where),
                      site=typed(table, "site", str, where), calibration=cal)


def _parse_class(table: Any, where: str, node_indices: set[int]) -> ClassConfig:
    check_table(table, where, _CLASS_KEYS)
    label = typed(table, "label", int, where)
    if label < 0:
        raise ValueError(f"{where}: label must be >= 0")
    function = typed(table, "function", str, where)
    node = typed(table, "node", int, where, None)
    if function != NEUTRAL_FUNCTION and node is None:
        raise ValueError(f"{where}: a motion class needs 'node' (the node that carries it)")
    if node is not None and node not in node_indices:
        raise ValueError(f"{where}: node {node} is not one of the profile's nodes {sorted(node_indices)}")
    return ClassConfig(label=label, name=typed(table, "name", str, where), function=function, node=node)
