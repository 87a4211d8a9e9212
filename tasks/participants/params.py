"""A participant file (``tasks/participants/<name>.toml``) as ``ParticipantParams``: the schema, its
validation (one-line ValueError / BomiError) and the check against a profile.

TOML schema: ``name``, ``profile`` (bomi profile name), ``description``, ``onset_s`` (a move's
duration), ``reaction_s`` (cue to movement), optional ``onset_sd_s`` and ``reaction_sd_s`` (their
spread from move to move, gamma-distributed; 0 or absent: fixed), ``max_amplitude`` (0..1]; ``[tremor]`` with ``frequencies_hz`` and ``relative_power``
(the tremor's power spectrum shape); ``[neutral]`` with
``angles_deg`` (absolute), ``rep_std_deg``, ``sway_std_deg``, ``tremor_std_deg`` and optionally
``carry_over`` (per node and angle, the share of a rest's offset from the neutral the next rest keeps); one
``[[classes]]`` per motion with ``label``, ``posture_deg``, ``rep_std_deg``, ``day_gain_log_std``, ``day_std_deg``,
``sway_std_deg``, ``tremor_std_deg`` and optionally ``range_share`` (the share of ``posture_deg`` this
person reaches); optional ``[spasm]`` (``Spasm``: background bursts) with ``rate_per_s``, ``max_deg``,
``duration_s``, ``nodes``; optional ``[evoked_spasm]`` (``EvokedSpasm``: spasms some motions set off)
with ``classes``, ``probability``, ``duration_s`` and ``undo_share`` ([least, most] ranges); ``[feel]`` (``Feel``: how they lean and correct a lean through the BoMI); a twin
(``tasks.participants.twin``) also has ``[provenance]`` (parameter -> where it comes from) and
``[protocol]`` (``Protocol``: the runs of its source recording). Every ``*_deg`` value is a (nodes x 3)
matrix of (pitch, roll, yaw).
``profile`` is a bomi profile name or a TOML file, relative to the participant file.

The file is read by ``bomi.config_files``: its tables are the dataclasses below (``Feel``, ``Spasm``,
``EvokedSpasm`` and ``Protocol`` as they are, the rest as ``_ParticipantFile``'s), each checked by its
``__post_init__``; ``_parse`` builds the ``ParticipantParams``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from bomi.classifier import NEUTRAL_LABEL
from bomi.config_files import beside, config_path, from_table, load_toml, parse_text, within
from bomi.errors import BomiError
from bomi.frames import SAMPLE_RATE_HZ
from bomi.fusion import DT
from bomi.profiles import Profile

PARTICIPANT_DIR = Path(__file__).resolve().parent
MAX_ANGLE_DEG = 180.0         # a posture or a neutral angle (pitch, roll, yaw) is within +-180 deg
MAX_STD_DEG = 90.0            # a spread of a posture beyond this is no posture held

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
    max_zero: float          # the learnt zero lean never exceeds this share of most_lean (the least deflection needs less than full range)
    most_lean: float = 1.0   # the furthest lean, as a share of the class posture (a twin: its recording's largest holds)
    give_up_s: float = 10.0  # the arm not answering the furthest lean this long, the participant relaxes and tries again

    def __post_init__(self) -> None:
        within(self, 0.05, 1.0, "least_lean")
        within(self, 0.0, 1.0, "lean_step")
        within(self, 0.0, 60.0, "watch_s")
        within(self, DT, 60.0, "speed_smoothing_s")
        within(self, 0.0, 1.0, "too_slow")
        within(self, 1.0, math.inf, "too_fast")
        within(self, 0.0, 0.99, "max_zero")
        within(self, 1.0, 2.0, "most_lean")
        within(self, 0.0, 3600.0, "give_up_s")


@dataclass(frozen=True)
class Spasm:
    """Involuntary bursts: Poisson with ``rate_per_s``; each a raised-cosine of up to ``max_deg``."""

    rate_per_s: float
    max_deg: float
    duration_s: float
    nodes: tuple[int, ...]       # 1-based node positions in the profile's node list

    def __post_init__(self) -> None:
        within(self, 0.0, math.inf, "rate_per_s")
        within(self, 0.0, 90.0, "max_deg")
        within(self, DT, 10.0, "duration_s")
        if not self.nodes or min(self.nodes) < 1:
            raise ValueError(f"nodes: must list node positions from 1, got {list(self.nodes)}")


@dataclass(frozen=True)
class EvokedSpasm:
    """Spasms that a motion sets off: each move to one of ``classes``, once its posture is reached, sets
    off with ``probability`` a spasm that pulls the body back along the move (a raised cosine peaking
    at ``undo_share`` of the move's excursion, drawn uniformly in its range) for a duration drawn
    uniformly in ``duration_s``. With ``beat_hz`` > 0 the spasm is clonic: within that raised cosine
    the body beats between the posture and the pulled-back point at that rate (each beat a full
    pull and return), instead of one smooth pull."""

    classes: tuple[int, ...]
    probability: float
    duration_s: tuple[float, float]
    undo_share: tuple[float, float]
    beat_hz: float = 0.0

    def __post_init__(self) -> None:
        if not self.classes:
            raise ValueError("classes: must list at least one motion class")
        within(self, 0.0, 1.0, "probability")
        within(self, 0.0, 0.5 / DT, "beat_hz")   # up to the sampling's Nyquist rate
        for name, low, high in (("duration_s", DT, 10.0), ("undo_share", 0.0, 2.0)):
            least, most = getattr(self, name)
            if not low <= least <= most <= high:
                raise ValueError(f"{name}: must be [least, most] within [{low:g}, {high:g}], got {[least, most]}")


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

    def __post_init__(self) -> None:
        if not self.labels or len(self.durations_s) != len(self.labels) \
                or not all(0 < d <= 3600 for d in self.durations_s):
            raise ValueError(f"durations_s: must be as many durations in (0, 3600] s as the {len(self.labels)} labels "
                             "(at least one)")


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
    rest_carry: np.ndarray | None = None          # (nodes, 3): the share of a rest's offset the next rest keeps

    @property
    def n_nodes(self) -> int:
        return self.neutral.posture_deg.shape[0]

    def motion(self, label: int) -> ClassMotion:
        return self.neutral if label == NEUTRAL_LABEL else self.classes[label]


# ------------------------------------------------------------------ the file's tables (bomi.config_files)
Matrix = tuple[tuple[float, float, float], ...]   # a ``*_deg`` value: (pitch, roll, yaw) per node


def _matrices(table: Any) -> dict[str, Matrix]:
    """The ``*_deg`` values of a [neutral] or [[classes]] table, by name."""
    return {f.name: getattr(table, f.name) for f in fields(table) if f.name.endswith("_deg")}


def _check_degrees(table: Any) -> None:
    """Each matrix of ``table`` has a row per node; its angles are within +-MAX_ANGLE_DEG, its
    standard deviations (``*_std_deg``) not negative and at most MAX_STD_DEG."""
    for name, rows in _matrices(table).items():
        m, spread = np.array(rows, dtype=float).reshape(-1, 3), name.endswith("_std_deg")
        if not len(m):
            raise ValueError(f"{name}: must be a nodes x 3 matrix (pitch, roll, yaw per node), got no row")
        if spread and (m < 0).any():
            raise ValueError(f"{name}: holds standard deviations, they cannot be negative")
        limit = MAX_STD_DEG if spread else MAX_ANGLE_DEG
        if (np.abs(m) > limit).any():
            what = "a standard deviation" if spread else "an angle"
            raise ValueError(f"{name}: holds {np.abs(m).max():g} deg, beyond the {limit:g} deg {what} of a body's "
                             f"posture can be")


@dataclass(frozen=True)
class _Tremor:
    frequencies_hz: tuple[float, ...]
    relative_power: tuple[float, ...]

    def __post_init__(self) -> None:
        freqs, power = np.array(self.frequencies_hz, dtype=float), np.array(self.relative_power, dtype=float)
        if (freqs.shape != power.shape or len(freqs) < 3 or freqs[0] != 0 or np.any(np.diff(freqs) <= 0)
                or freqs[-1] > SAMPLE_RATE_HZ / 2 or np.any(power < 0) or not np.any(power > 0)):
            raise ValueError(f"frequencies_hz: must rise from 0 to at most {SAMPLE_RATE_HZ / 2} Hz, with as many "
                             "non-negative relative_power values, not all 0")


@dataclass(frozen=True)
class _Neutral:
    angles_deg: Matrix            # absolute
    rep_std_deg: Matrix           # neutral-to-neutral
    sway_std_deg: Matrix
    tremor_std_deg: Matrix
    carry_over: Matrix | None = None   # how much of a rest's offset the next rest keeps (absent: none)

    def __post_init__(self) -> None:
        _check_degrees(self)
        if self.carry_over is not None:
            carry = np.array(self.carry_over, dtype=float)
            if carry.shape != np.array(self.rep_std_deg).shape or (carry < 0).any() or (carry >= 1).any():
                raise ValueError("carry_over: must be a matrix like rep_std_deg, each value in [0, 1), got "
                                 f"{carry.tolist()}")


@dataclass(frozen=True)
class _Class:
    label: int
    posture_deg: Matrix
    rep_std_deg: Matrix
    day_gain_log_std: float
    day_std_deg: Matrix
    sway_std_deg: Matrix
    tremor_std_deg: Matrix
    range_share: float = 1.0      # the share of the nominal posture this person reaches (P5's thumb)

    def __post_init__(self) -> None:
        if self.label <= NEUTRAL_LABEL:
            raise ValueError(f"label: must be a positive integer, got {self.label}")
        _check_degrees(self)
        within(self, 0.0, 2.0, "day_gain_log_std")
        within(self, 0.0, 1.0, "range_share")


@dataclass(frozen=True)
class _ParticipantFile:
    name: str
    profile: str
    onset_s: float
    reaction_s: float
    max_amplitude: float
    tremor: _Tremor
    neutral: _Neutral
    classes: tuple[_Class, ...]
    feel: Feel
    description: str = ""
    onset_sd_s: float = 0.0
    reaction_sd_s: float = 0.0
    spasm: Spasm | None = None
    evoked_spasm: EvokedSpasm | None = None
    provenance: dict[str, str] = field(default_factory=dict)
    protocol: Protocol | None = None

    def __post_init__(self) -> None:
        for key in ("name", "profile"):
            if not getattr(self, key):
                raise ValueError(f"{key}: must be a non-empty string")
        within(self, DT, 10.0, "onset_s")
        within(self, 0.0, 10.0, "reaction_s")
        within(self, 0.0, 5.0, "onset_sd_s", "reaction_sd_s")
        within(self, 0.01, 1.0, "max_amplitude")
        self._check_across()

    def _check_across(self) -> None:
        """What spans tables: the classes' labels, the nodes of every matrix (as many as [neutral]
        angles_deg has rows) and of the spasms, the classes that the evoked spasms and the protocol
        name."""
        if not self.classes:
            raise ValueError("classes: must be at least one [[classes]] table")
        labels = [c.label for c in self.classes]
        for k, label in enumerate(labels):
            if label in labels[:k]:
                raise ValueError(f"[classes[{k}]] label: {label} is used by an earlier class")
        n_nodes = len(self.neutral.angles_deg)
        tables = {"neutral": self.neutral, **{f"classes[{k}]": c for k, c in enumerate(self.classes)}}
        for where, table in tables.items():
            for name, rows in _matrices(table).items():
                if len(rows) != n_nodes:
                    raise ValueError(f"[{where}] {name}: must be a {n_nodes} x 3 matrix (pitch, roll, yaw per node, "
                                     f"as many rows as [neutral] angles_deg), got {len(rows)} rows")
        if self.spasm is not None and max(self.spasm.nodes) > n_nodes:
            raise ValueError(f"[spasm] nodes: must list node positions 1..{n_nodes}, got {list(self.spasm.nodes)}")
        if self.evoked_spasm is not None and set(self.evoked_spasm.classes) - set(labels):
            raise ValueError(f"[evoked_spasm] classes: must list motion classes of the participant ({sorted(labels)}), "
                             f"not {sorted(set(self.evoked_spasm.classes) - set(labels))}")
        performed = {NEUTRAL_LABEL, *labels}
        if self.protocol is not None and set(self.protocol.labels) - performed:
            raise ValueError(f"[protocol] labels: must list classes of the participant ({sorted(performed)}), "
                             f"not {sorted(set(self.protocol.labels) - performed)}")


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
    return parse_text(text, source, "participant", _parse)


def _parse(data: dict, source: str) -> ParticipantParams:
    file = from_table(_ParticipantFile, data)
    neutral = file.neutral
    n_nodes = len(neutral.angles_deg)
    classes = {c.label: ClassMotion(c.label, c.range_share * _array(c.posture_deg), _array(c.rep_std_deg),
                                    c.day_gain_log_std, _array(c.day_std_deg), _array(c.sway_std_deg),
                                    _array(c.tremor_std_deg))
               for c in file.classes}
    return ParticipantParams(
        name=file.name, profile=file.profile, description=file.description, onset_s=file.onset_s,
        reaction_s=file.reaction_s, onset_sd_s=file.onset_sd_s, reaction_sd_s=file.reaction_sd_s,
        max_amplitude=file.max_amplitude,
        tremor_spectrum=(_array(file.tremor.frequencies_hz), _array(file.tremor.relative_power)),
        neutral=ClassMotion(NEUTRAL_LABEL, _array(neutral.angles_deg), _array(neutral.rep_std_deg), 0.0,
                            np.zeros((n_nodes, 3)), _array(neutral.sway_std_deg), _array(neutral.tremor_std_deg)),
        classes=classes, spasm=file.spasm, evoked_spasm=file.evoked_spasm, feel=file.feel, source=source,
        protocol=file.protocol, provenance=file.provenance,
        rest_carry=None if neutral.carry_over is None else _array(neutral.carry_over))


def _array(values: tuple) -> np.ndarray:
    return np.array(values, dtype=float)


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
