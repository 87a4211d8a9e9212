"""What the held postures of a person's recordings show (``tasks.participants.twin`` fits a twin from it):
runs of equal labels, each hold's level, its slow sway and its tremor (and the tremor's spectrum), the
spread of the levels within a pass and their drift between passes."""
from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.signal

from bomi.classifier import NEUTRAL_LABEL
from bomi.frames import SAMPLE_RATE_HZ
from bomi.recording import Recording
from tasks.participants.motion import SWAY_CUTOFF_HZ, ColouredNoise, sway_filter

EDGE_SAMPLES = 30              # dropped at both ends of a block before filtering statistics
MAX_REPEATED_ROWS = 0.25       # blocks of a node with more held (repeated) rows are not used for noise
WELCH_SEGMENT = 128            # samples per Welch segment of the tremor spectrum (0.49 Hz bins)
SPECTRUM_FLOOR = 0.1           # above the peak, the tremor spectrum ends where it falls below this share of the peak
MIN_DAY_GAIN = 0.1             # guards the log of a day's gain (never reached on P1)
MIN_REST_PAIRS = 10            # fewer pairs of consecutive rests and a rest's carry-over is not measured
MAX_CARRY = 0.95               # a rest keeps at most this share of the last one's offset (the rests stay a stationary AR(1))


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


def _typical(stds: list[np.ndarray]) -> np.ndarray:
    """Median over blocks of per-block standard deviations (robust to the stitching jumps); NaN if none."""
    return np.median(stds, axis=0) if stds else np.full(3, np.nan)


@dataclass
class Holds:
    """What the held postures of every pass show, gathered block by block."""

    n_nodes: int
    deltas: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)  # (label, day) -> per-repetition deltas
    levels: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)  # (label, day) -> per-repetition medians
    neutral_levels: dict[int, list[np.ndarray]] = field(default_factory=dict)      # day -> c0 block medians
    sway: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)    # (label, node) -> per-block std (3,)
    tremor: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)
    spectra: list[np.ndarray] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)    # samples of every block measured for noise
    held: dict[int, list[np.ndarray]] = field(default_factory=dict)  # label -> each hold's samples minus its reference

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
            self.held.setdefault(block.label, []).append(angles[block.start:block.stop] - reference)
            self.levels.setdefault((block.label, day), []).append(level)

    def held_share(self, postures: dict[int, np.ndarray], quantile: float) -> float:
        """An amplitude the holds show, as a share of the class posture: per class, the
        ``quantile`` of its held samples' projection on its posture over the posture's length; the
        median over the classes."""
        lows = []
        for label, posture in postures.items():
            way = posture.ravel()
            samples = np.concatenate(self.held.get(label, [np.empty((0, way.size))])).reshape(-1, way.size)
            if len(samples) and way @ way > 0:
                lows.append(float(np.quantile(samples @ way / (way @ way), quantile)))
        return float(np.median(lows)) if lows else 1.0

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


def carry_over(groups: Sequence[np.ndarray]) -> np.ndarray | None:
    """Per node and angle, the share of a rest's offset from its pass's mean rest that the pass's next
    rest keeps: the least-squares slope of each offset on the one before, pooled over the passes
    (``groups``: each pass's rest levels in order), within [0, MAX_CARRY]; None below MIN_REST_PAIRS pairs."""
    pairs = [(g[:-1] - g.mean(axis=0), g[1:] - g.mean(axis=0)) for g in groups if len(g) > 2]
    if sum(len(before) for before, _ in pairs) < MIN_REST_PAIRS:
        return None
    before, after = (np.concatenate(side) for side in zip(*pairs))
    return np.clip(np.sum(before * after, axis=0) / np.maximum(np.sum(before ** 2, axis=0), 1e-12), 0.0, MAX_CARRY)


def within_pass_std(groups: Sequence[np.ndarray]) -> np.ndarray | None:
    """The pooled standard deviation of repetitions around their own pass's mean (unbiased: each pass
    with n repetitions gives n - 1 degrees of freedom); None when no pass repeats."""
    repeated = [g for g in groups if len(g) > 1]
    if not repeated:
        return None
    squares = sum(np.sum((g - g.mean(axis=0)) ** 2, axis=0) for g in repeated)
    return np.sqrt(squares / sum(len(g) - 1 for g in repeated))


def day_variation(days: list[np.ndarray], day_means_of: list[np.ndarray], posture: np.ndarray, rep_var: np.ndarray
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
