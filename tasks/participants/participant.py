"""The BoMI operator's body: a virtual participant that turns intents into IMU base-station frames.

An intent ``(class_label, amplitude)`` set at a sim time becomes, after a reaction time, a
minimum-jerk move from the current posture to neutral + amplitude x (the class posture + this
session's and this repetition's offsets), held with slow sway and tremor; intent 0 returns to
a (freshly drawn) neutral. Each node's angle trajectory goes through ``tasks.participants.imu_synth`` to raw
sensor counts and base-station frames, with frame loss and bursty delivery. Parameters come
from ``tasks/participants/<name>.toml`` (schema below; P1 is fitted by ``tasks.participants.twin``).
Every modelling assumption is listed in docs/virtual_participant.md.

TOML schema: ``name``, ``profile`` (bomi profile name), ``description``, ``onset_s``,
``reaction_s``, ``max_amplitude`` (0..1]; ``[tremor]`` with ``frequencies_hz`` and ``relative_power``
(the tremor's power spectrum shape); ``[neutral]`` with
``angles_deg`` (absolute), ``rep_std_deg``, ``sway_std_deg``, ``tremor_std_deg``; one
``[[classes]]`` per motion with ``label``, ``posture_deg``, ``rep_std_deg``, ``day_gain_log_std``, ``day_std_deg``,
``sway_std_deg``, ``tremor_std_deg``; optional ``[spasm]`` with ``rate_per_s``, ``max_deg``,
``duration_s``, ``nodes``; ``[feel]`` (``Feel``: how they lean and correct a lean through the BoMI); a twin
(``tasks.participants.twin``) also has ``[provenance]`` (parameter -> where it comes from) and
``[protocol]`` (``Protocol``: the runs of its source recording). Every ``*_deg`` value is a (nodes x 3)
matrix of (pitch, roll, yaw).
``profile`` is a bomi profile name or a TOML file, relative to the participant file.
"""
from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from enum import IntEnum
from functools import cached_property
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
import scipy.signal

from bomi.config_files import beside, check_numbers, check_table, config_path, load_toml, number
from bomi.errors import BomiError
from bomi.classifier import NEUTRAL_LABEL
from bomi.fusion import DT, WARMUP_S, NodeFusion
from bomi.frames import SAMPLE_RATE_HZ, parse_stream, row_positions, sample_indices
from bomi.profiles import Profile
from bomi.protocol import protocol_order
from bomi.recording import NodeData, Recording
from tasks.participants.imu_synth import Delivery, LinkModel, SensorNoise, deliver, synthesize_nodes

PARTICIPANT_DIR = Path(__file__).resolve().parent
SWAY_CUTOFF_HZ = 1.0          # sway below, tremor above: the split used by the P1 fit
SPASM_DRAW_S = 10.0           # spasm onsets are drawn this far ahead at a time
MAX_ANGLE_DEG = 180.0         # a posture or a neutral angle (pitch, roll, yaw) is within +-180 deg
MAX_STD_DEG = 90.0            # a spread of a posture beyond this is no posture held

_TOP_KEYS = {"name", "profile", "description", "onset_s", "reaction_s", "max_amplitude", "tremor", "neutral",
             "classes", "spasm", "feel", "provenance", "protocol"}
_NEUTRAL_KEYS = {"angles_deg", "rep_std_deg", "sway_std_deg", "tremor_std_deg"}
_CLASS_KEYS = {"label", "posture_deg", "rep_std_deg", "day_gain_log_std", "day_std_deg", "sway_std_deg",
               "tremor_std_deg"}
_SPASM_KEYS = {"rate_per_s", "max_deg", "duration_s", "nodes"}
_PROTOCOL_KEYS = {"source", "holds_only", "labels", "durations_s"}
_FEEL_KEYS = {"least_lean", "lean_step", "watch_s", "speed_smoothing_s", "too_slow", "too_fast", "max_zero"}


@dataclass(frozen=True)
class ClassMotion:
    """One motion class: nominal posture change from neutral at amplitude 1, and its variability."""

    label: int
    posture_deg: np.ndarray      # (nodes, 3)
    rep_std_deg: np.ndarray      # repetition-to-repetition std of the posture
    day_gain_log_std: float      # a session's (day's) posture is exp(N(0, this)) x the nominal one ...
    day_std_deg: np.ndarray      # ... plus an offset of this std
    sway_std_deg: np.ndarray     # slow wander while holding (below SWAY_CUTOFF_HZ)
    tremor_std_deg: np.ndarray   # tremor while holding (in the tremor band)


@dataclass(frozen=True)
class Feel:
    """How the participant drives a proportional class through the BoMI (``tasks.stacking.episode``): the
    leans they use and calibrate with, and how they correct a lean while watching the arm."""

    least_lean: float        # the least lean (share of the body's range) used and calibrated; full range is 1
    lean_step: float         # how much further (or less far) a correction leans
    watch_s: float           # after reaction + move, how long a posture is watched before correcting it
    speed_smoothing_s: float  # the arm's speed is judged over about this long
    too_slow: float          # seen / wanted speed below which the participant leans further
    too_fast: float          # seen / wanted speed above which they lean less far
    max_zero: float          # the learnt zero lean never exceeds this (the least deflection needs less than full range)


