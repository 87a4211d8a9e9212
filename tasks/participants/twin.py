"""The twin: a virtual participant fitted to a person's calibration recording(s) (`bomi twin`).

    bomi twin REC... --out P.toml [--profile PROFILE] [--prior P1]

Each recording is one *pass* (a day, or a session of a day). Only numbers leave the recordings,
each measured where the recordings show it and taken from a documented prior otherwise:

- the posture of each class (median held level minus the neutral around it), its spread from
  repetition to repetition within a pass, its slow sway and tremor in holds (level per node and
  angle, the sway corrected for what a hold's median takes of it; the tremor's spectrum from the
  first node);
- the onset (duration of a move) and reaction time (cue to movement), from the transitions of
  continuous recordings (cue-labelled, every row kept: what `bomi record` writes). Post-processed
  recordings keep only the holds, stitched (the published 5-day set): no transition to measure;
- the drift of each class between passes (a log-normal gain and an offset), from two passes or more.

What one pass cannot show (its drift between days, timing in a stitched file, noise levels of a
class whose holds are too short) comes from the prior participant (default P1, fitted by this same
code on its five days; docs/virtual_participant.md). The file written says, per parameter, whether
it was measured and from what, or which prior it took (``[provenance]``), and holds the protocol of
the first recording (``[protocol]``: its runs of classes and their durations) that `bomi synth`
performs. ``P1.toml`` is this fitter on the five published days:

    bomi twin $BOMI_DATA_DIR/day{1,2,3,4,5}_testp.mat --profile P1 --name P1 --out tasks/participants/P1.toml
"""
from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.optimize
import scipy.signal
from tqdm import tqdm

from bomi.classifier import NEUTRAL_LABEL
from bomi.errors import BomiError
from bomi.frames import SAMPLE_RATE_HZ
from bomi.profiles import Profile
from bomi.recording import Recording, Signal
from tasks.participants.motion import SWAY_CUTOFF_HZ, ColouredNoise, minimum_jerk, sway_filter
from tasks.participants.params import ClassMotion, ParticipantParams, Protocol

EDGE_SAMPLES = 30              # dropped at both ends of a block before filtering statistics
MAX_REPEATED_ROWS = 0.25       # blocks of a node with more held (repeated) rows are not used for noise
WELCH_SEGMENT = 128            # samples per Welch segment of the tremor spectrum (0.49 Hz bins)
SPECTRUM_FLOOR = 0.1           # above the peak, the tremor spectrum ends where it falls below this share of the peak
MIN_DAY_GAIN = 0.1             # guards the log of a day's gain (never reached on P1)
SATURATED_SHARE = 0.1          # a channel at its extreme value for more of the samples is clipped, not a body
MIN_CLASS_SAMPLES = 31         # 0.5 s: fewer held samples of a class and its posture is not measurable (error)
MIN_TRANSITIONS = 3            # fewer measurable transitions and onset/reaction come from the prior
MIN_TRANSITION_DEG = 3.0       # a transition smaller than this (all angles) is not timed
SETTLE_MARGIN_S = 0.3          # continuous recordings: a block's hold starts this long after the measured settle
# The timing prior when no recording shows a transition (the published ones do not): voluntary head
# moves of 25-30 deg take 0.5-1 s, simple reaction times are 0.2-0.5 s (docs/virtual_participant.md).
ASSUMED_ONSET_S = 0.8
ASSUMED_REACTION_S = 0.4
# How the participant leans through the BoMI (tasks.participants.participant.Feel): recordings of
# holds do not show it; written as assumed, the same as P4's and P5's files.
ASSUMED_FEEL = """
[feel]   # how the participant drives a proportional class through the BoMI (tasks/stacking/episode.py); assumed, the same for P1, P4, P5
least_lean = 0.5           # the least lean used, and calibrated with (half the body's range): the calibrated nu range spans the leans used
lean_step = 0.15           # a correction leans this much further (arm too slow or not answering) or less far (too fast)
watch_s = 1.0              # s: after reaction + move, how long a posture is watched before it is corrected
speed_smoothing_s = 0.3    # s: the arm's speed is judged over about this long
too_slow = 0.5             # seen / wanted speed below which the participant leans further
too_fast = 2.0             # seen / wanted speed above which the participant leans less far
max_zero = 0.9             # the learnt zero lean never exceeds this: the least deflection needs less than full range
"""


@functools.cache
def _min_jerk_time(share: float) -> float:
    """The share of a minimum-jerk move's duration after which it has covered ``share`` of its way."""
    return float(scipy.optimize.brentq(lambda s: minimum_jerk(np.array([s]))[0] - share, 0.0, 1.0))


