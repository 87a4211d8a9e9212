"""A participant file (``tasks/participants/<name>.toml``) as ``ParticipantParams``: the schema, its
validation (one-line ValueError / BomiError) and the check against a profile.

TOML schema: ``name``, ``profile`` (bomi profile name), ``description``, ``onset_s`` (a move's
duration), ``reaction_s`` (cue to movement), optional ``onset_sd_s`` and ``reaction_sd_s`` (their
spread from move to move, gamma-distributed; 0 or absent: fixed), ``max_amplitude`` (0..1]; ``[tremor]`` with ``frequencies_hz`` and ``relative_power``
(the tremor's power spectrum shape); ``[neutral]`` with
``angles_deg`` (absolute), ``rep_std_deg``, ``sway_std_deg``, ``tremor_std_deg``; one
``[[classes]]`` per motion with ``label``, ``posture_deg``, ``rep_std_deg``, ``day_gain_log_std``, ``day_std_deg``,
``sway_std_deg``, ``tremor_std_deg`` and optionally ``range_share`` (the share of ``posture_deg`` this
person reaches); optional ``[spasm]`` (``Spasm``: background bursts) with ``rate_per_s``, ``max_deg``,
``duration_s``, ``nodes``; optional ``[evoked_spasm]`` (``EvokedSpasm``: spasms some motions set off)
with ``classes``, ``probability``, ``duration_s`` and ``undo_share`` ([least, most] ranges); ``[feel]`` (``Feel``: how they lean and correct a lean through the BoMI); a twin
(``tasks.participants.twin``) also has ``[provenance]`` (parameter -> where it comes from) and
``[protocol]`` (``Protocol``: the runs of its source recording). Every ``*_deg`` value is a (nodes x 3)
matrix of (pitch, roll, yaw).
``profile`` is a bomi profile name or a TOML file, relative to the participant file.
"""
from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from bomi.classifier import NEUTRAL_LABEL
from bomi.config_files import beside, check_numbers, check_table, config_path, load_toml, number
from bomi.errors import BomiError
from bomi.frames import SAMPLE_RATE_HZ
from bomi.fusion import DT
from bomi.profiles import Profile

PARTICIPANT_DIR = Path(__file__).resolve().parent
MAX_ANGLE_DEG = 180.0         # a posture or a neutral angle (pitch, roll, yaw) is within +-180 deg
MAX_STD_DEG = 90.0            # a spread of a posture beyond this is no posture held

_TOP_KEYS = {"name", "profile", "description", "onset_s", "reaction_s", "onset_sd_s", "reaction_sd_s", "max_amplitude",
             "tremor", "neutral", "classes", "spasm", "evoked_spasm", "feel", "provenance", "protocol"}
_OPTIONAL_KEYS = {"description", "onset_sd_s", "reaction_sd_s", "spasm", "evoked_spasm", "provenance", "protocol"}
_NEUTRAL_KEYS = {"angles_deg", "rep_std_deg", "sway_std_deg", "tremor_std_deg"}
_CLASS_KEYS = {"label", "posture_deg", "rep_std_deg", "day_gain_log_std", "day_std_deg", "sway_std_deg",
               "tremor_std_deg", "range_share"}
_SPASM_KEYS = {"rate_per_s", "max_deg", "duration_s", "nodes"}
_EVOKED_KEYS = {"classes", "probability", "duration_s", "undo_share"}
_PROTOCOL_KEYS = {"source", "holds_only", "labels", "durations_s", "run_digests"}
_FEEL_KEYS = {"least_lean", "lean_step", "watch_s", "speed_smoothing_s", "too_slow", "too_fast", "max_zero", "most_lean",
              "give_up_s"}


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
    most_lean: float = 1.0   # the furthest lean, as a share of the class posture (a twin: its recording's largest holds)
    give_up_s: float = 10.0  # the arm not answering the furthest lean this long, the participant relaxes and tries again