@dataclass(frozen=True)
class Spasm:
    """Involuntary bursts: Poisson with ``rate_per_s``; each a raised-cosine of up to ``max_deg``."""

    rate_per_s: float
    max_deg: float
    duration_s: float
    nodes: tuple[int, ...]       # 1-based node positions in the profile's node list


@dataclass(frozen=True)
class Protocol:
    """A recording's calibration protocol as runs of one cued class each, in order: what
    ``bomi synth`` performs. ``holds_only``: the recording kept only the held postures (stitched,
    each run a hold); else it kept every row, labelled with the cue (each run is the move then the hold)."""

    labels: tuple[int, ...]
    durations_s: tuple[float, ...]
    holds_only: bool
    source: str


@dataclass(frozen=True)
class ParticipantParams:
    name: str
    profile: str
    description: str
    onset_s: float
    reaction_s: float
    max_amplitude: float
    tremor_spectrum: tuple[np.ndarray, np.ndarray]   # frequencies (Hz), relative power
    neutral: ClassMotion         # label 0: angles_deg absolute, rep_std = neutral-to-neutral std
    classes: dict[int, ClassMotion]
    spasm: Spasm | None
    feel: Feel
    source: str
    protocol: Protocol | None = None              # a twin's: the protocol of its source recording
    provenance: Mapping[str, str] = field(default_factory=dict)   # a twin's: parameter -> where it comes from

    @property
    def n_nodes(self) -> int:
        return self.neutral.posture_deg.shape[0]

    def motion(self, label: int) -> ClassMotion:
        return self.neutral if label == NEUTRAL_LABEL else self.classes[label]


# ------------------------------------------------------------------------------------- loading
def load_participant(path_or_name: str | Path, overrides: Mapping[str, Any] | None = None) -> ParticipantParams:
    """Load and validate a participant file, or a shipped one by name (P1, P4, P5); ``overrides``:
    dotted keys set before validation (``{"spasm.rate_per_s": 0.2}``)."""
    params = load_toml(path_or_name, PARTICIPANT_DIR, "participant", _parse, overrides)
    return replace(params, profile=beside(params.profile, config_path(path_or_name, PARTICIPANT_DIR)))


def parse_participant_text(text: str, source: str) -> ParticipantParams:
    """A participant file's text, validated as ``load_participant`` validates a file (`bomi twin`
    checks what it is about to write with it, so `bomi synth` accepts every twin written); a fault
    is a ValueError."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"not valid TOML ({exc})") from None
    check_numbers(data)
    return _parse(data, source)


def _matrix(table: dict, key: str, where: str, n_nodes: int | None, nonnegative: bool) -> np.ndarray:
    try:
        m = np.array(table[key], dtype=float)
    except (TypeError, ValueError):
        m = np.array([])
    if m.ndim != 2 or m.shape[1] != 3 or (n_nodes is not None and m.shape[0] != n_nodes) or not np.isfinite(m).all():
        nodes = "nodes" if n_nodes is None else str(n_nodes)
        raise ValueError(f"{where}: '{key}' must be a {nodes} x 3 matrix of numbers (pitch, roll, yaw per node)")
    if nonnegative and (m < 0).any():
        raise ValueError(f"{where}: '{key}' holds standard deviations, they cannot be negative")
    limit = MAX_STD_DEG if nonnegative else MAX_ANGLE_DEG
    if (np.abs(m) > limit).any():
        what = "a standard deviation" if nonnegative else "an angle"
        raise ValueError(f"{where}: '{key}' holds {np.abs(m).max():g} deg, beyond the {limit:g} deg {what} of a "
                         f"body's posture can be")
    return m


def _motion(table: dict, label: int, where: str, n_nodes: int, posture_key: str = "posture_deg") -> ClassMotion:
    zeros = np.zeros((n_nodes, 3))
    return ClassMotion(
        label=label,
        posture_deg=_matrix(table, posture_key, where, n_nodes, nonnegative=False),
        rep_std_deg=_matrix(table, "rep_std_deg", where, n_nodes, nonnegative=True),
        day_gain_log_std=number(table, "day_gain_log_std", where, 0.0, 2.0) if label else 0.0,
        day_std_deg=_matrix(table, "day_std_deg", where, n_nodes, nonnegative=True) if label else zeros,
        sway_std_deg=_matrix(table, "sway_std_deg", where, n_nodes, nonnegative=True),
        tremor_std_deg=_matrix(table, "tremor_std_deg", where, n_nodes, nonnegative=True),
    )


def _parse(data: dict, source: str) -> ParticipantParams:
    check_table(data, "participant", _TOP_KEYS, _TOP_KEYS - {"description", "spasm", "provenance", "protocol"})
    for key in ("name", "profile"):
        if not isinstance(data[key], str) or not data[key]:
            raise ValueError(f"'{key}' must be a non-empty string")
    neutral_table = check_table(data["neutral"], "[neutral]", _NEUTRAL_KEYS, _NEUTRAL_KEYS)
    n_nodes = _matrix(neutral_table, "angles_deg", "[neutral]", None, nonnegative=False).shape[0]
    neutral = _motion(neutral_table, NEUTRAL_LABEL, "[neutral]", n_nodes, posture_key="angles_deg")
    freqs, power = _parse_tremor(data["tremor"])
    if not isinstance(data["classes"], list) or not data["classes"]:
        raise ValueError("'classes' must be a non-empty list of [[classes]] tables")
    classes: dict[int, ClassMotion] = {}
    for k, table in enumerate(data["classes"]):
        where = f"classes[{k}]"
        check_table(table, where, _CLASS_KEYS, _CLASS_KEYS)
        label = table["label"]
        if isinstance(label, bool) or not isinstance(label, int) or label <= NEUTRAL_LABEL or label in classes:
            raise ValueError(f"{where}: 'label' must be a positive integer not used before, got {label!r}")
        classes[label] = _motion(table, label, where, n_nodes)
    spasm = _parse_spasm(data["spasm"], n_nodes) if "spasm" in data else None
    provenance = data.get("provenance", {})
    if not isinstance(provenance, dict) or not all(isinstance(v, str) for v in provenance.values()):
        raise ValueError("[provenance]: each parameter's provenance must be a string")
    protocol = _parse_protocol(data["protocol"], set(classes) | {NEUTRAL_LABEL}) if "protocol" in data else None
    return ParticipantParams(
        name=data["name"], profile=data["profile"], description=str(data.get("description", "")),
        onset_s=number(data, "onset_s", "participant", DT, 10.0),
        reaction_s=number(data, "reaction_s", "participant", 0.0, 10.0),
        max_amplitude=number(data, "max_amplitude", "participant", 0.01, 1.0),
        tremor_spectrum=(freqs, power), neutral=neutral, classes=classes, spasm=spasm,
        feel=_parse_feel(data["feel"]), source=source, protocol=protocol, provenance=provenance)



def _parse_tremor(table: Any) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies_hz, relative_power) of the tremor spectrum."""
    keys = {"frequencies_hz", "relative_power"}
    tremor = check_table(table, "[tremor]", keys, keys)
    try:
        freqs, power = (np.array(tremor[k], dtype=float) for k in ("frequencies_hz", "relative_power"))
    except (TypeError, ValueError):
        freqs = power = np.array([])
    if (freqs.ndim != 1 or freqs.shape != power.shape or len(freqs) < 3 or freqs[0] != 0
            or np.any(np.diff(freqs) <= 0) or freqs[-1] > SAMPLE_RATE_HZ / 2
            or np.any(power < 0) or not np.any(power > 0)):
        raise ValueError("[tremor]: frequencies_hz must rise from 0 to at most "
                         f"{SAMPLE_RATE_HZ / 2} Hz, with as many non-negative relative_power values, not all 0")
    return freqs, power


