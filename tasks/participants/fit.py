"""Fit the virtual participant P1 to the published 5-day recordings; write its TOML profile.

    python -m tasks.participants.fit [--data DIR] --out tasks/participants/P1.toml

Only numbers leave the data: per-class posture deltas from neutral, their variability from
repetition to repetition and from day to day, and the slow sway and tremor in holds, all
measured on the recordings' fused angles (PitchiRaw, RolliRaw, YawiRaw). The files hold only the
5 s holds, stitched (transitions were cut by the dataset's post-processing), so onset timing is
not measurable from them and stays an assumption. docs/virtual_participant.md explains each step.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.signal
from tqdm import tqdm

from bomi.dataset import data_dir
from bomi.errors import BomiError
from bomi.frames import SAMPLE_RATE_HZ
from bomi.recording import Recording, read_recording
from tasks.participants.participant import SWAY_CUTOFF_HZ

EDGE_SAMPLES = 30              # dropped at both ends of a block before filtering statistics
MAX_REPEATED_ROWS = 0.25       # blocks of a node with more held (repeated) rows are not used for noise
WELCH_SEGMENT = 128            # samples per Welch segment of the tremor spectrum (0.49 Hz bins)
SPECTRUM_FLOOR = 0.1           # above the peak, the tremor spectrum ends where it falls below this share of the peak
MIN_DAY_GAIN = 0.1             # guards the log of a day's gain (never reached on P1)
ASSUMED_ONSET_S = 0.8          # min-jerk onset of a posture (not measurable here, see docs)
ASSUMED_REACTION_S = 0.4       # cue-to-movement delay (likewise)
# How the participant leans through the BoMI (tasks.participants.participant.Feel): not in recordings of holds
# either; the fit writes it as assumed, the same as P4's and P5's files.
ASSUMED_FEEL = """
[feel]   # how the participant drives a proportional class through the BoMI (tasks/episode.py); assumed, the same for P1, P4, P5
least_lean = 0.5           # the least lean used, and calibrated with (half the body's range): the calibrated nu range spans the leans used
lean_step = 0.15           # a correction leans this much further (arm too slow or not answering) or less far (too fast)
watch_s = 1.0              # s: after reaction + move, how long a posture is watched before it is corrected
speed_smoothing_s = 0.3    # s: the arm's speed is judged over about this long
too_slow = 0.5             # seen / wanted speed below which the participant leans further
too_fast = 2.0             # seen / wanted speed above which the participant leans less far
max_zero = 0.9             # the learnt zero lean never exceeds this: the least deflection needs less than full range
"""


@dataclass(frozen=True)
class Block:
    """One stitched hold: its label, day and rows [start, stop) of the day's recording."""

    day: int
    label: int
    start: int
    stop: int


def hold_blocks(labels: np.ndarray, day: int) -> list[Block]:
    """The runs of equal labels of one recording."""
    edges = np.r_[0, np.flatnonzero(np.diff(labels.astype(int))) + 1, len(labels)]
    return [Block(day, int(labels[a]), int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def stacked_angles(rec: Recording) -> np.ndarray:
    """(n, nodes, 3) fused angles in node order."""
    return np.stack([rec.nodes[i].angles for i in rec.node_indices], axis=1)


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


@dataclass
class Fit:
    """Everything the profile stores, arrays are (nodes, 3) unless noted."""

    days: int
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


def _typical(stds: list[np.ndarray]) -> np.ndarray:
    """Median over blocks of per-block standard deviations (robust to the stitching jumps); NaN if none."""
    return np.median(stds, axis=0) if stds else np.full(3, np.nan)


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


@dataclass
class _Holds:
    """What the held postures of every day show, gathered block by block."""

    n_nodes: int
    deltas: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)  # (label, day) -> per-repetition deltas
    levels: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)  # (label, day) -> per-repetition medians
    neutral_levels: dict[int, list[np.ndarray]] = field(default_factory=dict)      # day -> c0 block medians
    sway: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)    # (label, node) -> per-block std (3,)
    tremor: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)
    spectra: list[np.ndarray] = field(default_factory=list)

    def add_levels(self, day: int, blocks: list[Block], angles: np.ndarray) -> None:
        """Each block's median posture; a motion's as a delta from the neutral before and after it
        (robust to the slow yaw drift)."""
        medians = [np.median(angles[b.start:b.stop], axis=0) for b in blocks]
        for k, (block, level) in enumerate(zip(blocks, medians)):
            if block.label == 0:
                self.neutral_levels.setdefault(day, []).append(level)
                continue
            around = [medians[j] for j in (k - 1, k + 1) if 0 <= j < len(blocks) and blocks[j].label == 0]
            if around:
                self.deltas.setdefault((block.label, day), []).append(level - np.mean(around, axis=0))
                self.levels.setdefault((block.label, day), []).append(level)

    def add_noise(self, blocks: list[Block], angles: np.ndarray) -> None:
        """Sway and tremor of every usable block and node; node 1's tremor spectrum."""
        for block in blocks:
            for node in range(self.n_nodes):
                x = angles[block.start:block.stop, node]
                if repeated_fraction(x) > MAX_REPEATED_ROWS or len(x) <= 4 * EDGE_SAMPLES:
                    continue
                s, t = split_sway_tremor(x)
                self.sway.setdefault((block.label, node), []).append(s.std(axis=0))
                self.tremor.setdefault((block.label, node), []).append(t.std(axis=0))
                if node == 0:
                    self.spectra.append(
                        scipy.signal.welch(t, fs=SAMPLE_RATE_HZ, nperseg=WELCH_SEGMENT, axis=0)[1].sum(axis=1))

    def per_node(self, table: dict, label: int) -> np.ndarray:
        return np.array([_typical(table.get((label, node), [])) for node in range(self.n_nodes)])

    def per_day(self, table: dict, label: int, days: int) -> list[np.ndarray]:
        return [np.array(table[(label, d)]) for d in range(1, days + 1) if (label, d) in table]


