"""A profile derived from a person's labelled recording(s), for `bomi train` / `evaluate` without --profile.

What the recording holds decides: its nodes (those with angles in every recording), the feature
vector (FV3 when every such node has its gyroscope, else FV1), its labels (c0 is the neutral
posture; the motions c1, c2, ... take the functions of the joystick layout their number allows,
``derived_layout``: the stacking task needs translation, wrist and fingers; the mode buttons go to
the motions no other motion passes near on its way from the neutral posture, ``button_motions``,
the directions to the rest in label order), and the node that carries each motion (the one whose
mean angle change from neutral is largest over the class's samples). Classifier settings are left to the person's own data
(``shrinkage = "select"``, ``rejection_threshold = "select"``): the plain setting unless the
cross-validation on the training recording earns an extra its place, the extras being LDA
shrinkage, training also on every motion at 3/4 and 1/2 of its recorded size (the paper's
multiple-amplitude training), and rejection (``bomi.chain.select_settings``, docs/signal_chain.md).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from bomi.chain import choose_rest_offsets
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
AUTO_MODE = "auto-mode"                     # tasks/operators/assist.py Assist.AUTO_MODE
# each layout's directions, the richest first
_DIRECTIONS = {THREE_AXIS: ("F", "B", "R", "L", "Rr", "Lr"), TWO_AXIS: ("F", "B", "R", "L"), ONE_AXIS: ("F", "B")}
_WORDS = {6: "six", 4: "four", 2: "two"}   # their numbers of directions, as the reasons say them
BUTTON_NAMES = ("B1", "B2")   # the mode buttons (sim/joystick.py BUTTONS; bomi/ does not import sim/)


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
    by themselves (automatic mode switching, tasks/operators/assist.py: the user rests and waits for them).
    The 3-axis layout only with a button: six motions take the 2-axis layout and both buttons.
    ``functions``: the directions, then the buttons (``assigned_functions`` gives them to motions)."""
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


def path_clearance(postures: Mapping[int, np.ndarray]) -> dict[int, float]:
    """Per motion label: how far its posture lies from the nearest straight path from the neutral
    posture (zero) to another motion's posture, all nodes and angles together, in the postures' units
    (``whitened``: within-class standard deviations). On the way to a motion the body passes every
    posture near that path: one with little clearance is decided there for a moment, and as a mode
    button it would change the mode the person is using."""
    flat = {label: np.ravel(np.asarray(p, dtype=float)) for label, p in postures.items()}
    clearance = {}
    for label, p in flat.items():
        distances = [np.inf]
        for other, q in flat.items():
            if other != label and q @ q > 0:
                along = min(max(float(p @ q) / float(q @ q), 0.0), 1.0)
                distances.append(float(np.linalg.norm(p - along * q)))
        clearance[label] = min(distances)
    return clearance


def within_class_covariance(recordings: Sequence[Recording], nodes: Sequence[int]) -> np.ndarray:
    """The pooled covariance of the angles (nodes x 3 together, deg^2) around each class's mean in each
    recording: how far a posture varies while held, as the LDA sees it (one covariance for all classes)."""
    deviations = []
    for rec in recordings:
        angles = np.hstack([rec.nodes[i].angles for i in nodes])
        for label in np.unique(rec.labels):
            held = angles[rec.labels == label]
            deviations.append(held - held.mean(axis=0))
    return np.cov(np.vstack(deviations), rowvar=False, bias=True).reshape(3 * len(nodes), 3 * len(nodes))


WHITENING_RIDGE = 1e-3   # share of the mean variance added to every direction: a direction that never varies is not infinitely far


def whitened(postures: Mapping[int, np.ndarray], covariance: np.ndarray) -> dict[int, np.ndarray]:
    """The postures (flattened) in units of the within-class spread: distances become how many standard
    deviations of a held posture apart they are, whatever node or angle they lie along."""
    ridge = WHITENING_RIDGE * float(np.trace(covariance)) / len(covariance) + 1e-9
    values, vectors = np.linalg.eigh(covariance + ridge * np.eye(len(covariance)))
    inverse_root = vectors @ np.diag(values ** -0.5) @ vectors.T
    return {label: inverse_root @ np.ravel(p) for label, p in postures.items()}


def button_motions(postures: Mapping[int, np.ndarray], count: int) -> tuple[int, ...]:
    """The ``count`` motions with the most path clearance (``path_clearance``), the most first (B1
    then B2); equal clearances in label order."""
    clearance = path_clearance(postures)
    return tuple(sorted(clearance, key=lambda label: (-clearance[label], label))[:count])