def _parse_protocol(table: Any, labels: set[int]) -> Protocol:
    table = check_table(table, "[protocol]", _PROTOCOL_KEYS, _PROTOCOL_KEYS)
    runs, durations = table["labels"], table["durations_s"]
    if (not isinstance(runs, list) or not runs or not all(isinstance(v, int) and v in labels for v in runs)
            or not isinstance(durations, list) or len(durations) != len(runs)
            or not all(isinstance(v, (int, float)) and 0 < v <= 3600 for v in durations)):
        raise ValueError(f"[protocol]: 'labels' must list classes of the participant ({sorted(labels)}) and "
                         "'durations_s' as many durations in (0, 3600] s")
    if not isinstance(table["holds_only"], bool) or not isinstance(table["source"], str):
        raise ValueError("[protocol]: 'holds_only' must be true or false and 'source' a string")
    return Protocol(tuple(runs), tuple(float(v) for v in durations), table["holds_only"], table["source"])


def _parse_feel(table: Any) -> Feel:
    table = check_table(table, "[feel]", _FEEL_KEYS, _FEEL_KEYS)
    return Feel(least_lean=number(table, "least_lean", "[feel]", 0.05, 1.0),
                lean_step=number(table, "lean_step", "[feel]", 0.0, 1.0),
                watch_s=number(table, "watch_s", "[feel]", 0.0, 60.0),
                speed_smoothing_s=number(table, "speed_smoothing_s", "[feel]", DT, 60.0),
                too_slow=number(table, "too_slow", "[feel]", 0.0, 1.0),
                too_fast=number(table, "too_fast", "[feel]", 1.0),
                max_zero=number(table, "max_zero", "[feel]", 0.0, 0.99))


def _parse_spasm(table: Any, n_nodes: int) -> Spasm:
    table = check_table(table, "[spasm]", _SPASM_KEYS, _SPASM_KEYS)
    nodes = table["nodes"]
    if not isinstance(nodes, list) or not nodes or not all(isinstance(n, int) and 1 <= n <= n_nodes for n in nodes):
        raise ValueError(f"[spasm]: 'nodes' must list node positions 1..{n_nodes}")
    return Spasm(number(table, "rate_per_s", "[spasm]", 0.0), number(table, "max_deg", "[spasm]", 0.0, 90.0),
                 number(table, "duration_s", "[spasm]", DT, 10.0), tuple(nodes))


