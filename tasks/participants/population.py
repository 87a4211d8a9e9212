"""A population of synthetic new people to develop and check a new person's classifier on.

Pure: ``draw_person(seed)`` -> ``SyntheticPerson`` (participant parameters, the profile they wear,
and what happens to their recordings), ``pass_recordings(person)`` -> the two passes of the
calibration protocol, as ``bomi record`` would have recorded them (frames synthesised, parsed and
fused by the real chain, holds only as in the published files). The same seed always gives the
same person and the same recordings.

What varies from person to person (every range is an assumption, chosen to span more than the
paper's three participants, not fitted to anyone):

- 1 to 3 nodes (node 1 a headset, others on a shoulder, hand or foot), 4 to 9 classes (neutral and
  3 to 8 motions), each motion carried by one node, in a direction of its own (at least
  ``MIN_SEPARATION_DEG`` from the other motions of that node) and with a range of
  ``RANGE_DEG``; the other nodes move a little with it (coupling);
- each node's mounting on the body (a random rotation; the headset's is hardware.md's, turned by
  up to ``HEAD_MOUNT_TILT_DEG``), and how far the mounting the fusion assumes is off the true one
  (``mounting_error_deg``: pitch, roll and yaw leak into each other);
- repeatability, sway, tremor (strength and frequency), spasm bursts, movement speed;
- drift between the two passes (the motions' postures and the neutral posture change);
- a slow yaw (heading) drift within each pass, as a magnetic disturbance gives the fused heading;
- for some people a glitching node: now and then its samples freeze or its angles jump.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from bomi.classifier import NEUTRAL_LABEL, PostProcessing
from bomi.features import FeatureSpec
from bomi.fusion import HEADSET_MOUNTING, NodeCalibration
from bomi.paper import CLASS_FUNCTIONS
from bomi.profiles import DEFAULT_NEUTRAL_SAMPLES, NEUTRAL_FUNCTION, ClassConfig, NodeConfig, Profile
from bomi.recording import NodeData, Recording
from tasks.participants.params import ClassMotion, ParticipantParams, Spasm, load_participant
from tasks.participants.participant import calibration_session, session_recording

NODE_COUNTS = (1, 2, 3)
MOTION_COUNTS = range(3, 9)               # 4..9 classes with the neutral posture
RANGE_DEG = (8.0, 35.0)                   # a motion's size at full amplitude
MIN_SEPARATION_DEG = 25.0                 # between the directions of two motions of one node
HEAD_MOUNT_TILT_DEG = 20.0
PASSES = 2
_SITES = ("head (headband)", "shoulder", "hand", "foot")


@dataclass(frozen=True)
class Glitch:
    """A glitching node: episodes (Poisson, ``rate_per_s``) of ``duration_s`` in which its samples
    freeze (the base station repeats the last one) or its angles jump by up to ``jump_deg``."""

    node: int
    rate_per_s: float
    duration_s: float
    jump_deg: float


@dataclass(frozen=True)
class SyntheticPerson:
    """One drawn person: who they are (``params``), the profile they wear (its node calibrations
    are what the fusion assumes), and what happens to their recordings."""

    seed: int
    params: ParticipantParams
    profile: Profile
    true_mountings: tuple[tuple[tuple[float, ...], ...], ...]   # per node: the sensor's real mounting
    mounting_error_deg: float       # angle between the assumed and the real mounting of every node
    neutral_drift_deg: np.ndarray   # (nodes, 3): the neutral posture of pass 2 minus that of pass 1
    yaw_drift_deg_per_min: np.ndarray  # (nodes,) heading drift within a pass
    glitch: Glitch | None

    @property
    def n_classes(self) -> int:
        return len(self.profile.classes)


def _directions(rng: np.random.Generator, count: int) -> np.ndarray:
    """``count`` unit (pitch, roll, yaw) directions at least MIN_SEPARATION_DEG apart, drawn with
    yaw less likely than pitch and roll (heads and limbs mostly tilt)."""
    directions: list[np.ndarray] = []
    min_cos = np.cos(np.radians(MIN_SEPARATION_DEG))
    while len(directions) < count:
        v = rng.normal(size=3) * np.array([1.0, 1.0, 0.6])
        v /= np.linalg.norm(v)
        if all(v @ d < min_cos for d in directions):
            directions.append(v)
    return np.array(directions)


def _mounting(rng: np.random.Generator, node: int) -> np.ndarray:
    if node == 1:
        tilt = Rotation.from_rotvec(rng.normal(size=3) * np.radians(HEAD_MOUNT_TILT_DEG) / np.sqrt(3))
        return np.array(HEADSET_MOUNTING) @ tilt.as_matrix()
    return Rotation.random(random_state=rng).as_matrix()


def _rounded(matrix: np.ndarray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in matrix)


def _matrix(rng: np.random.Generator, n_nodes: int, low: float, high: float) -> np.ndarray:
    return rng.uniform(low, high, (n_nodes, 3))


def draw_person(seed: int) -> SyntheticPerson:
    """The person of ``seed`` (any non-negative int; the same seed, the same person)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 26]))
    n_nodes = int(rng.choice(NODE_COUNTS))
    n_motions = int(rng.choice(list(MOTION_COUNTS)))
    # each motion's carrying node: node 1 carries most; every node carries at least one when there are enough
    carriers = rng.choice(np.arange(1, n_nodes + 1), n_motions, p=np.r_[2.0, np.ones(n_nodes - 1)] / (n_nodes + 1))
    carriers[:min(n_nodes, n_motions)] = np.arange(1, min(n_nodes, n_motions) + 1)
    carriers = np.sort(carriers)
    mountings = [_mounting(rng, node) for node in range(1, n_nodes + 1)]
    error_deg = float(rng.choice([0.0, rng.uniform(2.0, 15.0)]))
    assumed = [m @ Rotation.from_rotvec(rng.normal(size=3) / np.sqrt(3) * np.radians(error_deg)).as_matrix()
               for m in mountings]
    p1 = load_participant("P1")
    precision = rng.uniform(0.5, 2.5)          # how repeatable the person is (P1 is about 1)
    tremor = rng.uniform(0.05, 0.8)            # tremor std in holds, deg
    sway = rng.uniform(0.2, 1.5)
    drift = rng.uniform(0.0, 1.0)              # how much the postures change between passes
    classes = {}
    for node in range(1, n_nodes + 1):
        labels = [k + 1 for k in range(n_motions) if carriers[k] == node]
        for label, direction in zip(labels, _directions(rng, len(labels))):
            posture = rng.normal(0.0, 1.5, (n_nodes, 3))      # coupling: the other nodes move a little
            posture[node - 1] = direction * rng.uniform(*RANGE_DEG)
            classes[label] = ClassMotion(
                label=label, posture_deg=posture,
                rep_std_deg=_matrix(rng, n_nodes, 0.7, 2.0) * precision,
                day_gain_log_std=0.15 * drift, day_std_deg=_matrix(rng, n_nodes, 0.5, 2.5) * drift,
                sway_std_deg=_matrix(rng, n_nodes, 0.5, 1.5) * sway,
                tremor_std_deg=_matrix(rng, n_nodes, 0.5, 1.5) * tremor)
    neutral = ClassMotion(label=NEUTRAL_LABEL, posture_deg=rng.normal(0.0, 3.0, (n_nodes, 3)),
                          rep_std_deg=_matrix(rng, n_nodes, 0.7, 1.7) * precision, day_gain_log_std=0.0,
                          day_std_deg=np.zeros((n_nodes, 3)), sway_std_deg=_matrix(rng, n_nodes, 0.3, 0.8) * sway,
                          tremor_std_deg=_matrix(rng, n_nodes, 0.5, 1.5) * tremor)
    freqs, power = p1.tremor_spectrum
    spasm = None
    if rng.random() < 0.4:
        spasm = Spasm(rate_per_s=float(rng.uniform(0.02, 0.3)), max_deg=float(rng.uniform(3.0, 15.0)),
                      duration_s=float(rng.uniform(0.2, 0.8)), nodes=tuple(range(1, n_nodes + 1)))
    name = f"N{seed}"
    params = ParticipantParams(
        name=name, profile=name, description=f"synthetic person {seed} (tasks/participants/population.py)",
        onset_s=float(rng.uniform(0.6, 1.6)), reaction_s=float(rng.uniform(0.3, 0.9)), max_amplitude=1.0,
        tremor_spectrum=(freqs * rng.uniform(0.7, 2.0), power), neutral=neutral, classes=classes, spasm=spasm,
        feel=p1.feel, source=f"population seed {seed}")
    nodes = tuple(NodeConfig(i, 10 + i - 1, _SITES[0] if i == 1 else str(rng.choice(_SITES[1:])),
                             NodeCalibration(mounting=_rounded(assumed[i - 1])) if i == 1 else
                             replace(NodeCalibration.uncalibrated(), mounting=_rounded(assumed[i - 1])))
                  for i in range(1, n_nodes + 1))
    profile = Profile(
        name=name, description=params.description, nodes=nodes,
        classes=(ClassConfig(NEUTRAL_LABEL, "neutral posture", NEUTRAL_FUNCTION, None),) + tuple(
            ClassConfig(label, f"c{label}", CLASS_FUNCTIONS[label - 1], int(carriers[label - 1]))
            for label in range(1, n_motions + 1)),
        spec=FeatureSpec("FV3", tuple(range(1, n_nodes + 1))), shrinkage=None,
        neutral_samples=DEFAULT_NEUTRAL_SAMPLES, post=PostProcessing(), source=params.source, amplitude="along_class")
    glitch = None
    if rng.random() < 0.25:
        glitch = Glitch(node=int(rng.integers(1, n_nodes + 1)), rate_per_s=float(rng.uniform(0.01, 0.1)),
                        duration_s=float(rng.uniform(0.1, 1.0)), jump_deg=float(rng.uniform(5.0, 40.0)))
    return SyntheticPerson(
        seed=seed, params=params, profile=profile, true_mountings=tuple(_rounded(m) for m in mountings),
        mounting_error_deg=error_deg, neutral_drift_deg=rng.normal(0.0, 2.0 * drift, (n_nodes, 3)),
        yaw_drift_deg_per_min=rng.choice([0.0, 1.0]) * rng.normal(0.0, 2.0, n_nodes), glitch=glitch)