def assigned_functions(postures: Mapping[int, np.ndarray], layout: DerivedLayout) -> dict[int, str]:
    """Per motion label (the keys of ``postures``, label -> mean posture from the neutral one): its
    function in ``layout``: the buttons to the motions of most path clearance, the directions to the
    others in label order."""
    roles = list(layout.functions)
    buttons = [f for f in roles if f in BUTTON_NAMES]
    pressing = button_motions(postures, len(buttons))
    moving = [label for label in sorted(postures) if label not in pressing]
    return {**dict(zip(moving, [f for f in roles if f not in BUTTON_NAMES])), **dict(zip(pressing, buttons))}


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
    postures = motion_postures(recordings, nodes, motions)
    spread = whitened(postures, within_class_covariance(recordings, nodes))
    layout = derived_layout(len(motions))
    functions = assigned_functions(spread, layout)
    classes = (ClassConfig(NEUTRAL_LABEL, "c0", NEUTRAL_FUNCTION, None),) + tuple(
        ClassConfig(label, f"c{label}", functions[label], nodes[int(np.argmax(np.linalg.norm(postures[label], axis=1)))])
        for label in motions)
    calibrations = {i: node_calibration(first, i) for i in nodes}
    mounted = [f"node {i} mounting {calibrations[i].mounting} (the one its own angle columns agree with)"
               for i in nodes if calibrations[i] != NodeCalibration.default_for(i)]
    profile = Profile(
        name="derived", description=f"derived from the recording: its nodes, its labels, generic class names; "
                                    + "".join(f"{m}; " for m in mounted) + f"layout {layout.layout}: {layout.reason}"
                                    + _buttons_reason(spread, functions),
        joystick_layout=layout.layout, assist=layout.assist,
        nodes=tuple(NodeConfig(i, _BASE_STATION_FIRST_IMU + i - 1, f"node {i}", calibrations[i]) for i in nodes),
        classes=classes, spec=FeatureSpec("FV3" if gyro else "FV1", tuple(nodes)), shrinkage=SELECT,
        neutral_samples=DEFAULT_NEUTRAL_SAMPLES, post=PostProcessing(), source=f"derived from {first.source}",
        amplitude="along_class",
        select_rejection=True, amplitude_scales=DERIVED_AMPLITUDE_SCALES)
    rest_offsets, reason = choose_rest_offsets(recordings, profile)
    return replace(profile, rest_offsets=rest_offsets, description=f"{profile.description}; {reason}")


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


def motion_postures(recordings: Sequence[Recording], nodes: Sequence[int], motions: Sequence[int]) -> dict[int, np.ndarray]:
    """Per motion label: its mean neutral-subtracted angles over the recordings' samples of the class
    (nodes x 3, deg; zeros for a class with no sample). Its carrying node is the row of largest norm."""
    postures = {}
    for label in motions:
        rows = []
        for i in nodes:
            changes = np.concatenate([rec.nodes[i].angles[rec.labels == label]
                                      - neutral_offsets(rec.nodes[i].angles, DEFAULT_NEUTRAL_SAMPLES)
                                      for rec in recordings])
            rows.append(changes.mean(axis=0) if len(changes) else np.zeros(3))
        postures[label] = np.array(rows)
    return postures


def _buttons_reason(postures: Mapping[int, np.ndarray], functions: Mapping[int, str]) -> str:
    pressing = sorted((f, label) for label, f in functions.items() if f in BUTTON_NAMES)
    if not pressing:
        return ""
    clearance = path_clearance(postures)
    return ("; buttons on the motions farthest from the others' paths from neutral, in within-class standard "
            "deviations (" + ", ".join(f"{f} c{label} {clearance[label]:.1f}" for f, label in pressing) + ")")


def describe(profile: Profile) -> str:
    """One line: what a derived profile holds."""
    kind = profile.spec.kind
    classes = ", ".join(f"c{c.label} {c.function}" + ("" if c.node is None else f" (node {c.node})")
                        for c in profile.classes)
    scales = ", ".join(f"{s:g}" for s in profile.amplitude_scales)
    layout = derived_layout(sum(c.function != NEUTRAL_FUNCTION for c in profile.classes))
    return (f"no --profile: {profile.source}: node(s) {list(profile.node_indices)}, {kind} "
            f"({'angles + GYRO' if kind != 'FV1' else 'angles: the recording has no GYRO'}), classes {classes}; "
            f"layout {layout.layout}{' + ' + ', '.join(layout.assist) if layout.assist else ''} "
            f"({profile.description.split(f'layout {layout.layout}: ', 1)[-1]}); "
            f"classifier plain unless the cross-validation on the training recording earns an extra its place "
            f"(shrinkage, motions also trained at {scales} of their size, rejection)")