def check_against_profile(params: ParticipantParams, profile: Profile) -> None:
    """The participant must wear the profile's nodes and perform exactly its motion classes."""
    if Path(params.profile).suffix.lower() != ".toml" and params.profile != profile.name:
        raise BomiError(f"{params.source}: made for profile {params.profile}, not {profile.name}")
    if params.n_nodes != len(profile.nodes):
        raise BomiError(f"{params.source}: {params.n_nodes} nodes per angle matrix, profile {profile.name} "
                        f"has {len(profile.nodes)}")
    motions = sorted(cls.label for cls in profile.classes if cls.label != NEUTRAL_LABEL)
    if sorted(params.classes) != motions:
        raise BomiError(f"{params.source}: classes {sorted(params.classes)} do not match profile "
                        f"{profile.name}'s motion classes {motions}")


# ------------------------------------------------------------------------------ motion pieces
def minimum_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk position profile 10 s^3 - 15 s^4 + 6 s^5 for s in [0, 1] (clipped outside)."""
    s = np.clip(s, 0.0, 1.0)
    return s ** 3 * (10.0 - 15.0 * s + 6.0 * s ** 2)


@dataclass
class ColouredNoise:
    """Unit-variance Gaussian noise through a fixed filter (b, a), streamed (filter state kept between calls)."""

    b: np.ndarray
    a: np.ndarray
    channels: int
    rng: np.random.Generator
    gain: float = field(init=False)
    state: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        impulse = scipy.signal.lfilter(self.b, self.a, np.r_[1.0, np.zeros(8191)])
        self.gain = 1.0 / float(np.sqrt(np.sum(impulse ** 2)))
        self.state = np.zeros((max(len(self.a), len(self.b)) - 1, self.channels))
        # start in the stationary regime: run the filter over a few seconds of noise first
        self.next(int(10 * SAMPLE_RATE_HZ))

    def next(self, n: int) -> np.ndarray:
        noise = self.rng.standard_normal((n, self.channels))
        if len(self.a) == 1 and self.a[0] == 1.0:   # FIR (the tremor's)
            out, self.state = fir_filter(self.b, noise, self.state)
        else:
            out, self.state = scipy.signal.lfilter(self.b, self.a, noise, axis=0, zi=self.state)
        return out * self.gain


def fir_filter(b: np.ndarray, x: np.ndarray, zi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.lfilter(b, [1.0], x, axis=0, zi=zi)`` of (n, C) ``x`` by scipy's own FIR arithmetic
    (``np.convolve`` of each channel, the state added to the first outputs): the same bits
    (tests/test_participant.py), without its ``np.apply_along_axis``, 2/3 of the cost of a stream's
    chunk of a few dozen samples. Returns (output, final state)."""
    full = np.empty((len(x) + len(b) - 1, x.shape[1]))
    for channel in range(x.shape[1]):
        full[:, channel] = np.convolve(b, x[:, channel])
    full[:len(zi)] += zi
    return full[:len(x)], full[len(x):]


def sway_filter() -> tuple[np.ndarray, np.ndarray]:
    """Fourth-order Butterworth low-pass at SWAY_CUTOFF_HZ (little leakage into the tremor band)."""
    return scipy.signal.butter(4, SWAY_CUTOFF_HZ, "low", fs=SAMPLE_RATE_HZ)


def tremor_filter(spectrum: tuple[np.ndarray, np.ndarray], taps: int = 255) -> tuple[np.ndarray, np.ndarray]:
    """FIR filter whose power response follows the tremor spectrum (amplitude = sqrt of power)."""
    freqs, power = spectrum
    nyquist = SAMPLE_RATE_HZ / 2
    if freqs[-1] < nyquist:
        freqs, power = np.r_[freqs, nyquist], np.r_[power, 0.0]
    return scipy.signal.firwin2(taps, freqs, np.sqrt(power), fs=SAMPLE_RATE_HZ), np.array([1.0])


@dataclass(frozen=True)
class PostureMove:
    """A min-jerk move from ``start`` to ``target`` (absolute angles, (nodes, 3)) beginning at ``t0``."""

    t0: float
    duration: float
    start: np.ndarray
    target: np.ndarray
    label: int
    amplitude: float

    def progress(self, t: np.ndarray) -> np.ndarray:
        """Share of the move done at times ``t`` (0 before, 1 after)."""
        return minimum_jerk((t - self.t0) / self.duration)

    def at(self, t: np.ndarray) -> np.ndarray:
        """Posture at times ``t``, (n, nodes, 3)."""
        return self.posture(self.progress(t))

    def posture(self, progress: np.ndarray) -> np.ndarray:
        """Posture at (n,) shares ``progress`` of the move, (n, nodes, 3)."""
        return self.start[None] + progress[:, None, None] * (self.target - self.start)[None]

    @cached_property
    def done(self) -> np.ndarray:
        """The posture once the move is done, (nodes, 3): ``posture`` at progress 1.0, bit for bit
        (start + (target - start), which need not be ``target``'s bits)."""
        return self.posture(np.ones(1))[0]


@dataclass(frozen=True)
class Truth:
    """Ground truth per generated sample: time, intent (label, amplitude) and true angles (n, nodes, 3)."""

    time_s: np.ndarray
    intent: np.ndarray
    amplitude: np.ndarray
    angles: np.ndarray