def true_profile(person: SyntheticPerson) -> Profile:
    """The person's profile with the real mountings: what the synthesiser puts on the body."""
    nodes = tuple(replace(node, calibration=replace(node.calibration, mounting=mounting))
                  for node, mounting in zip(person.profile.nodes, person.true_mountings))
    return replace(person.profile, nodes=nodes)


def pass_recording(person: SyntheticPerson, k: int) -> Recording:
    """Pass ``k`` (0 or 1) of the paper's protocol (3 repetitions of every motion, 5 s holds and 5 s
    of neutral between), recorded and fused with the profile's (assumed) calibrations, holds only."""
    if k not in range(PASSES):
        raise ValueError(f"pass must be one of {list(range(PASSES))}, got {k}")
    params = person.params
    if k:
        params = replace(params, neutral=replace(params.neutral,
                                                 posture_deg=params.neutral.posture_deg + person.neutral_drift_deg))
    session = calibration_session(params, true_profile(person), seed=int(np.random.SeedSequence([person.seed, k])
                                                                          .generate_state(1)[0]))
    rec = session_recording(session, person.profile)
    rng = np.random.default_rng(np.random.SeedSequence([person.seed, k, 1]))
    nodes = {}
    for slot, (i, data) in enumerate(sorted(rec.nodes.items())):
        angles, gyro = data.angles.copy(), data.gyro.copy()
        angles[:, 2] += person.yaw_drift_deg_per_min[slot] * (rec.time - rec.time[0]) / 60.0
        if person.glitch is not None and person.glitch.node == i:
            _glitch(angles, gyro, rec.time, person.glitch, rng)
        nodes[i] = NodeData(data.acc, gyro, data.mag, angles)
    return Recording(nodes=nodes, labels=rec.labels, time=rec.time, source=f"person {person.seed} pass {k + 1}")