@dataclass(frozen=True)
class Spasm:
    """Involuntary bursts: Poisson with ``rate_per_s``; each a raised-cosine of up to ``max_deg``."""

    rate_per_s: float
    max_deg: float
    duration_s: float
    nodes: tuple[int, ...]       # 1-based node positions in the profile's node list


@dataclass(frozen=True)
class EvokedSpasm:
    """Spasms that a motion sets off: each move to one of ``classes``, once its posture is reached, sets
    off with ``probability`` a spasm that pulls the body back along the move (a raised cosine peaking
    at ``undo_share`` of the move's excursion, drawn uniformly in its range) for a duration drawn
    uniformly in ``duration_s``."""

    classes: tuple[int, ...]
    probability: float
    duration_s: tuple[float, float]
    undo_share: tuple[float, float]


@dataclass(frozen=True)
class Protocol:
    """A recording's calibration protocol as runs of one cued class each, in order: what
    ``bomi synth`` performs. ``holds_only``: the recording kept only the held postures (stitched,
    each run a hold); else it kept every row, labelled with the cue (each run is the move then the hold)."""

    labels: tuple[int, ...]
    durations_s: tuple[float, ...]
    holds_only: bool
    source: str
    run_digests: tuple[str, ...] = ()   # of every run of the source recordings (bomi.passes.run_digests)


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
    evoked_spasm: EvokedSpasm | None = None       # spasms set off by some motions (P4's c1)
    onset_sd_s: float = 0.0                       # move durations vary from move to move with this SD ...
    reaction_sd_s: float = 0.0                    # ... and reaction times with this one (gamma; 0: fixed)
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
    check_table(data, "participant", _TOP_KEYS, _TOP_KEYS - _OPTIONAL_KEYS)
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
        check_table(table, where, _CLASS_KEYS, _CLASS_KEYS - {"range_share"})
        label = table["label"]
        if isinstance(label, bool) or not isinstance(label, int) or label <= NEUTRAL_LABEL or label in classes:
            raise ValueError(f"{where}: 'label' must be a positive integer not used before, got {label!r}")
        motion = _motion(table, label, where, n_nodes)
        if "range_share" in table:   # the share of the nominal posture this person reaches (P5's thumb)
            motion = replace(motion, posture_deg=number(table, "range_share", where, 0.0, 1.0) * motion.posture_deg)
        classes[label] = motion
    spasm = _parse_spasm(data["spasm"], n_nodes) if "spasm" in data else None
    evoked = _parse_evoked(data["evoked_spasm"], set(classes)) if "evoked_spasm" in data else None
    provenance = data.get("provenance", {})
    if not isinstance(provenance, dict) or not all(isinstance(v, str) for v in provenance.values()):
        raise ValueError("[provenance]: each parameter's provenance must be a string")
    protocol = _parse_protocol(data["protocol"], set(classes) | {NEUTRAL_LABEL}) if "protocol" in data else None
    return ParticipantParams(
        name=data["name"], profile=data["profile"], description=str(data.get("description", "")),
        onset_s=number(data, "onset_s", "participant", DT, 10.0),
        reaction_s=number(data, "reaction_s", "participant", 0.0, 10.0),
        onset_sd_s=number(data, "onset_sd_s", "participant", 0.0, 5.0, default=0.0),
        reaction_sd_s=number(data, "reaction_sd_s", "participant", 0.0, 5.0, default=0.0),
        max_amplitude=number(data, "max_amplitude", "participant", 0.01, 1.0),
        tremor_spectrum=(freqs, power), neutral=neutral, classes=classes, spasm=spasm, evoked_spasm=evoked,
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
    table = check_table(table, "[protocol]", _PROTOCOL_KEYS, _PROTOCOL_KEYS - {"run_digests"})
    runs, durations = table["labels"], table["durations_s"]
    if (not isinstance(runs, list) or not runs or not all(isinstance(v, int) and v in labels for v in runs)
            or not isinstance(durations, list) or len(durations) != len(runs)
            or not all(isinstance(v, (int, float)) and 0 < v <= 3600 for v in durations)):
        raise ValueError(f"[protocol]: 'labels' must list classes of the participant ({sorted(labels)}) and "
                         "'durations_s' as many durations in (0, 3600] s")
    if not isinstance(table["holds_only"], bool) or not isinstance(table["source"], str):
        raise ValueError("[protocol]: 'holds_only' must be true or false and 'source' a string")
    digests = table.get("run_digests", [])
    if not isinstance(digests, list) or not all(isinstance(v, str) for v in digests):
        raise ValueError("[protocol]: 'run_digests' must be a list of strings")
    return Protocol(tuple(runs), tuple(float(v) for v in durations), table["holds_only"], table["source"],
                    tuple(digests))


def _parse_feel(table: Any) -> Feel:
    table = check_table(table, "[feel]", _FEEL_KEYS, _FEEL_KEYS - {"most_lean", "give_up_s"})
    return Feel(least_lean=number(table, "least_lean", "[feel]", 0.05, 1.0),
                lean_step=number(table, "lean_step", "[feel]", 0.0, 1.0),
                watch_s=number(table, "watch_s", "[feel]", 0.0, 60.0),
                speed_smoothing_s=number(table, "speed_smoothing_s", "[feel]", DT, 60.0),
                too_slow=number(table, "too_slow", "[feel]", 0.0, 1.0),
                too_fast=number(table, "too_fast", "[feel]", 1.0),
                max_zero=number(table, "max_zero", "[feel]", 0.0, 0.99),
                most_lean=number(table, "most_lean", "[feel]", 1.0, 2.0, default=1.0),
                give_up_s=number(table, "give_up_s", "[feel]", 0.0, 3600.0, default=10.0))


def _parse_spasm(table: Any, n_nodes: int) -> Spasm:
    table = check_table(table, "[spasm]", _SPASM_KEYS, _SPASM_KEYS)
    nodes = table["nodes"]
    if not isinstance(nodes, list) or not nodes or not all(isinstance(n, int) and 1 <= n <= n_nodes for n in nodes):
        raise ValueError(f"[spasm]: 'nodes' must list node positions 1..{n_nodes}")
    return Spasm(number(table, "rate_per_s", "[spasm]", 0.0), number(table, "max_deg", "[spasm]", 0.0, 90.0),
                 number(table, "duration_s", "[spasm]", DT, 10.0), tuple(nodes))


def recorded_day(params: ParticipantParams) -> ParticipantParams:
    """The participant on the day of its recording: no drift between days drawn (each class's posture
    the fitted one). What a twin is to a model trained on its own source recording: the person of that
    day, moving within the amplitudes the model learnt (issue 53.4); a twin of one pass otherwise
    drifts by its prior's drift on every seed's day."""
    classes = {label: replace(m, day_gain_log_std=0.0, day_std_deg=np.zeros_like(m.day_std_deg))
               for label, m in params.classes.items()}
    return replace(params, classes=classes)


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


def _range(table: dict, key: str, where: str, low: float, high: float) -> tuple[float, float]:
    value = table[key]
    if (not isinstance(value, list) or len(value) != 2 or not all(isinstance(v, (int, float)) for v in value)
            or not low <= value[0] <= value[1] <= high):
        raise ValueError(f"{where}: '{key}' must be [least, most] within [{low:g}, {high:g}]")
    return float(value[0]), float(value[1])


def _parse_evoked(table: Any, labels: set[int]) -> EvokedSpasm:
    table = check_table(table, "[evoked_spasm]", _EVOKED_KEYS, _EVOKED_KEYS)
    classes = table["classes"]
    if not isinstance(classes, list) or not classes or not all(isinstance(c, int) and c in labels for c in classes):
        raise ValueError(f"[evoked_spasm]: 'classes' must list motion classes of the participant ({sorted(labels)})")
    return EvokedSpasm(tuple(classes), number(table, "probability", "[evoked_spasm]", 0.0, 1.0),
                       _range(table, "duration_s", "[evoked_spasm]", DT, 10.0),
                       _range(table, "undo_share", "[evoked_spasm]", 0.0, 2.0))