TIMING_SHARES = (0.1, 0.9)     # a move is timed where it has covered 10 % and 90 % of its way
# What a fitted timing may be (docs/virtual_participant.md, "Timing a real file supports"): a cued
# reaction faster than 0.1 s is an anticipation, not a reaction (Luce 1986), and a choice among up to
# nine cued postures takes well under a second (Hick 1952); voluntary head and limb moves of the
# protocol's size take 0.2-2 s (head: Zangemeister, Lehman & Stark 1981; arm: Flash & Hogan 1985).
ONSET_BOUNDS_S = (0.2, 2.0)
REACTION_BOUNDS_S = (0.1, 1.0)


@dataclass(frozen=True)
class Block:
    """One run of equal labels of a pass: rows [start, stop)."""

    day: int
    label: int
    start: int
    stop: int


def hold_blocks(labels: np.ndarray, day: int) -> list[Block]:
    """The runs of equal labels of one recording."""
    edges = np.r_[0, np.flatnonzero(np.diff(labels.astype(int))) + 1, len(labels)]
    return [Block(day, int(labels[a]), int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def stacked_angles(rec: Recording, nodes: Sequence[int] | None = None) -> np.ndarray:
    """(n, nodes, 3) fused angles of ``nodes`` (default: every node of the recording), in that order."""
    return np.stack([rec.nodes[i].angles for i in (nodes or rec.node_indices)], axis=1)


def repeated_fraction(x: np.ndarray) -> float:
    """Share of rows identical to the previous one (the recorder holds a node's last sample on loss)."""
    return float(np.mean(np.all(np.diff(x, axis=0) == 0, axis=-1))) if len(x) > 1 else 1.0


def split_sway_tremor(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A hold's (n, 3) angles -> slow sway around the hold's median and tremor (above SWAY_CUTOFF_HZ), edges dropped."""
    b, a = scipy.signal.butter(2, SWAY_CUTOFF_HZ, "high", fs=SAMPLE_RATE_HZ)
    tremor = scipy.signal.filtfilt(b, a, x, axis=0)
    sway = x - tremor - np.median(x, axis=0)
    keep = slice(EDGE_SAMPLES, -EDGE_SAMPLES)
    return sway[keep], tremor[keep]


SPLIT_DRAWS = 400             # simulated holds of the model's sway when measuring the split's gain


@functools.cache
def sway_gain(samples: int) -> float:
    """The median std the sway/tremor split measures over holds of ``samples`` per unit std of the
    participant model's sway (simulated, fixed seed: deterministic). Below 1: a hold's median takes
    the slowest sway (0.75 over the published 5 s holds)."""
    x = ColouredNoise(*sway_filter(), SPLIT_DRAWS, np.random.default_rng(0)).next(samples)
    return float(np.median(split_sway_tremor(x)[0].std(axis=0)))


def motion_spectrum(freqs: np.ndarray, psd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tremor spectrum relative to its peak, up to where it first falls below SPECTRUM_FLOOR past the peak.

    The fused angles' power beyond is not body motion: the gyroscopes see only 0.8-1.3 deg/s in
    holds, which the tremor up to there already accounts for (see docs/virtual_participant.md).
    """
    relative = psd / psd.max()
    peak = int(np.argmax(relative))
    end = peak + int(np.argmax(relative[peak:] < SPECTRUM_FLOOR))
    return freqs[:end + 1], np.r_[relative[:end], 0.0]


def isotropic_yaw(stds: np.ndarray) -> np.ndarray:
    """(nodes, 3) stds with yaw set to the mean of pitch and roll.

    The recordings' fused yaw is not the host fusion's (dataset README) and its wobble within
    holds is not seen by the gyroscopes (0.8-1.3 deg/s), so it is not body motion.
    """
    out = np.array(stds, dtype=float)
    out[:, 2] = out[:, :2].mean(axis=1)
    return out


# ------------------------------------------------------------------------------------ timing
@dataclass(frozen=True)
class Transition:
    """A move from one run's level to the next one's: when it covered 10 % and 90 % of its way,
    in seconds after the cue (the label change); None when the signal jumps (a stitched file)."""

    t10: float | None
    t90: float | None

    @property
    def stitched(self) -> bool:
        return self.t10 is None


def transition(x: np.ndarray, time: np.ndarray, before: Block, after: Block) -> Transition | None:
    """The move from ``before``'s level to ``after``'s in the (n, k) flattened angles ``x`` at ``time``
    (s; levels: medians of each run's second half); None when it is too small or not complete within ``after``."""
    old = np.median(x[(before.start + before.stop) // 2:before.stop], axis=0)
    new = np.median(x[(after.start + after.stop) // 2:after.stop], axis=0)
    way = new - old
    if np.linalg.norm(way) < MIN_TRANSITION_DEG:
        return None
    progress = (x[after.start:(after.start + after.stop) // 2] - old) @ way / (way @ way)
    if len(progress) < 2:
        return None
    if progress[:2].mean() > 0.5:
        return Transition(None, None)
    crossed = [np.flatnonzero(progress >= share) for share in TIMING_SHARES]
    if any(len(c) == 0 for c in crossed):
        return None
    t10 = crossed[0][0]
    later = crossed[1][crossed[1] > t10]
    if not len(later):
        return None
    cue = time[after.start]
    return Transition(float(time[after.start + t10] - cue), float(time[after.start + later[0]] - cue))


def implausible_timing(onset: float, reaction: float) -> str | None:
    """Why a fitted (onset_s, reaction_s) is outside ONSET_BOUNDS_S / REACTION_BOUNDS_S, or None."""
    out = [f"{what} {value:.2f} s outside {low:g}-{high:g} s"
           for what, value, (low, high) in (("onset", onset, ONSET_BOUNDS_S), ("reaction", reaction, REACTION_BOUNDS_S))
           if not low <= value <= high]
    return "; ".join(out) or None


def timing_from(transitions: Sequence[Transition]) -> tuple[float, float] | None:
    """(onset_s, reaction_s) of a minimum-jerk move fitted to the median 10 % and 90 % times; None if too few."""
    timed = [t for t in transitions if not t.stitched]
    if len(timed) < MIN_TRANSITIONS:
        return None
    t10 = float(np.median([t.t10 for t in timed]))
    t90 = float(np.median([t.t90 for t in timed]))
    share10, share90 = (_min_jerk_time(share) for share in TIMING_SHARES)
    onset = (t90 - t10) / (share90 - share10)
    return onset, max(t10 - share10 * onset, 0.0)


# ------------------------------------------------------------------------------------ a pass
@dataclass
class Pass:
    """One recording in the profile's node order: its angles, runs and whether it shows transitions."""

    source: str
    angles: np.ndarray              # (n, nodes, 3)
    time: np.ndarray                # (n,) s: the recording's Time, else the row count at the sample rate
    blocks: list[Block]
    transitions: list[Transition]

    @property
    def continuous(self) -> bool:
        """The recording keeps the moves (timed transitions outnumber jumps), not just the holds."""
        timed = sum(not t.stitched for t in self.transitions)
        return timed > len(self.transitions) - timed

    def holds(self, settle_s: float) -> list[Block]:
        """The blocks cut to their holds: in a continuous recording, a block after a change of label
        starts ``settle_s`` + SETTLE_MARGIN_S later (the move)."""
        if not self.continuous:
            return self.blocks
        cut = int(np.ceil((settle_s + SETTLE_MARGIN_S) * SAMPLE_RATE_HZ))
        return [Block(b.day, b.label, min(b.start + (cut if k else 0), b.stop), b.stop)
                for k, b in enumerate(self.blocks)]

    def protocol(self) -> Protocol:
        """Each run from its first row to the next run's first row (the last: to its last row, and one period)."""
        starts = np.r_[[self.time[b.start] for b in self.blocks], self.time[-1] + 1.0 / SAMPLE_RATE_HZ]
        return Protocol(labels=tuple(b.label for b in self.blocks),
                        durations_s=tuple(round(float(d), 3) for d in np.diff(starts)),
                        holds_only=not self.continuous, source=Path(self.source).name)


def read_pass(rec: Recording, day: int, profile: Profile) -> Pass:
    """A recording as a pass of ``profile``'s nodes and classes; one-line BomiError when it cannot be one."""
    nodes = list(profile.node_indices)
    rec.require(nodes, (Signal.ANGLES,), "a twin")
    labels = rec.require_labels()
    known = {cls.label for cls in profile.classes}
    unknown = sorted(set(labels.tolist()) - known)
    if unknown:
        raise BomiError(f"{rec.source}: labels {unknown} are not classes of profile {profile.name} "
                        f"({sorted(known)})")
    if NEUTRAL_LABEL not in labels:
        raise BomiError(f"{rec.source}: no neutral posture (label {NEUTRAL_LABEL}): a twin measures every posture "
                        "from the neutral")
    check_sensors_alive(rec, nodes)
    if rec.time is not None and np.any(np.diff(rec.time) < 0):
        row = int(np.flatnonzero(np.diff(rec.time) < 0)[0]) + 1
        raise BomiError(f"{rec.source}: Time goes back at row {row} ({rec.time[row - 1]:g} then "
                        f"{rec.time[row]:g} s): a twin times the protocol from it")
    angles = stacked_angles(rec, nodes)
    blocks = hold_blocks(labels, day)
    flat = angles.reshape(len(angles), -1)
    time = rec.time if rec.time is not None else np.arange(len(rec)) / SAMPLE_RATE_HZ
    moves = [transition(flat, time, a, b) for a, b in zip(blocks[:-1], blocks[1:])]
    return Pass(rec.source, angles, time, blocks, [t for t in moves if t is not None])


def dead_channels(rec: Recording, nodes: Sequence[int]) -> list[str]:
    """The channels of ``nodes`` that show no body: constant (zero included) over the whole
    recording, or saturated (more than SATURATED_SHARE of the samples at the channel's extreme value)."""
    dead = []
    for node in nodes:
        data = rec.nodes[node]
        for signal in data.signals:
            values = getattr(data, signal.value)
            for axis in range(values.shape[1]):
                x = values[:, axis]
                name = f"node {node} {signal.value}[{axis}]"
                if np.ptp(x) == 0:
                    dead.append(f"{name} constant at {x[0]:g}")
                elif max(np.mean(x == x.max()), np.mean(x == x.min())) > SATURATED_SHARE:
                    dead.append(f"{name} saturated")
    return dead


def check_sensors_alive(rec: Recording, nodes: Sequence[int]) -> None:
    """One line naming the recording and its dead channels, if any: a twin of them would be
    postures of zero (or of a clipped sensor), not of a person."""
    dead = dead_channels(rec, nodes)
    if dead:
        more = f" and {len(dead) - 3} more" if len(dead) > 3 else ""
        raise BomiError(f"{rec.source}: dead sensor channel(s): {', '.join(dead[:3])}{more}; a twin needs a "
                        "recording of live sensors")


def same_person(recordings: Sequence[Recording]) -> None:
    """The recordings of one `bomi twin` are one person's passes: the same nodes and the same classes.
    One line naming the first that differs from the first recording."""
    first = recordings[0]
    shape = (first.node_indices, sorted(set(first.require_labels().tolist())))
    for rec in recordings[1:]:
        other = (rec.node_indices, sorted(set(rec.require_labels().tolist())))
        if other != shape:
            raise BomiError(f"{rec.source}: nodes {list(other[0])}, classes {other[1]}; {first.source} has nodes "
                            f"{list(shape[0])}, classes {shape[1]}: not passes of one person (--same-person: they "
                            "are, fit them together)")


def check_class_samples(passes: Sequence[Pass], profile: Profile) -> None:
    """Every class of the profile needs MIN_CLASS_SAMPLES labelled rows over the recordings."""
    for cls in profile.classes:
        n = sum(b.stop - b.start for p in passes for b in p.blocks if b.label == cls.label)
        if n < MIN_CLASS_SAMPLES:
            sources = ", ".join(Path(p.source).name for p in passes)
            raise BomiError(f"{sources}: class c{cls.label} ({cls.name}) has {n} labelled samples, a twin needs at "
                            f"least {MIN_CLASS_SAMPLES} ({MIN_CLASS_SAMPLES / SAMPLE_RATE_HZ:.1f} s) to measure its "
                            "posture")


# ------------------------------------------------------------------------------------ the fit
@dataclass
class Twin:
    """Everything the participant file stores; arrays are (nodes, 3) unless noted. ``provenance``:
    per parameter, measured from what, or which prior."""

    name: str
    profile: str
    passes: int
    onset_s: float
    reaction_s: float
    neutral_deg: np.ndarray
    neutral_rep_std: np.ndarray
    neutral_sway_std: np.ndarray
    neutral_tremor_std: np.ndarray
    tremor_spectrum: tuple[np.ndarray, np.ndarray]   # frequencies (Hz), power relative to the peak
    postures: dict[int, np.ndarray]
    rep_std: dict[int, np.ndarray]
    day_gain_log_std: dict[int, float]
    day_std: dict[int, np.ndarray]
    sway_std: dict[int, np.ndarray]
    tremor_std: dict[int, np.ndarray]
    protocol: Protocol
    provenance: dict[str, str]
    fallbacks: list[str] = field(default_factory=list)   # what could not be measured, said on stdout


def _typical(stds: list[np.ndarray]) -> np.ndarray:
    """Median over blocks of per-block standard deviations (robust to the stitching jumps); NaN if none."""
    return np.median(stds, axis=0) if stds else np.full(3, np.nan)


@dataclass
class _Holds:
    """What the held postures of every pass show, gathered block by block."""

    n_nodes: int
    deltas: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)  # (label, day) -> per-repetition deltas
    levels: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)  # (label, day) -> per-repetition medians
    neutral_levels: dict[int, list[np.ndarray]] = field(default_factory=dict)      # day -> c0 block medians
    sway: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)    # (label, node) -> per-block std (3,)
    tremor: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)
    spectra: list[np.ndarray] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)    # samples of every block measured for noise

    def add_levels(self, day: int, blocks: list[Block], angles: np.ndarray) -> None:
        """Each block's median posture; a motion's as a delta from the neutral before and after it
        (robust to the slow yaw drift), or from the pass's median neutral when none is adjacent."""
        medians = [np.median(angles[b.start:b.stop], axis=0) for b in blocks]
        neutral = [m for b, m in zip(blocks, medians) if b.label == NEUTRAL_LABEL]
        for k, (block, level) in enumerate(zip(blocks, medians)):
            if block.label == NEUTRAL_LABEL:
                self.neutral_levels.setdefault(day, []).append(level)
                continue
            around = [medians[j] for j in (k - 1, k + 1) if 0 <= j < len(blocks) and blocks[j].label == NEUTRAL_LABEL]
            reference = np.mean(around, axis=0) if around else np.median(neutral, axis=0)
            self.deltas.setdefault((block.label, day), []).append(level - reference)
            self.levels.setdefault((block.label, day), []).append(level)

    def add_noise(self, blocks: list[Block], angles: np.ndarray) -> None:
        """Sway and tremor of every usable block and node; the first node's tremor spectrum."""
        for block in blocks:
            for node in range(self.n_nodes):
                x = angles[block.start:block.stop, node]
                if len(x) <= 4 * EDGE_SAMPLES or repeated_fraction(x) > MAX_REPEATED_ROWS:
                    continue
                s, t = split_sway_tremor(x)
                self.lengths.append(len(x))
                self.sway.setdefault((block.label, node), []).append(s.std(axis=0))
                self.tremor.setdefault((block.label, node), []).append(t.std(axis=0))
                if node == 0 and len(t) >= WELCH_SEGMENT:
                    self.spectra.append(
                        scipy.signal.welch(t, fs=SAMPLE_RATE_HZ, nperseg=WELCH_SEGMENT, axis=0)[1].sum(axis=1))

    def per_node(self, table: dict, label: int) -> np.ndarray:
        return np.array([_typical(table.get((label, node), [])) for node in range(self.n_nodes)])

    def noise(self, label: int) -> tuple[np.ndarray, np.ndarray]:
        """A class's (sway, tremor) stds per node (NaN: no hold measured); the sway divided by the
        split's gain for the typical hold length, so that the twin's sessions, split the same way,
        show the sway measured here. The tremor is taken as measured (its leak from the sway, and the
        sway's from it, are left: a weak tremor's spectrum, measured in that band, does not show them)."""
        sway, tremor = self.per_node(self.sway, label), self.per_node(self.tremor, label)
        return (sway / sway_gain(int(np.median(self.lengths))) if self.lengths else sway), tremor

    def per_day(self, table: dict, label: int, days: int) -> list[np.ndarray]:
        return [np.array(table[(label, d)]) for d in range(1, days + 1) if (label, d) in table]


def within_pass_std(groups: Sequence[np.ndarray]) -> np.ndarray | None:
    """The pooled standard deviation of repetitions around their own pass's mean (unbiased: each pass
    with n repetitions gives n - 1 degrees of freedom); None when no pass repeats."""
    repeated = [g for g in groups if len(g) > 1]
    if not repeated:
        return None
    squares = sum(np.sum((g - g.mean(axis=0)) ** 2, axis=0) for g in repeated)
    return np.sqrt(squares / sum(len(g) - 1 for g in repeated))


def _day_variation(days: list[np.ndarray], day_means_of: list[np.ndarray], posture: np.ndarray, rep_var: np.ndarray
                   ) -> tuple[float, np.ndarray]:
    """(day gain log-std, day offset std) of one class from its per-day repetitions (deltas): a day's
    mean posture = gain x nominal posture + an offset, the gain log-normal, fitted on the angles the
    feature vectors use (not the yaw of the second node on, unreliable in the published files)."""
    reps_per_day = np.mean([len(reps) for reps in days])
    day_means = np.array(day_means_of)
    used = np.ones_like(posture)
    used[1:, 2] = 0.0
    gains = np.einsum("dij,ij->d", day_means, posture * used) / np.sum((posture * used) ** 2)
    gains = np.clip(gains, MIN_DAY_GAIN, None)
    offsets = day_means - gains[:, None, None] * posture
    # var(day offsets) = day var + rep var / reps per day
    day_var = np.var(offsets, axis=0, ddof=1) - rep_var / reps_per_day
    return float(np.std(np.log(gains), ddof=1)), np.sqrt(np.clip(day_var, 0.0, None))


def prior_day_variation(prior: ParticipantParams, profile: str, label: int, rep_std: np.ndarray
                        ) -> tuple[float, np.ndarray, str]:
    """A class's drift between days when the recordings show one pass: the prior's own class when
    it was fitted for the same profile (the same motion), else its typical drift: the median gain
    log-std over its classes, and an offset std of the median ratio of its classes' offset to
    repetition spread, times this class's repetition spread."""
    if prior.profile == profile and label in prior.classes:
        m = prior.classes[label]
        return m.day_gain_log_std, m.day_std_deg, f"prior: {prior.name}'s class c{label} ({Path(prior.source).name})"
    gain = float(np.median([m.day_gain_log_std for m in prior.classes.values()]))
    ratio = float(np.median([np.linalg.norm(m.day_std_deg) / max(np.linalg.norm(m.rep_std_deg), 1e-9)
                             for m in prior.classes.values()]))
    return gain, ratio * rep_std, f"prior: {prior.name}'s typical class drift ({Path(prior.source).name})"


def _names(passes: Sequence[Pass]) -> str:
    return ", ".join(Path(p.source).name for p in passes)


def fit_twin(recordings: Sequence[Recording], profile: Profile, prior: ParticipantParams | None,
             name: str, profile_ref: str | None = None) -> Twin:
    """Measure a participant from one recording per pass (all of ``profile``'s nodes and classes).

    ``prior`` supplies what the recordings cannot show (None: everything must be measurable, as
    for P1's five days; a BomiError says what is not). ``profile_ref`` is what the file names as
    its profile (default: the profile's name).
    """
    passes = [read_pass(rec, day, profile) for day, rec in enumerate(recordings, start=1)]
    check_class_samples(passes, profile)
    names = _names(passes)
    fallbacks: list[str] = []
    provenance: dict[str, str] = {}

    def from_prior(keys: Sequence[str], why: str, what: str | None = None) -> None:
        """Say that ``keys`` could not be measured and come from the prior (an error without one)."""
        if prior is None:
            raise BomiError(f"{names}: {why}, and no prior participant was given")
        what = what or f"prior: {prior.name} ({Path(prior.source).name})"
        provenance.update({key: what + (f" [there: {prior.provenance[key]}]" if key in prior.provenance else "")
                           for key in keys})
        fallbacks.append(f"{', '.join(keys)}: {why}; {what}")

    transitions = [t for p in passes for t in p.transitions]
    timing = timing_from(transitions)
    continuous = [p for p in passes if p.continuous]
    implausible = None if timing is None else implausible_timing(*timing)
    if timing is not None and continuous and implausible is None:
        onset, reaction = timing
        timed = sum(not t.stitched for t in transitions)
        for key in ("onset_s", "reaction_s"):
            provenance[key] = (f"measured: minimum-jerk fit to the median 10 %/90 % times of {timed} transitions "
                               f"({_names(continuous)})")
    else:
        onset, reaction = (ASSUMED_ONSET_S, ASSUMED_REACTION_S) if prior is None else (prior.onset_s, prior.reaction_s)
        why = ("the recordings keep only the holds (no transition)" if not continuous
               else f"fewer than {MIN_TRANSITIONS} measurable transitions" if timing is None
               else f"the timing measured from the transitions is not plausible ({implausible}; "
                    "docs/virtual_participant.md): are the labels the cues?")
        if prior is None:
            for key in ("onset_s", "reaction_s"):
                provenance[key] = f"assumed: {why}; voluntary moves take 0.5-1 s, simple reactions 0.2-0.5 s"
        else:
            from_prior(("onset_s", "reaction_s"), why)

    n_nodes = len(profile.nodes)
    holds = _Holds(n_nodes)
    for p in tqdm(passes, desc="measuring passes", unit="pass", disable=len(passes) < 2):
        blocks = p.holds(reaction + onset)
        holds.add_levels(p.blocks[0].day, blocks, p.angles)
        holds.add_noise(blocks, p.angles)
    labels = sorted(cls.label for cls in profile.classes if cls.label != NEUTRAL_LABEL)
    n_passes = len(passes)
    per_day = {label: holds.per_day(holds.deltas, label, n_passes) for label in labels}
    per_day_levels = {label: holds.per_day(holds.levels, label, n_passes) for label in labels}
    postures = {label: np.median(np.concatenate(per_day[label]), axis=0) for label in labels}
    provenance["posture_deg"] = (f"measured: median over repetitions of each hold's median minus the neutral "
                                 f"around it ({names})")

    # repetition spread: of the held level within a pass; classes never repeated take the pooled spread
    day_neutrals = [np.array(levels) for _, levels in sorted(holds.neutral_levels.items())]
    pooled = within_pass_std([reps for days in per_day_levels.values() for reps in days])
    rep_std: dict[int, np.ndarray] = {}
    for label in labels:
        own = within_pass_std(per_day_levels[label])
        if own is not None or pooled is not None:
            rep_std[label] = own if own is not None else pooled
    once = [label for label in labels if label in rep_std and not any(len(r) > 1 for r in per_day_levels[label])]
    provenance["rep_std_deg"] = (f"measured: spread of each class's held levels around its pass mean ({names})"
                                 + (f"; {', '.join(f'c{c}' for c in once)} shown once per pass: pooled over the "
                                    "classes that repeat" if once else ""))
    missing = [label for label in labels if label not in rep_std]
    if missing:
        from_prior(("rep_std_deg",), "no class is repeated within a pass")
        for label in missing:
            rep_std[label] = prior_nodes(prior, profile, prior_class(prior, profile.name, label).rep_std_deg)
    neutral_rep_std = within_pass_std(day_neutrals)
    if neutral_rep_std is not None:
        provenance["neutral.rep_std_deg"] = f"measured: spread of the neutral holds' levels within a pass ({names})"
    else:
        from_prior(("neutral.rep_std_deg",), "the neutral posture is held once per pass")
        neutral_rep_std = prior_nodes(prior, profile, prior.neutral.rep_std_deg)

    # drift between passes
    day_gain, day_std = {}, {}
    unseen = [label for label in labels if len(per_day[label]) < 2]
    if unseen and n_passes >= 2:
        from_prior(("day_gain_log_std", "day_std_deg"),
                   f"{', '.join(f'c{c}' for c in unseen)} shown in one pass only")
    for label in labels:
        days = per_day[label]
        if len(days) >= 2:
            day_gain[label], day_std[label] = _day_variation(days, [reps.mean(axis=0) for reps in days],
                                                             postures[label], rep_std[label] ** 2)
        elif prior is not None:
            day_gain[label], day_std[label], _ = prior_day_variation(prior, profile.name, label, rep_std[label])
    if n_passes >= 2 and not unseen:
        provenance["day_gain_log_std"] = provenance["day_std_deg"] = (
            f"measured: each class's mean posture per pass = gain x posture + offset, over {n_passes} passes ({names})")
    elif n_passes < 2:
        what = (prior_day_variation(prior, profile.name, labels[0], rep_std[labels[0]])[2]
                .replace(f"class c{labels[0]}", "classes") if prior is not None else None)
        from_prior(("day_gain_log_std", "day_std_deg"), "one pass shows no drift between days", what)

    if holds.spectra:
        freqs = np.fft.rfftfreq(WELCH_SEGMENT, 1.0 / SAMPLE_RATE_HZ)
        spectrum = motion_spectrum(freqs, np.mean(holds.spectra, axis=0))
        provenance["tremor"] = (f"measured: mean Welch spectrum of node {profile.nodes[0].index}'s pitch + roll "
                                f"tremor over {len(holds.spectra)} holds ({names})")
    else:
        from_prior(("tremor",), f"no hold of node {profile.nodes[0].index} long enough for a "
                             f"{WELCH_SEGMENT}-sample spectrum")
        spectrum = prior.tremor_spectrum

    # sway and tremor: per class where a hold is long enough, else the neutral's, else the prior's
    neutral_sway, neutral_tremor = holds.noise(NEUTRAL_LABEL)
    provenance["sway_std_deg"] = provenance["tremor_std_deg"] = (
        f"measured: median over holds of the std below / above {SWAY_CUTOFF_HZ:g} Hz, the sway divided by "
        f"the split's gain for the model's sway (twin.sway_gain), yaw as the mean of pitch and roll ({names})")
    if np.isnan(neutral_sway).any():
        from_prior(("neutral.sway_std_deg", "neutral.tremor_std_deg"),
                   f"no neutral hold of a node longer than {4 * EDGE_SAMPLES} samples")
        neutral_sway = np.where(np.isnan(neutral_sway), prior_nodes(prior, profile, prior.neutral.sway_std_deg),
                                neutral_sway)
        neutral_tremor = np.where(np.isnan(neutral_tremor), prior_nodes(prior, profile, prior.neutral.tremor_std_deg),
                                  neutral_tremor)
    neutral_sway, neutral_tremor = isotropic_yaw(neutral_sway), isotropic_yaw(neutral_tremor)
    noise = {label: holds.noise(label) for label in labels}
    sway = {label: isotropic_yaw(noise[label][0]) for label in labels}
    tremor = {label: isotropic_yaw(noise[label][1]) for label in labels}
    short = [label for label in labels if np.isnan(sway[label]).any()]
    if short:
        note = (f"{', '.join(f'c{c}' for c in short)}: no hold longer than {4 * EDGE_SAMPLES} samples on some node, "
                "the neutral's level there")
        provenance["sway_std_deg"] += f"; {note}"
        fallbacks.append(f"sway_std_deg, tremor_std_deg: {note}")
        sway = {label: np.where(np.isnan(s), neutral_sway, s) for label, s in sway.items()}
        tremor = {label: np.where(np.isnan(s), neutral_tremor, s) for label, s in tremor.items()}

    first = Path(passes[0].source).name
    provenance["neutral.angles_deg"] = f"measured: median of the first pass's neutral holds ({first})"
    provenance["max_amplitude"] = "definition: the postures are measured as performed (full range)"
    provenance["feel"] = "assumed: recordings of holds do not show how a person leans through the BoMI (as P4, P5)"
    provenance["protocol"] = f"the runs of {first}, for bomi synth"
    return Twin(
        name=name, profile=profile_ref or profile.name, passes=n_passes, onset_s=onset, reaction_s=reaction,
        neutral_deg=np.median(day_neutrals[0], axis=0) if day_neutrals else np.zeros((n_nodes, 3)),
        neutral_rep_std=neutral_rep_std, neutral_sway_std=neutral_sway, neutral_tremor_std=neutral_tremor,
        tremor_spectrum=spectrum, postures=postures, rep_std=rep_std, day_gain_log_std=day_gain, day_std=day_std,
        sway_std=sway, tremor_std=tremor, protocol=passes[0].protocol(), provenance=provenance, fallbacks=fallbacks)


def prior_nodes(prior: ParticipantParams, profile: Profile, matrix: np.ndarray) -> np.ndarray:
    """A (nodes, 3) matrix of the prior for this profile's nodes: as it is for the same profile, else
    its median node, for every node."""
    if prior.profile == profile.name and matrix.shape[0] == len(profile.nodes):
        return matrix
    return np.tile(np.median(matrix, axis=0), (len(profile.nodes), 1))


def prior_class(prior: ParticipantParams, profile: str, label: int) -> ClassMotion:
    """The prior's class of the same label for the same profile, else its class of median repetition spread."""
    if prior.profile == profile and label in prior.classes:
        return prior.classes[label]
    classes = sorted(prior.classes.values(), key=lambda m: float(np.linalg.norm(m.rep_std_deg)))
    return classes[len(classes) // 2]


# ------------------------------------------------------------------------------------ writing
def _toml_matrix(m: np.ndarray) -> str:
    return "[" + ", ".join("[" + ", ".join(f"{v:.3f}" for v in row) + "]" for row in m) + "]"


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def twin_toml(twin: Twin, description: str) -> str:
    """The participant file (schema: tasks/participants/participant.py), provenance and protocol included."""
    protocol = twin.protocol
    lines = [
        f"# Virtual participant {twin.name}, fitted by `bomi twin` (tasks/participants/twin.py) on {twin.passes}",
        "# recording(s): numbers only, no data. Angles are (pitch, roll, yaw) in degrees per node, in the",
        f"# node order of profile {twin.profile}. [provenance] says where each parameter comes from;",
        "# docs/virtual_participant.md explains each step.",
        f"name = {_toml_string(twin.name)}",
        f"profile = {_toml_string(twin.profile)}",
        f"description = {_toml_string(description)}",
        f"onset_s = {round(twin.onset_s, 3):g}",
        f"reaction_s = {round(twin.reaction_s, 3):g}",
        "max_amplitude = 1.0",
        "",
        "[tremor]   # power spectrum of the first node's tremor (fused pitch and roll above 1 Hz) in holds",
        "frequencies_hz = [" + ", ".join(f"{f:.3f}" for f in twin.tremor_spectrum[0]) + "]",
        "relative_power = [" + ", ".join(f"{p:.4f}" for p in twin.tremor_spectrum[1]) + "]",
        "",
        "[neutral]",
        f"angles_deg = {_toml_matrix(twin.neutral_deg)}   # first pass, absolute",
        f"rep_std_deg = {_toml_matrix(twin.neutral_rep_std)}",
        f"sway_std_deg = {_toml_matrix(twin.neutral_sway_std)}",
        f"tremor_std_deg = {_toml_matrix(twin.neutral_tremor_std)}",
    ]
    for label, posture in twin.postures.items():
        lines += [
            "",
            "[[classes]]",
            f"label = {label}",
            f"posture_deg = {_toml_matrix(posture)}",
            f"rep_std_deg = {_toml_matrix(twin.rep_std[label])}",
            f"day_gain_log_std = {twin.day_gain_log_std[label]:.3f}",
            f"day_std_deg = {_toml_matrix(twin.day_std[label])}",
            f"sway_std_deg = {_toml_matrix(twin.sway_std[label])}",
            f"tremor_std_deg = {_toml_matrix(twin.tremor_std[label])}",
        ]
    lines += ["", "[provenance]   # per parameter: measured (how, from which recordings), a prior, or assumed"]
    lines += [f"{_toml_string(key)} = {_toml_string(text)}" for key, text in sorted(twin.provenance.items())]
    lines += ["", "[protocol]   # the runs of the first recording (class, seconds), performed by `bomi synth`",
              f"source = {_toml_string(protocol.source)}",
              f"holds_only = {'true' if protocol.holds_only else 'false'}   # the recording kept only the holds "
              "(stitched), else every row after the cue",
              "labels = [" + ", ".join(str(v) for v in protocol.labels) + "]",
              "durations_s = [" + ", ".join(f"{v:g}" for v in protocol.durations_s) + "]"]
    return "\n".join(lines) + "\n" + ASSUMED_FEEL
