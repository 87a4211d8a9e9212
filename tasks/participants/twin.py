"""The twin: a virtual participant fitted to a person's calibration recording(s) (`bomi twin`).

    bomi twin REC... --out P.toml [--profile PROFILE] [--prior P1]

Each recording is one *pass* (a day, or a session of a day). Only numbers leave the recordings,
each measured where the recordings show it and taken from a documented prior otherwise:

- the posture of each class (median held level minus the neutral around it), its spread from
  repetition to repetition within a pass, its slow sway and tremor in holds (level per node and
  angle, the sway corrected for what a hold's median takes of it; the tremor's spectrum from the
  first node);
- the onset (duration of a move) and reaction time (cue to movement), and their spread from move to
  move, from each move's onset and offset found in the signals (``bomi.onsets``) of continuous
  recordings (cue-labelled, every row kept: what `bomi record` writes); there each hold starts after
  its own move. Post-processed recordings keep only the holds, stitched (the published 5-day set):
  no move to time;
- the drift of each class between passes (a log-normal gain and an offset), from two passes or more.
- the least and the furthest lean through the BoMI (``[feel]``: ``least_lean``, ``most_lean``), where
  the holds' amplitudes begin and end along each class's posture, so that a model trained on the
  recording, whose speed range spans those amplitudes, drives the twin as it would the person.

What one pass cannot show (its drift between days, timing in a stitched file, noise levels of a
class whose holds are too short) comes from the prior participant (default P1, fitted by this same
code on its five days; docs/virtual_participant.md). The file written says, per parameter, whether
it was measured and from what, or which prior it took (``[provenance]``), and holds the protocol of
the first recording (``[protocol]``: its runs of classes and their durations) that `bomi synth`
performs. ``P1.toml`` is this fitter on the five published days:

    bomi twin $BOMI_DATA_DIR/day{1,2,3,4,5}_testp.mat --profile P1 --name P1 --out tasks/participants/P1.toml
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi.classifier import NEUTRAL_LABEL
from bomi.errors import BomiError
from bomi.frames import SAMPLE_RATE_HZ
from bomi.onsets import SPEED_SHARE, Move, MoveKind, find_moves, keeps_moves
from bomi.passes import run_digests
from bomi.profiles import Profile
from bomi.recording import Recording, Signal
from tasks.participants.holds import (EDGE_SAMPLES, MIN_REST_PAIRS, WELCH_SEGMENT, Block, Holds, carry_over,
                                     day_variation, hold_blocks, isotropic_yaw, motion_spectrum, stacked_angles,
                                     within_pass_std)
from tasks.participants.motion import SWAY_CUTOFF_HZ
from tasks.participants.params import ClassMotion, ParticipantParams, Protocol

SATURATED_SHARE = 0.1          # a channel at its extreme value for more of the samples is clipped, not a body
MIN_CLASS_SAMPLES = 31         # 0.5 s: fewer held samples of a class and its posture is not measurable (error)
MIN_TRANSITIONS = 3            # fewer timed moves and onset/reaction come from the prior
SETTLE_MARGIN_S = 0.3          # continuous recordings: a block's hold starts this long after the measured settle
# The timing prior when no recording shows a transition (the published ones do not): voluntary head
# moves of 25-30 deg take 0.5-1 s, simple reaction times are 0.2-0.5 s (docs/virtual_participant.md).
ASSUMED_ONSET_S = 0.8
ASSUMED_REACTION_S = 0.4
# The least and the furthest lean (``Feel.least_lean``, ``Feel.most_lean``) are where the recording's
# holds begin and end: the least and the largest of each class's held samples along its posture (the
# median over classes), the very range a model trained on the recording calibrates its speed on
# (``bomi.classifier.amplitude_ranges``: nu = 0 at the least held sample, 1 at the largest), so that the
# twin drives that model over the speeds it drives the person (issue 53.4). The 5 % and 95 % quantiles
# used before (0.810 and 1.187 for P1) left the slowest third of that range out: run lean-range-dev.
LEAN_QUANTILES = (0.0, 1.0)
LEAN_ENDS = ("least", "largest")   # how the provenance names them
# The rest of how the participant leans through the BoMI (tasks.participants.params.Feel): recordings
# of holds do not show it; written as assumed, the same as P4's and P5's files.
FEEL = """
[feel]   # how the participant drives a proportional class through the BoMI (tasks/stacking/episode.py); least_lean and most_lean measured, the rest assumed as for P1, P4, P5
least_lean = {least_lean:.3f}         # the least lean used, and calibrated with: where the recording's holds begin ([provenance])
most_lean = {most_lean:.3f}          # the furthest lean (1: the posture): where the recording's holds end ([provenance])
lean_step = 0.15           # a correction leans this much further (arm too slow or not answering) or less far (too fast)
watch_s = 1.0              # s: after reaction + move, how long a posture is watched before it is corrected
speed_smoothing_s = 0.3    # s: the arm's speed is judged over about this long
too_slow = 0.5             # seen / wanted speed below which the participant leans further
too_fast = 2.0             # seen / wanted speed above which the participant leans less far
max_zero = 0.9             # the learnt zero lean never exceeds this share of the furthest lean: the least deflection needs less than full range
give_up_s = 10.0           # s: the arm not answering the furthest lean this long, the participant relaxes to rest and tries again: the limit of a person's attention to a system that does not respond (Nielsen 1993, Usability Engineering, 5.5; Miller 1968)
"""


# What a fitted timing may be (docs/virtual_participant.md, "Timing a real file supports"): a cued
# reaction faster than 0.1 s is an anticipation, not a reaction (Luce 1986), and a choice among up to
# nine cued postures takes well under a second (Hick 1952); voluntary head and limb moves of the
# protocol's size take 0.2-2 s (head: Zangemeister, Lehman & Stark 1981; arm: Flash & Hogan 1985).
ONSET_BOUNDS_S = (0.2, 2.0)
REACTION_BOUNDS_S = (0.1, 1.0)
MAD_TO_SD = 1.4826             # a normal distribution's SD per median absolute deviation


def speed_share_time(share: float = SPEED_SHARE) -> float:
    """The share of a minimum-jerk move's duration after which its speed first reaches ``share`` of its peak:
    the speed 30 s^2 (1 - s)^2 is 1.875 at its peak, so s (1 - s) = sqrt(share / 16)."""
    return (1.0 - np.sqrt(1.0 - 4.0 * np.sqrt(share / 16.0))) / 2.0


# ------------------------------------------------------------------------------------ timing
@dataclass(frozen=True)
class Timing:
    """A participant's timing fitted to the moves found in a recording (``bomi.onsets``): the minimum-jerk
    move duration (``onset_s``) and cue-to-movement time (``reaction_s``), median over the moves, and
    their spreads (robust: the median absolute deviation as an SD)."""

    onset_s: float
    reaction_s: float
    onset_sd_s: float
    reaction_sd_s: float
    moves: int


def implausible_timing(onset: float, reaction: float) -> str | None:
    """Why a fitted (onset_s, reaction_s) is outside ONSET_BOUNDS_S / REACTION_BOUNDS_S, or None."""
    out = [f"{what} {value:.2f} s outside {low:g}-{high:g} s"
           for what, value, (low, high) in (("onset", onset, ONSET_BOUNDS_S), ("reaction", reaction, REACTION_BOUNDS_S))
           if not low <= value <= high]
    return "; ".join(out) or None


def timing_from(moves: Sequence[Move]) -> Timing | None:
    """The minimum-jerk timing of each timed move (its onset and offset are where its speed crosses
    SPEED_SHARE of the peak: ``speed_share_time`` of the duration after its start and before its end),
    summarised; None with fewer than MIN_TRANSITIONS timed moves."""
    timed = [m for m in moves if m.kind is MoveKind.TIMED]
    if len(timed) < MIN_TRANSITIONS:
        return None
    share = speed_share_time()
    durations = np.array([m.duration_s for m in timed]) / (1.0 - 2.0 * share)
    reactions = np.array([m.onset_s for m in timed]) - share * durations

    def spread(x: np.ndarray) -> float:
        return float(MAD_TO_SD * np.median(np.abs(x - np.median(x))))

    return Timing(float(np.median(durations)), max(float(np.median(reactions)), 0.0), spread(durations),
                  spread(reactions), len(timed))


# ------------------------------------------------------------------------------------ a pass
@dataclass
class Pass:
    """One recording in the profile's node order: its angles, runs and whether it shows transitions."""

    source: str
    angles: np.ndarray              # (n, nodes, 3)
    time: np.ndarray                # (n,) s: the recording's Time, else the row count at the sample rate
    blocks: list[Block]
    moves: list[Move]               # the move after each block's cue: blocks[1:]
    run_digests: tuple[str, ...] = ()   # every run's (bomi.passes.run_digests): a model trained on it names them

    @property
    def continuous(self) -> bool:
        """The recording keeps the moves (timed moves outnumber jumps), not just the holds."""
        return keeps_moves(self.moves)

    def holds(self, settle_s: float) -> list[Block]:
        """The blocks cut to their holds: in a continuous recording, a block after a cue starts
        SETTLE_MARGIN_S after its move's measured offset, or when none was found (too small, still
        moving at the run's end) ``settle_s`` + SETTLE_MARGIN_S after the cue."""
        if not self.continuous:
            return self.blocks
        margin = int(np.ceil(SETTLE_MARGIN_S * SAMPLE_RATE_HZ))
        cut = int(np.ceil(settle_s * SAMPLE_RATE_HZ)) + margin
        starts = [self.blocks[0].start] + [m.offset_row + margin if m.kind is MoveKind.TIMED else b.start + cut
                                           for b, m in zip(self.blocks[1:], self.moves)]
        return [Block(b.day, b.label, min(start, b.stop), b.stop) for b, start in zip(self.blocks, starts)]

    def protocol(self) -> Protocol:
        """Each run from its first row to the next run's first row (the last: to its last row, and one period)."""
        starts = np.r_[[self.time[b.start] for b in self.blocks], self.time[-1] + 1.0 / SAMPLE_RATE_HZ]
        try:
            return Protocol(labels=tuple(b.label for b in self.blocks),
                            durations_s=tuple(round(float(d), 3) for d in np.diff(starts)),
                            holds_only=not self.continuous, source=Path(self.source).name)
        except ValueError as exc:   # a run over an hour long: no protocol a twin can replay
            raise BomiError(f"{self.source}: its protocol: {exc}") from None


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
    time = rec.time if rec.time is not None else np.arange(len(rec)) / SAMPLE_RATE_HZ
    return Pass(rec.source, angles, time, blocks, find_moves(angles, time, labels),
                tuple(digest for _, _, digest in run_digests(rec)))


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
    onset_sd_s: float
    reaction_sd_s: float
    neutral_deg: np.ndarray
    neutral_rep_std: np.ndarray
    rest_carry: np.ndarray | None
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
    least_lean: float
    most_lean: float
    provenance: dict[str, str]
    fallbacks: list[str] = field(default_factory=list)   # what could not be measured, said on stdout