def _glitch(angles: np.ndarray, gyro: np.ndarray, time: np.ndarray, glitch: Glitch, rng: np.random.Generator) -> None:
    """Glitch episodes in place: half freeze the node's samples, half make its angles jump."""
    span = time[-1] - time[0]
    for onset in rng.uniform(time[0], time[-1], rng.poisson(glitch.rate_per_s * span)):
        rows = np.flatnonzero((time >= onset) & (time < onset + glitch.duration_s))
        if len(rows) == 0:
            continue
        if rng.random() < 0.5:
            angles[rows] = angles[rows[0]]
            gyro[rows] = gyro[rows[0]]
        else:
            angles[rows] += rng.uniform(-glitch.jump_deg, glitch.jump_deg, 3)


def pass_recordings(person: SyntheticPerson) -> tuple[Recording, Recording]:
    """The person's two passes of the calibration protocol (pass 1 to train on, pass 2 to test)."""
    return pass_recording(person, 0), pass_recording(person, 1)


PASS_GAP_S = 6.2   # the pause between the two passes of a one-file recording (issue 41's real file paused 6.2 s)


def one_file(person: SyntheticPerson, gap_s: float = PASS_GAP_S, rows: int | None = None) -> Recording:
    """Both passes in one recording, as a logger left running between them writes it: the second
    pass's clock resumes ``gap_s`` after the first's last row. ``rows``: only the first rows of each
    pass (a shorter protocol: the first repetition of every motion takes about 3500)."""
    first, second = pass_recordings(person)
    keep = slice(0, rows)
    time = np.r_[first.time[keep], second.time[keep] - second.time[0] + first.time[keep][-1] + gap_s]
    nodes = {i: NodeData(**{s: np.concatenate([getattr(first.nodes[i], s)[keep], getattr(second.nodes[i], s)[keep]])
                            for s in ("acc", "gyro", "mag", "angles")}) for i in first.nodes}
    return Recording(nodes=nodes, labels=np.r_[first.labels[keep], second.labels[keep]], time=time,
                     source=f"person {person.seed}, both passes")