def _day_variation(days: list[np.ndarray], day_levels: list[np.ndarray], pooled_rep_var: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """(posture, repetition std, day gain log-std, day offset std) of one class from its per-day
    repetitions (deltas) and held levels: a day's mean posture = gain x nominal posture + an
    offset, the gain log-normal, fitted on the angles the feature vectors use (not the yaw of nodes
    2.., unreliable here); the repetition spread is that of the held level itself (not of the
    delta, which adds the neutrals' spread)."""
    posture = np.median(np.concatenate(days), axis=0)
    own = [reps - reps.mean(axis=0) for reps in day_levels if len(reps) > 1]
    rep_var = np.mean(np.concatenate(own) ** 2, axis=0) if own else pooled_rep_var
    reps_per_day = np.mean([len(reps) for reps in days])
    day_means = np.array([reps.mean(axis=0) for reps in days])
    used = np.ones_like(posture)
    used[1:, 2] = 0.0
    gains = np.einsum("dij,ij->d", day_means, posture * used) / np.sum((posture * used) ** 2)
    gains = np.clip(gains, MIN_DAY_GAIN, None)
    offsets = day_means - gains[:, None, None] * posture
    # var(day offsets) = day var + rep var / reps per day
    day_var = np.var(offsets, axis=0, ddof=1) - rep_var / reps_per_day
    return posture, np.sqrt(rep_var), float(np.std(np.log(gains), ddof=1)), np.sqrt(np.clip(day_var, 0.0, None))


def fit_recordings(recordings: list[Recording]) -> Fit:
    """Measure the participant from one recording per day (all with the same nodes and labels)."""
    holds = _Holds(len(recordings[0].node_indices))
    for day, rec in enumerate(tqdm(recordings, desc="fitting days", unit="day"), start=1):
        angles = stacked_angles(rec)
        blocks = hold_blocks(rec.require_labels(), day)
        holds.add_levels(day, blocks, angles)
        holds.add_noise(blocks, angles)
    freqs = np.fft.rfftfreq(WELCH_SEGMENT, 1.0 / SAMPLE_RATE_HZ)
    labels = sorted({label for label, _ in holds.deltas})
    per_day = {label: holds.per_day(holds.deltas, label, len(recordings)) for label in labels}
    per_day_levels = {label: holds.per_day(holds.levels, label, len(recordings)) for label in labels}
    within = [reps - reps.mean(axis=0) for days in per_day_levels.values() for reps in days if len(reps) > 1]
    pooled_rep_var = np.mean(np.concatenate(within) ** 2, axis=0)
    variation = {label: _day_variation(per_day[label], per_day_levels[label], pooled_rep_var) for label in labels}
    day_neutrals = [np.array(levels) for levels in holds.neutral_levels.values()]
    neutral_within = np.concatenate([lv - lv.mean(axis=0) for lv in day_neutrals])
    return Fit(
        days=len(recordings),
        neutral_deg=np.median(day_neutrals[0], axis=0),
        neutral_rep_std=np.sqrt(np.mean(neutral_within ** 2, axis=0)),
        neutral_sway_std=isotropic_yaw(holds.per_node(holds.sway, 0)),
        neutral_tremor_std=isotropic_yaw(holds.per_node(holds.tremor, 0)),
        tremor_spectrum=motion_spectrum(freqs, np.mean(holds.spectra, axis=0)),
        postures={label: v[0] for label, v in variation.items()},
        rep_std={label: v[1] for label, v in variation.items()},
        day_gain_log_std={label: v[2] for label, v in variation.items()},
        day_std={label: v[3] for label, v in variation.items()},
        sway_std={label: isotropic_yaw(holds.per_node(holds.sway, label)) for label in labels},
        tremor_std={label: isotropic_yaw(holds.per_node(holds.tremor, label)) for label in labels},
    )


def _fill_missing(values: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Noise levels of nodes with no usable block (every block held) take the neutral level."""
    return np.where(np.isnan(values), fallback, values)


def _toml_matrix(m: np.ndarray) -> str:
    return "[" + ", ".join("[" + ", ".join(f"{v:.3f}" for v in row) + "]" for row in m) + "]"


def fit_toml(fit: Fit, source: str) -> str:
    """The participant profile text (see tasks/participants/participant.py for the schema)."""
    lines = [
        f"# Virtual participant P1, fitted by `python -m tasks.participants.fit` on {fit.days} days of",
        f"# {source} (the published P1 test recordings). Numbers only, no data. Angles are",
        "# (pitch, roll, yaw) in degrees per node, node order of bomi profile P1. See docs/virtual_participant.md.",
        'name = "P1"',
        'profile = "P1"',
        'description = "Able-bodied participant P1 of the paper, fitted on the 5-day recordings."',
        f"onset_s = {ASSUMED_ONSET_S}      # assumed: the recordings hold no transitions",
        f"reaction_s = {ASSUMED_REACTION_S}   # assumed",
        "max_amplitude = 1.0",
        "",
        "[tremor]   # mean power spectrum of the head's tremor (fused pitch and roll above 1 Hz) in holds",
        "frequencies_hz = [" + ", ".join(f"{f:.3f}" for f in fit.tremor_spectrum[0]) + "]",
        "relative_power = [" + ", ".join(f"{p:.4f}" for p in fit.tremor_spectrum[1]) + "]",
        "",
        "[neutral]",
        f"angles_deg = {_toml_matrix(fit.neutral_deg)}   # day 1, absolute",
        f"rep_std_deg = {_toml_matrix(fit.neutral_rep_std)}",
        f"sway_std_deg = {_toml_matrix(fit.neutral_sway_std)}",
        f"tremor_std_deg = {_toml_matrix(fit.neutral_tremor_std)}",
    ]
    for label, posture in fit.postures.items():
        lines += [
            "",
            "[[classes]]",
            f"label = {label}",
            f"posture_deg = {_toml_matrix(posture)}",
            f"rep_std_deg = {_toml_matrix(fit.rep_std[label])}",
            f"day_gain_log_std = {fit.day_gain_log_std[label]:.3f}",
            f"day_std_deg = {_toml_matrix(fit.day_std[label])}",
            f"sway_std_deg = {_toml_matrix(_fill_missing(fit.sway_std[label], fit.neutral_sway_std))}",
            f"tremor_std_deg = {_toml_matrix(_fill_missing(fit.tremor_std[label], fit.neutral_tremor_std))}",
        ]
    return "\n".join(lines) + "\n" + ASSUMED_FEEL


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tasks.participants.fit", description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="directory of dayN_testp.mat (default: BOMI_DATA_DIR)")
    parser.add_argument("--out", type=Path, required=True, help="participant TOML to write")
    args = parser.parse_args(argv)
    directory = args.data or data_dir()
    paths = sorted(directory.glob("day*_testp.mat"))
    try:
        if not paths:
            raise BomiError(f"{directory}: no dayN_testp.mat recordings found")
        text = fit_toml(fit_recordings([read_recording(p) for p in paths]), directory.name)
    except BomiError as exc:
        print(f"bomi: error: {exc}", file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