# ------------------------------------------------------------------------ the virtual participant
class Session(IntEnum):
    """Which of a day's sessions a virtual participant performs: the same person (the day's
    postures) with the session's own noise."""

    CALIBRATION = 1
    TASK = 2


class VirtualParticipant:
    """A streaming source of base-station bytes driven by intents (see the module docstring).

    ``seed`` fixes the person on that day: the day's posture offsets (``day_postures``), the same
    in every ``session``.  The seed and ``session`` together fix the rest: repetition offsets,
    sway, tremor, spasms, sensor noise, frame loss and delivery times, independent between the
    calibration and the task (separate ``numpy.random.SeedSequence`` children of the seed).
    """

    def __init__(self, params: ParticipantParams, profile: Profile, seed: int,
                 noise: SensorNoise = SensorNoise(), link: LinkModel = LinkModel(), session: Session = Session.TASK):
        check_against_profile(params, profile)
        self.params, self.profile, self.noise, self.link = params, profile, noise, link
        # child 0 of the seed: the person; child ``session``: that session's noise, one generator
        # per purpose (and per node for sensors and link), each drawn in sample order: the output
        # does not depend on how the caller slices time into advance() calls
        children = np.random.SeedSequence(seed).spawn(1 + max(Session))
        person = np.random.default_rng(children[0])
        body, sway, tremor, spasm, *per_node = (np.random.default_rng(s) for s in
                                                children[session].spawn(4 + 2 * len(profile.nodes)))
        self._rng, self._spasm_rng = body, spasm
        self._sensor_rngs = per_node[:len(profile.nodes)]
        self._link_rngs = {node.index: rng for node, rng in zip(profile.nodes, per_node[len(profile.nodes):])}
        channels = params.n_nodes * 3
        self._sway = ColouredNoise(*sway_filter(), channels, sway)
        self._tremor = ColouredNoise(*tremor_filter(params.tremor_spectrum), channels, tremor)
        self._day_posture = {label: np.exp(person.normal(0.0, m.day_gain_log_std)) * m.posture_deg
                             + person.normal(0.0, m.day_std_deg) for label, m in params.classes.items()}
        rest = self._target(NEUTRAL_LABEL, 0.0)
        self._moves: list[PostureMove] = [PostureMove(0.0, params.onset_s, rest, rest, NEUTRAL_LABEL, 0.0)]
        self._starts = np.array([0.0])          # each move's t0
        n_spasm_nodes = len(params.spasm.nodes) if params.spasm else 0
        self._spasm_onsets = np.empty(0)
        self._spasm_sizes = np.empty((0, n_spasm_nodes, 3))
        self._spasm_until = 0.0                 # spasm onsets are drawn up to this time
        self._generated = 0                     # samples generated so far (sample k at time k * DT)
        self._passed = 0                        # samples whose time has passed (``pass_time``), made or not
        self._last_angles: np.ndarray | None = None     # (nodes, 3) angles of the last sample
        self._last_arrival: dict[int, float] = {}
        self._pending = _merge()              # generated frames in arrival order ...
        self._returned = 0                      # ... of which those before this one were returned
        self._truth: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []

    # -- intents
    def _target(self, label: int, amplitude: float) -> np.ndarray:
        """A fresh repetition's posture: the session's neutral + amplitude x (day posture + repetition offset)."""
        neutral = self.params.neutral
        if label == NEUTRAL_LABEL:
            return neutral.posture_deg + self._rng.normal(0.0, neutral.rep_std_deg)
        excursion = self._day_posture[label] + self._rng.normal(0.0, self.params.classes[label].rep_std_deg)
        return neutral.posture_deg + amplitude * self.params.max_amplitude * excursion

    @property
    def day_postures(self) -> dict[int, np.ndarray]:
        """The day's posture of each class, (nodes, 3) degrees: the person, shared by the sessions of a seed."""
        return {label: posture.copy() for label, posture in self._day_posture.items()}

    @property
    def spasm_onsets(self) -> np.ndarray:
        """Onset times (s) of the spasm bursts drawn so far."""
        return self._spasm_onsets.copy()

    @property
    def time_s(self) -> float:
        """Sim time up to which samples are made (or passed: ``pass_time``)."""
        return max(self._generated, self._passed) * DT

    def pass_time(self, t_end: float) -> None:
        """Let sim time pass to ``t_end`` without making its samples yet: an intent set from now on
        acts after them, exactly as if ``deliveries(t_end)`` had been called, and the next call that
        makes samples makes them all in one pass (a whole protocol: one synthesis, not one per cue)."""
        self._passed = max(self._passed, _samples_until(t_end))

    @property
    def intent(self) -> tuple[int, float]:
        return self._moves[-1].label, self._moves[-1].amplitude

    def set_intent(self, label: int, amplitude: float, t: float) -> None:
        """From sim time ``t``: move (after the reaction time) to ``label``'s posture at ``amplitude`` in [0, 1].

        Setting the intent already in force does nothing (the posture is held).
        """
        if label != NEUTRAL_LABEL and label not in self.params.classes:
            raise ValueError(f"participant {self.params.name} has no class {label}")
        if not 0.0 <= amplitude <= 1.0:
            raise ValueError(f"amplitude must be in [0, 1], got {amplitude}")
        if (label, amplitude) == self.intent or (label == NEUTRAL_LABEL and self.intent[0] == NEUTRAL_LABEL):
            return
        t0 = max(t + self.params.reaction_s, self.time_s, self._moves[-1].t0)
        t = np.array([t0])
        start = self._moves[self._move_index(t)[0]].at(t)[0]
        self._moves.append(PostureMove(t0, self.params.onset_s, start, self._target(label, amplitude), label,
                                      amplitude))
        self._starts = np.append(self._starts, t0)

    def _move_index(self, t: np.ndarray) -> np.ndarray:
        """Index of the move in force at each time of ``t``."""
        return np.maximum(np.searchsorted(self._starts, t, side="right") - 1, 0)

    def _holding(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """At the increasing times ``t``: the deliberate posture (no sway/tremor/spasm), the std of the sway and
        of the tremor while holding (each blended from the old to the new class over each move), all
        (n, nodes, 3), and the intent's (n,) label and amplitude; one pass per move in force."""
        posture, sway, tremor = np.empty((3, len(t), self.params.n_nodes, 3))
        label, amplitude = np.empty(len(t), dtype=int), np.empty(len(t))
        which = self._move_index(t)
        cuts = [] if which[0] == which[-1] else (np.flatnonzero(which[1:] != which[:-1]) + 1).tolist()  # (which rises)
        for first, end in zip([0, *cuts], [*cuts, len(t)]):
            k, rows = int(which[first]), slice(first, end)
            move = self._moves[k]
            old, new = self.params.motion(self._moves[max(k - 1, 0)].label), self.params.motion(move.label)
            label[rows], amplitude[rows] = move.label, move.amplitude
            if (t[first] - move.t0) / move.duration >= 1.0:   # the move done: progress 1.0 from here on (t rises)
                posture[rows], sway[rows], tremor[rows] = move.done, new.sway_std_deg, new.tremor_std_deg
                continue                                      # (the blend's bits at 1.0: 0 * old + new)
            progress = move.progress(t[rows])
            posture[rows] = move.posture(progress)
            blend = progress[:, None, None]
            sway[rows] = (1 - blend) * old.sway_std_deg[None] + blend * new.sway_std_deg[None]
            tremor[rows] = (1 - blend) * old.tremor_std_deg[None] + blend * new.tremor_std_deg[None]
        return posture, sway, tremor, label, amplitude

    def _spasms(self, t: np.ndarray) -> np.ndarray:
        """Spasm bursts over the samples at ``t``, (n, nodes, 3)."""
        out = np.zeros((len(t), self.params.n_nodes, 3))
        spasm = self.params.spasm
        if spasm is None or spasm.rate_per_s == 0 or len(t) == 0:
            return out
        while self._spasm_until < t[-1]:
            n_new = self._spasm_rng.poisson(spasm.rate_per_s * SPASM_DRAW_S)
            onsets = np.sort(self._spasm_rng.uniform(self._spasm_until, self._spasm_until + SPASM_DRAW_S, n_new))
            size = self._spasm_rng.uniform(-1.0, 1.0, (n_new, len(spasm.nodes), 3))
            size *= spasm.max_deg / np.maximum(np.abs(size).max(axis=(1, 2), keepdims=True), 1e-9)
            size *= self._spasm_rng.uniform(0.3, 1.0, (n_new, 1, 1))
            self._spasm_onsets = np.concatenate([self._spasm_onsets, onsets])
            self._spasm_sizes = np.concatenate([self._spasm_sizes, size])
            self._spasm_until += SPASM_DRAW_S
        nodes = np.array(spasm.nodes) - 1
        recent = slice(np.searchsorted(self._spasm_onsets, t[0] - spasm.duration_s),
                       np.searchsorted(self._spasm_onsets, t[-1], side="right"))
        for onset, size in zip(self._spasm_onsets[recent], self._spasm_sizes[recent]):
            phase = (t - onset) / spasm.duration_s
            active = (phase >= 0) & (phase <= 1)
            if active.any():
                bump = 0.5 * (1 - np.cos(2 * np.pi * phase[active]))
                out[np.ix_(np.flatnonzero(active), nodes)] += bump[:, None, None] * size[None]
        return out

    # -- output
    def _generate(self, t_end: float) -> None:
        n_total = max(_samples_until(t_end), self._passed)
        n = n_total - self._generated
        if n <= 0:
            return
        index = np.arange(self._generated, n_total)
        t = index * DT
        shape = (n, self.params.n_nodes, 3)
        posture, sway, tremor, label, amplitude = self._holding(t)
        angles = (posture + self._sway.next(n).reshape(shape) * sway
                  + self._tremor.next(n).reshape(shape) * tremor + self._spasms(t))
        raws = synthesize_nodes(angles, [node.calibration for node in self.profile.nodes], self._sensor_rngs,
                                self.noise, previous_deg=self._last_angles)
        self._last_angles = angles[-1]
        raw = {node.index: r for node, r in zip(self.profile.nodes, raws)}
        fresh = deliver(raw, index, t, self._link_rngs, self.link, not_before_s=self._last_arrival)
        backwards = fresh.node_index[::-1]   # in arrival order: a node's last frame is its latest
        for node in self._link_rngs:
            mine = backwards == node
            if mine.any():
                self._last_arrival[node] = float(fresh.arrival_s[len(mine) - 1 - int(mine.argmax())])
        self._pending, self._returned = _merge(self._pending.rows(self._returned), fresh), 0
        self._truth.append((t, label, amplitude, angles))
        self._generated = n_total

    def deliveries(self, t_end: float) -> Delivery:
        """The frames that reach the host by sim time ``t_end`` (and were not returned before)."""
        self._generate(t_end)
        # the pending frames from ``_returned`` on have not been returned: a cursor, not a split of the rest every call
        start = self._returned
        self._returned = max(int(np.searchsorted(self._pending.arrival_s, t_end, side="right")), start)
        return self._pending.rows(start, self._returned)

    def advance(self, t_end: float) -> bytes:
        """The base-station bytes that arrive by sim time ``t_end`` (and were not returned before)."""
        return self.deliveries(t_end).stream()

    def flush(self) -> Delivery:
        """Every frame generated but not yet returned, whatever its arrival time (end of a session)."""
        rest = self._pending.rows(self._returned)
        self._pending, self._returned = _merge(), 0
        return rest

    def truth(self) -> Truth:
        """Ground truth of every sample generated so far (the body's intent and angles, not the chain's)."""
        if not self._truth:
            return Truth(np.empty(0), np.empty(0, int), np.empty(0), np.empty((0, self.params.n_nodes, 3)))
        t, label, amp, angles = (np.concatenate(parts) for parts in zip(*self._truth))
        return Truth(t, label, amp, angles)


def _samples_until(t_end: float) -> int:
    """How many samples (sample k at time k * DT) are taken by sim time ``t_end``."""
    return math.floor(t_end / DT + 1e-9) + 1


def _merge(*parts: Delivery) -> Delivery:
    """Deliveries in one arrival order (stable: earlier parts first on ties); no parts: nothing."""
    parts = tuple(part for part in parts if part.frames)
    if len(parts) < 2:   # nothing to merge (an empty delivery, or the one part as it is)
        return parts[0] if parts else Delivery(np.empty(0), np.empty(0, int), np.empty(0, int), [])
    arrival = np.concatenate([p.arrival_s for p in parts])
    node, sample = (np.concatenate([getattr(p, name) for p in parts]) for name in ("node_index", "sample_index"))
    frames = list(chain.from_iterable(p.frames for p in parts))
    if (arrival[1:] >= arrival[:-1]).all():   # in order already (the stable sort would keep it so)
        return Delivery(arrival, node, sample, frames)
    order = np.argsort(arrival, kind="stable")
    return Delivery(arrival[order], node[order], sample[order], [frames[i] for i in order])


# ------------------------------------------------------------------------- calibration protocol
@dataclass(frozen=True)
class CalibrationSession:
    """The paper's calibration protocol performed by a virtual participant.

    Per generated sample (n,): ``cue`` is the class asked for (0 between motions), ``holding``
    is True while the cued posture is reached and held (the published recordings keep only
    these samples), ``recorded`` is False during the warm-up that lets the fusion settle.
    ``delivery`` is every frame the base station sent, in arrival order.
    """

    participant: str
    seed: int
    delivery: Delivery
    truth: Truth
    cue: np.ndarray
    holding: np.ndarray
    recorded: np.ndarray


def calibration_session(params: ParticipantParams, profile: Profile, seed: int, repetitions: int = 3,
                        hold_s: float = 5.0, neutral_s: float = 5.0, amplitudes: Sequence[float] = (1.0,),
                        order: Sequence[tuple[int, float]] | None = None, warmup_s: float = WARMUP_S,
                        noise: SensorNoise = SensorNoise(), link: LinkModel = LinkModel()) -> CalibrationSession:
    """Run the protocol: neutral, then each cued motion held ``hold_s`` with ``neutral_s`` of neutral between.

    The participant needs ``reaction_s + onset_s`` after each cue to reach the posture; the
    hold (and the neutral) lasts ``hold_s`` (``neutral_s``) from then. ``order`` overrides the
    default (label, amplitude) sequence.
    """
    motions = list(order) if order is not None else protocol_order(sorted(params.classes), repetitions, amplitudes)
    runs = [(NEUTRAL_LABEL, 0.0, neutral_s)]
    for label, amplitude in motions:
        runs += [(label, amplitude, hold_s), (NEUTRAL_LABEL, 0.0, neutral_s)]
    return perform_runs(params, profile, seed, runs, warmup_s, noise, link)


def protocol_session(params: ParticipantParams, profile: Profile, seed: int, protocol: Protocol,
                     warmup_s: float = WARMUP_S) -> CalibrationSession:
    """A recording's protocol performed: the same runs, each as long as it was recorded. In a
    holds-only recording a run is the hold; in a continuous one it also holds the participant's
    move after the cue (``reaction_s + onset_s``), so the hold is that much shorter."""
    settle = 0.0 if protocol.holds_only else params.reaction_s + params.onset_s
    runs = [(label, 0.0 if label == NEUTRAL_LABEL else 1.0, max(duration - (settle if k else 0.0), DT))
            for k, (label, duration) in enumerate(zip(protocol.labels, protocol.durations_s))]
    return perform_runs(params, profile, seed, runs, warmup_s)


def perform_runs(params: ParticipantParams, profile: Profile, seed: int, runs: Sequence[tuple[int, float, float]],
                 warmup_s: float = WARMUP_S, noise: SensorNoise = SensorNoise(), link: LinkModel = LinkModel()
                 ) -> CalibrationSession:
    """Runs of (class, amplitude, hold s): the first held from the end of the warm-up, each next one
    cued when the previous hold ends and held ``hold`` s once reached (``reaction_s + onset_s`` after the cue)."""
    vp = VirtualParticipant(params, profile, seed, noise, link, Session.CALIBRATION)
    settle = params.reaction_s + params.onset_s
    (first, first_amp, first_s), *rest = runs
    cues: list[tuple[float, int]] = [(0.0, first)]
    if first != NEUTRAL_LABEL:
        vp.set_intent(first, first_amp, 0.0)
    holds: list[tuple[float, float, int]] = [(warmup_s, warmup_s + first_s, first)]
    t = warmup_s + first_s
    for cue_label, cue_amp, duration in rest:
        vp.pass_time(t)
        vp.set_intent(cue_label, cue_amp, t)
        cues.append((t, cue_label))
        holds.append((t + settle, t + settle + duration, cue_label))
        t += settle + duration
    delivery = _merge(vp.deliveries(t), vp.flush())   # the whole session synthesised in one pass
    truth = vp.truth()
    keep = np.arange(len(truth.time_s)) <= int(np.floor(t / DT + 1e-9))   # the samples up to t, as generated
    truth = Truth(truth.time_s[keep], truth.intent[keep], truth.amplitude[keep], truth.angles[keep])
    # each sample's latest cue, and the latest hold begun by then (the holds follow one another,
    # each ``settle`` after the previous one's end): one search over the samples, not a pass per cue
    starts, labels = np.array(cues).T
    latest = np.searchsorted(starts, truth.time_s, side="right") - 1
    cue = np.where(latest >= 0, labels.astype(int)[latest], NEUTRAL_LABEL)
    begun, ends = np.array([hold[:2] for hold in holds]).T
    latest = np.searchsorted(begun, truth.time_s, side="right") - 1
    holding = (latest >= 0) & (truth.time_s < ends[latest])
    return CalibrationSession(params.name, seed, delivery, truth, cue, holding, truth.time_s >= warmup_s)


# ------------------------------------------------------------------------------ recording it
def record_stream(stream: bytes, profile: Profile, source: str) -> tuple[Recording, np.ndarray]:
    """Parse base-station bytes into fused rows exactly as ``bomi record`` does; also each row's sample index.

    The whole stream at once, by the batch forms of the live steps: the frames a ``FrameParser``
    delivers (``parse_stream``), rows as ``RowAssembler`` pairs them by arrival, a lost frame's
    node repeating its previous sample (``row_positions``), each frame in a row fused once, in
    order, by the node's ``NodeFusion`` (``update_many``: the frames before a node's first row are
    never fused, as ``FusedRows`` never sees them). The sample index of a row (to label it) is that
    of its newest frame, from the unwrapped packet counters (``sample_indices``).
    """
    ids = tuple(node.node_id for node in profile.nodes)
    frames = parse_stream(stream)
    frames = frames[np.isin(frames["node_id"], ids)]
    rows = row_positions(frames["node_id"], ids)
    if not len(rows):
        raise BomiError(f"{source}: no complete row of nodes {list(profile.node_indices)} in the stream")
    nodes = {}
    for k, node in enumerate(profile.nodes):
        used, row_frame = np.unique(rows[:, k], return_inverse=True)   # each frame once, in arrival order
        mine = frames[used]
        acc, gyro, mag = (mine[name].astype(float) for name in ("acc", "gyro", "mag"))
        angles = NodeFusion(node.calibration).update_many(acc, gyro, mag)
        nodes[node.index] = NodeData(acc[row_frame], gyro[row_frame], mag[row_frame], angles[row_frame])
    indices = sample_indices(frames["node_id"], frames["counter"])[rows].max(axis=1)
    return Recording(nodes=nodes, labels=None, time=indices * DT, source=source), indices


def session_recording(session: CalibrationSession, profile: Profile, holds_only: bool = True) -> Recording:
    """The session as ``bomi record`` would record it, labelled with the cue; warm-up cut.

    ``holds_only`` keeps just the held postures, like the published (post-processed) recordings;
    otherwise every row after the warm-up is kept, transitions labelled with their cue.
    """
    source = f"virtual {session.participant} (seed {session.seed})"
    full, index = record_stream(session.delivery.stream(), profile, source)
    keep = session.recorded[index] & (session.holding[index] if holds_only else True)
    nodes = {i: NodeData(d.acc[keep], d.gyro[keep], d.mag[keep], d.angles[keep]) for i, d in full.nodes.items()}
    return Recording(nodes=nodes, labels=session.cue[index][keep], time=full.time[keep], source=source)
