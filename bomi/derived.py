"""A profile derived from a person's labelled recording(s), for `bomi train` / `evaluate` without --profile.

What the recording holds decides: its nodes (those with angles in every recording), the feature
vector (FV3 when every such node has its gyroscope, else FV1), its labels (c0 is the neutral
posture; the motions c1, c2, ... take, in label order, the functions of the joystick layout their
number allows, ``derived_layout``: the stacking task needs translation, wrist and fingers),
and the node that carries each motion (the one whose mean angle change from neutral is largest
over the class's samples). Classifier settings are left to the person's own data
(``shrinkage = "select"``, ``rejection_threshold = "select"``): the plain setting unless the
cross-validation on the training recording earns an extra its place, the extras being LDA
shrinkage, training also on every motion at 3/4 and 1/2 of its recorded size (the paper's
multiple-amplitude training), and rejection (``bomi.chain.select_settings``, docs/signal_chain.md).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from bomi.classifier import NEUTRAL_LABEL, PostProcessing
from bomi.errors import BomiError
from bomi.features import FeatureSpec
from bomi.fusion import (MOUNTING_AGREE_DEG, NodeCalibration, agreeing_mounting, angle_disagreement, fuse,
                         neutral_offsets)
from bomi.paper import CLASS_FUNCTIONS
from bomi.profiles import DEFAULT_NEUTRAL_SAMPLES, NEUTRAL_FUNCTION, SELECT, ClassConfig, NodeConfig, Profile
from bomi.recording import NodeData, Recording, Signal

DERIVED_AMPLITUDE_SCALES = (0.75, 0.5)
MOUNTING_ROWS = 20_000   # at most the rows a node's mounting is checked on (5 min: the protocol's motions disambiguate it)
THREE_AXIS, TWO_AXIS, ONE_AXIS = "3-axis", "2-axis", "1-axis"   # the layouts' names (sim/joystick.py LAYOUTS)
AUTO_MODE = "auto-mode"                     # tasks/assist.py Assist.AUTO_MODE
# each layout's directions, the richest first
_DIRECTIONS = {THREE_AXIS: ("F", "B", "R", "L", "Rr", "Lr"), TWO_AXIS: ("F", "B", "R", "L"), ONE_AXIS: ("F", "B")}
_WORDS = {6: "six", 4: "four", 2: "two"}   # their numbers of directions, as the reasons say them


@dataclass(frozen=True)
class DerivedLayout:
    """How a person's motions drive the arm: the layout, each motion's function in label order, the
    assistances on, and why."""

    layout: str
    functions: tuple[str, ...]
    assist: tuple[str, ...]
    reason: str


def derived_layout(motions: int) -> DerivedLayout:
    """The layout that reaches translation, wrist and fingers with ``motions`` classes (2..8): the
    richest layout whose directions the motions cover (3-axis: six, 2-axis: four, 1-axis: F/B), the
    motions left over being the mode buttons (B1 forward, B2 back); with none left, the modes change
    by themselves (automatic mode switching, tasks/assist.py: the user rests and waits for them).
    The 3-axis layout only with a button: six motions take the 2-axis layout and both buttons."""
    richer = None   # the next richer layout, whose directions and a button the motions do not cover
    for layout, directions in _DIRECTIONS.items():
        spare = motions - len(directions)
        if spare >= 1 or (spare == 0 and layout != THREE_AXIS):
            break
        richer = layout
    buttons = ("B1", "B2")[:spare]
    own = f"the {layout} layout's {_WORDS[len(directions)]} directions"
    if buttons:
        fewer = "" if richer is None else \
            f"too few for the {richer} layout's {_WORDS[len(_DIRECTIONS[richer])]} directions and a mode button; "
        return DerivedLayout(layout, directions + buttons, (), f"{motions} motions: {fewer}{own} and {' and '.join(buttons)}")
    return DerivedLayout(layout, directions, (AUTO_MODE,),
                         f"{motions} motions: {own}, no class left for a mode button; "
                         "the modes are switched automatically (--assist auto-mode)")


_BASE_STATION_FIRST_IMU = 10   # node index i is base-station id 10 + i - 1 (hardware.md)


def derive_profile(recordings: Sequence[Recording]) -> Profile:
    """The profile the recordings imply; one-line BomiError when they cannot make one."""
    first = recordings[0]
    nodes = [i for i in first.node_indices if all(i in rec.nodes and rec.nodes[i].angles is not None
                                                   for rec in recordings)]
    if not nodes:
        first.require(first.node_indices, (Signal.ANGLES,), "training")
    labels = sorted(set().union(*(set(rec.require_labels().tolist()) for rec in recordings)))
    motions = [label for label in labels if label != NEUTRAL_LABEL]
    if NEUTRAL_LABEL not in labels or len(motions) < 2:
        raise BomiError(f"{first.source}: a profile is derived from labels 0 (neutral posture) and at least two "
                        f"motions, the recording has labels {labels}")
    if len(motions) > len(CLASS_FUNCTIONS):
        raise BomiError(f"{first.source}: {len(motions)} motion classes, more than the {len(CLASS_FUNCTIONS)} "
                        "joystick functions (give a --profile)")
    for rec in recordings:
        if len(rec) < DEFAULT_NEUTRAL_SAMPLES:
            raise BomiError(f"{rec.source}: {len(rec)} samples, fewer than the {DEFAULT_NEUTRAL_SAMPLES} of the "
                            "neutral-offset calibration")
    gyro = all(rec.nodes[i].gyro is not None for rec in recordings for i in nodes)
    carriers = _carrying_nodes(recordings, nodes, motions)
    layout = derived_layout(len(motions))
    classes = (ClassConfig(NEUTRAL_LABEL, "c0", NEUTRAL_FUNCTION, None),) + tuple(
        ClassConfig(label, f"c{label}", function, carriers[label]) for label, function in zip(motions, layout.functions))
    calibrations = {i: node_calibration(first, i) for i in nodes}
    mounted = [f"node {i} mounting {calibrations[i].mounting} (the one its own angle columns agree with)"
               for i in nodes if calibrations[i] != NodeCalibration.default_for(i)]
    return Profile(
        name="derived", description=f"derived from the recording: its nodes, its labels, generic class names; "
                                    + "".join(f"{m}; " for m in mounted) + f"layout {layout.layout}: {layout.reason}",
        joystick_layout=layout.layout, assist=layout.assist,
        nodes=tuple(NodeConfig(i, _BASE_STATION_FIRST_IMU + i - 1, f"node {i}", calibrations[i]) for i in nodes),
        classes=classes, spec=FeatureSpec("FV3" if gyro else "FV1", tuple(nodes)), shrinkage=SELECT,
        neutral_samples=DEFAULT_NEUTRAL_SAMPLES, post=PostProcessing(), source=f"derived from {first.source}",
        amplitude="along_class",
        select_rejection=True, amplitude_scales=DERIVED_AMPLITUDE_SCALES)


def node_calibration(rec: Recording, node: int) -> NodeCalibration:
    """The node's default calibration (the headset's for node 1), with the axis mounting its own angle
    columns agree with when they disagree with the default's by more than MOUNTING_AGREE_DEG and the
    recording has the raw signals to tell (``bomi.fusion.agreeing_mounting``): live, the angles are
    fused from the raw signals, and must be those the model was trained on."""
    default = NodeCalibration.default_for(node)
    signals = (Signal.ACC, Signal.GYRO, Signal.MAG, Signal.ANGLES)
    if any(getattr(rec.nodes[node], s.value) is None for s in signals):
        return default
    data = NodeData(**{s.value: getattr(rec.nodes[node], s.value)[:MOUNTING_ROWS] for s in signals})
    pitch, roll, yaw = fuse(data.acc, data.gyro, data.mag, default)
    if angle_disagreement(data.angles, np.column_stack([pitch, roll, yaw])).max() <= MOUNTING_AGREE_DEG:
        return default
    mounting, left = agreeing_mounting(data, default)
    return replace(default, mounting=mounting) if left.max() <= MOUNTING_AGREE_DEG else default


def _carrying_nodes(recordings: Sequence[Recording], nodes: Sequence[int], motions: Sequence[int]) -> dict[int, int]:
    """Per motion label: the node whose mean neutral-subtracted angles over the class are largest."""
    size = {}
    for label in motions:
        means = []
        for i in nodes:
            changes = [rec.nodes[i].angles[rec.labels == label] - neutral_offsets(rec.nodes[i].angles, DEFAULT_NEUTRAL_SAMPLES)
                       for rec in recordings]
            changes = np.concatenate(changes)
            means.append(float(np.linalg.norm(changes.mean(axis=0))) if len(changes) else 0.0)
        size[label] = nodes[int(np.argmax(means))]
    return size


def describe(profile: Profile) -> str:
    """One line: what a derived profile holds."""
    kind = profile.spec.kind
    classes = ", ".join(f"c{c.label} {c.function}" + ("" if c.node is None else f" (node {c.node})")
                        for c in profile.classes)
    scales = ", ".join(f"{s:g}" for s in profile.amplitude_scales)
    layout = derived_layout(sum(c.function != NEUTRAL_FUNCTION for c in profile.classes))
    return (f"no --profile: {profile.source}: node(s) {list(profile.node_indices)}, {kind} "
            f"({'angles + GYRO' if kind != 'FV1' else 'angles: the recording has no GYRO'}), classes {classes}; "
            f"layout {layout.layout}{' + ' + ', '.join(layout.assist) if layout.assist else ''} ({layout.reason}); "
            f"classifier plain unless the cross-validation on the training recording earns an extra its place "
            f"(shrinkage, motions also trained at {scales} of their size, rejection)")