def priorday_variation(prior: ParticipantParams, profile: str, label: int, rep_std: np.ndarray
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

    continuous = [p for p in passes if p.continuous]
    timing = timing_from([m for p in continuous for m in p.moves])
    implausible = None if timing is None else implausible_timing(timing.onset_s, timing.reaction_s)
    if timing is not None and implausible is None:
        onset, reaction, onset_sd, reaction_sd = (timing.onset_s, timing.reaction_s, timing.onset_sd_s,
                                                  timing.reaction_sd_s)
        how = (f"of the onsets and offsets of {timing.moves} moves found in the signals after their cues "
               f"(bomi.onsets: {SPEED_SHARE:.0%} of the peak speed), as a minimum-jerk move ({_names(continuous)})")
        for key in ("onset_s", "reaction_s"):
            provenance[key] = f"measured: median {how}"
        for key in ("onset_sd_s", "reaction_sd_s"):
            provenance[key] = f"measured: spread (median absolute deviation x {MAD_TO_SD}) {how}"
    else:
        onset, reaction = (ASSUMED_ONSET_S, ASSUMED_REACTION_S) if prior is None else (prior.onset_s, prior.reaction_s)
        onset_sd, reaction_sd = (0.0, 0.0) if prior is None else (prior.onset_sd_s, prior.reaction_sd_s)
        why = ("the recordings keep only the holds (no transition)" if not continuous
               else f"fewer than {MIN_TRANSITIONS} moves timed in the signals" if timing is None
               else f"the timing measured from the moves found in the signals is not plausible ({implausible}; "
                    "docs/virtual_participant.md)")
        if prior is None:
            for key in ("onset_s", "reaction_s"):
                provenance[key] = f"assumed: {why}; voluntary moves take 0.5-1 s, simple reactions 0.2-0.5 s"
        else:
            from_prior(("onset_s", "reaction_s") + (("onset_sd_s", "reaction_sd_s") if onset_sd or reaction_sd else ()),
                       why)

    n_nodes = len(profile.nodes)
    holds = Holds(n_nodes)
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
    rest_carry = carry_over(day_neutrals)
    if rest_carry is not None:
        provenance["neutral.carry_over"] = ("measured: per node and angle, the slope of each neutral hold's level "
                                            f"(from its pass's mean) on the one before it, pooled over the passes ({names})")
    else:
        provenance["neutral.carry_over"] = (f"not measurable: fewer than {MIN_REST_PAIRS} pairs of consecutive neutral "
                                            "holds; none (each rest drawn anew)")

    # drift between passes
    day_gain, day_std = {}, {}
    unseen = [label for label in labels if len(per_day[label]) < 2]
    if unseen and n_passes >= 2:
        from_prior(("day_gain_log_std", "day_std_deg"),
                   f"{', '.join(f'c{c}' for c in unseen)} shown in one pass only")
    for label in labels:
        days = per_day[label]
        if len(days) >= 2:
            day_gain[label], day_std[label] = day_variation(days, [reps.mean(axis=0) for reps in days],
                                                             postures[label], rep_std[label] ** 2)
        elif prior is not None:
            day_gain[label], day_std[label], _ = priorday_variation(prior, profile.name, label, rep_std[label])
    if n_passes >= 2 and not unseen:
        provenance["day_gain_log_std"] = provenance["day_std_deg"] = (
            f"measured: each class's mean posture per pass = gain x posture + offset, over {n_passes} passes ({names})")
    elif n_passes < 2:
        what = (priorday_variation(prior, profile.name, labels[0], rep_std[labels[0]])[2]
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
    least_lean, most_lean = (holds.held_share(postures, q) for q in LEAN_QUANTILES)
    least_lean, most_lean = float(np.clip(least_lean, 0.05, 1.0)), float(np.clip(most_lean, 1.0, 2.0))
    for key, end in zip(("feel.least_lean", "feel.most_lean"), LEAN_ENDS):
        provenance[key] = (f"measured: the {end} of each class's held samples along its posture, "
                           f"median over the classes ({names})")
    provenance["feel"] = "assumed: recordings of holds do not show how a person corrects a lean (as P4, P5)"
    provenance["protocol"] = f"the runs of {first}, for bomi synth"
    return Twin(
        name=name, profile=profile_ref or profile.name, passes=n_passes, onset_s=onset, reaction_s=reaction,
        onset_sd_s=onset_sd, reaction_sd_s=reaction_sd,
        neutral_deg=np.median(day_neutrals[0], axis=0) if day_neutrals else np.zeros((n_nodes, 3)),
        neutral_rep_std=neutral_rep_std, rest_carry=rest_carry, neutral_sway_std=neutral_sway, neutral_tremor_std=neutral_tremor,
        tremor_spectrum=spectrum, postures=postures, rep_std=rep_std, day_gain_log_std=day_gain, day_std=day_std,
        sway_std=sway, tremor_std=tremor, protocol=replace(passes[0].protocol(), run_digests=tuple(sorted({d for p in passes for d in p.run_digests}))), least_lean=least_lean, most_lean=most_lean, provenance=provenance, fallbacks=fallbacks)


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
        *([f"onset_sd_s = {round(twin.onset_sd_s, 3):g}", f"reaction_sd_s = {round(twin.reaction_sd_s, 3):g}"]
          if twin.onset_sd_s or twin.reaction_sd_s else []),
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
    if twin.rest_carry is not None:
        lines.append(f"carry_over = {_toml_matrix(twin.rest_carry)}   # of a rest's offset, kept by the next rest")
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
              "durations_s = [" + ", ".join(f"{v:g}" for v in protocol.durations_s) + "]",
              "run_digests = [" + ", ".join(_toml_string(v) for v in protocol.run_digests) + "]   # its source "
              "recordings' runs: a model trained on them was trained on this person's day (tasks.trials.standin)"]
    return "\n".join(lines) + "\n" + FEEL.format(least_lean=twin.least_lean, most_lean=twin.most_lean)
