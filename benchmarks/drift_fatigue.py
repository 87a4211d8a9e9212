"""Within-session drift and fatigue of the real P1, measured on the five published test sessions.

    python benchmarks/drift_fatigue.py [--data DIR]   # -> benchmarks/results/drift_fatigue.{md,png}

Each day's file holds 55 stitched 5 s holds in one session order (27 motions, neutral between).
Two questions, answered per day and then over the five days (days are the independent units:
mean slope, its 95 % Student-t interval):

- **Drift**: does the neutral posture wander over a session?  Slope of each neutral hold's median
  angle against its place in the session, per node and angle, in degrees per session (54 holds).
- **Fatigue**: do the motions shrink over a session?  Each motion hold's amplitude (its delta from
  the neutral holds around it, projected on that class's mean delta of the day) relative to the
  class's mean amplitude that day, against its place in the session: % per session.  Classes shown
  two or more times a day also give the last repetition over the first.

Motion *speed* is not measurable here: the files hold the holds only (transitions were cut).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import scipy.stats  # noqa: E402

from bomi.dataset import data_dir  # noqa: E402
from bomi.recording import read_recording  # noqa: E402
from tasks.participants.twin import hold_blocks, stacked_angles  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
NODES = ("head", "right shoulder", "left shoulder")
ANGLES = ("pitch", "roll", "yaw")


def mean_ci(values: np.ndarray) -> tuple[float, float, float]:
    """Mean and 95 % Student-t interval over the first axis' entries (the days)."""
    values = np.asarray(values, float)
    mean = float(values.mean())
    half = float(scipy.stats.t.ppf(0.975, len(values) - 1) * values.std(ddof=1) / np.sqrt(len(values)))
    return mean, mean - half, mean + half


def session_measures(angles: np.ndarray, labels: np.ndarray) -> dict:
    """Per session: neutral medians and motion amplitudes with their place (hold index) in it."""
    blocks = hold_blocks(labels, 0)
    medians = [np.median(angles[b.start:b.stop], axis=0) for b in blocks]
    neutral = [(k, m) for k, (b, m) in enumerate(zip(blocks, medians)) if b.label == 0]
    deltas: dict[int, list[tuple[int, np.ndarray]]] = {}
    for k, (block, level) in enumerate(zip(blocks, medians)):
        around = [medians[j] for j in (k - 1, k + 1) if 0 <= j < len(blocks) and blocks[j].label == 0]
        if block.label != 0 and around:
            deltas.setdefault(block.label, []).append((k, level - np.mean(around, axis=0)))
    amplitude = []  # (hold index, relative amplitude, label, repetition)
    for label, reps in deltas.items():
        direction = np.mean([d for _, d in reps], axis=0).ravel()
        size = [float(np.dot(d.ravel(), direction) / np.dot(direction, direction)) for _, d in reps]
        amplitude += [(k, s, label, r) for r, ((k, _), s) in enumerate(zip(reps, size))]
    return {"n_blocks": len(blocks), "neutral": neutral, "amplitude": amplitude}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="directory of dayN_testp.mat (default: BOMI_DATA_DIR)")
    args = parser.parse_args(argv)
    paths = sorted((args.data or data_dir()).glob("day*_testp.mat"))
    if not paths:
        print(f"drift_fatigue: error: {args.data or data_dir()}: no dayN_testp.mat recordings", file=sys.stderr)
        return 2
    sessions = []
    for path in paths:
        rec = read_recording(path)
        sessions.append(session_measures(stacked_angles(rec), rec.require_labels()))
    span = sessions[0]["n_blocks"] - 1  # holds from the first to the last of a session

    drift = np.zeros((len(sessions), 3, 3))  # deg per session, per day, node, angle
    neutral_spread = np.zeros((len(sessions), 3, 3))
    for d, s in enumerate(sessions):
        k = np.array([i for i, _ in s["neutral"]], float)
        levels = np.array([m for _, m in s["neutral"]])
        for node in range(3):
            for angle in range(3):
                fit = scipy.stats.linregress(k, levels[:, node, angle])
                drift[d, node, angle] = fit.slope * span
                neutral_spread[d, node, angle] = np.std(levels[:, node, angle] - (fit.intercept + fit.slope * k), ddof=2)
    fatigue, first_last = [], []
    for s in sessions:
        k, size = (np.array([a[i] for a in s["amplitude"]], float) for i in (0, 1))
        fatigue.append(100 * scipy.stats.linregress(k, size).slope * span)
        by_label: dict[int, list[tuple[int, float]]] = {}
        for k_, size_, label, rep in s["amplitude"]:
            by_label.setdefault(label, []).append((rep, size_))
        ratios = [reps[-1][1] / reps[0][1] for reps in by_label.values() if len(reps) >= 2]
        first_last.append(100 * (np.mean(ratios) - 1))

    lines = ["# Within-session drift and fatigue of the real P1 (5 test sessions)", "",
             "`python benchmarks/drift_fatigue.py` on `flexible_bomi_p1_5days`; days are the independent units "
             "(mean over 5 days, 95 % Student-t interval). A session = 55 holds of 5 s (27 motions, neutral between).", "",
             "## Drift of the neutral posture (deg from the first to the last hold of a session)", "",
             "| node | angle | drift mean | 95 % CI | per day | neutral spread (deg, std around the trend) |",
             "|---|---|---|---|---|---|"]
    for node in range(3):
        for angle in range(3):
            m, lo, hi = mean_ci(drift[:, node, angle])
            per_day = ", ".join(f"{v:+.2f}" for v in drift[:, node, angle])
            lines.append(f"| {NODES[node]} | {ANGLES[angle]} | {m:+.2f} | [{lo:+.2f}, {hi:+.2f}] | {per_day} | "
                         f"{neutral_spread[:, node, angle].mean():.2f} |")
    m, lo, hi = mean_ci(fatigue)
    m2, lo2, hi2 = mean_ci(first_last)
    lines += ["", "## Fatigue: motion amplitude over a session", "",
              "| measure | mean | 95 % CI | per day |", "|---|---|---|---|",
              f"| amplitude trend, % from first to last hold | {m:+.1f} | [{lo:+.1f}, {hi:+.1f}] | "
              + ", ".join(f"{v:+.1f}" for v in fatigue) + " |",
              f"| last repetition / first - 1, % (classes repeated in a day) | {m2:+.1f} | [{lo2:+.1f}, {hi2:+.1f}] | "
              + ", ".join(f"{v:+.1f}" for v in first_last) + " |",
              "", "Motion speed cannot be measured: the published files hold the 5 s holds only.", ""]
    significant = [(NODES[n], ANGLES[a]) for n in range(3) for a in range(3)
                   if np.sign(mean_ci(drift[:, n, a])[1]) == np.sign(mean_ci(drift[:, n, a])[2])]
    lines.append("Drifts whose interval excludes 0: " + (", ".join(f"{n} {a}" for n, a in significant) or "none") + ".")
    lines.append("Amplitude trend interval excludes 0: " + ("yes" if np.sign(lo) == np.sign(hi) else "no") + ".")
    OUT.mkdir(exist_ok=True)
    (OUT / "drift_fatigue.md").write_text("\n".join(lines) + "\n")

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for d, s in enumerate(sessions):
        k = np.array([i for i, _ in s["neutral"]])
        levels = np.array([m for _, m in s["neutral"]])
        for node, style in zip(range(3), ("-", "--", ":")):
            axes[0].plot(k, levels[:, node, 0] - levels[0, node, 0], style, color=f"C{d}",
                         label=f"day {d + 1} {NODES[node]}" if node == 0 or d == 0 else None)
        a = np.array([(x[0], x[1]) for x in s["amplitude"]])
        axes[1].plot(a[:, 0], 100 * a[:, 1], "o", color=f"C{d}", ms=3, label=f"day {d + 1}")
        fit = scipy.stats.linregress(a[:, 0], a[:, 1])
        axes[1].plot([0, span], [100 * fit.intercept, 100 * (fit.intercept + fit.slope * span)], color=f"C{d}")
    axes[0].set(xlabel="hold in the session", ylabel="neutral pitch - first neutral (deg)",
                title="neutral posture over a session (head solid, shoulders dashed/dotted)")
    axes[1].set(xlabel="hold in the session", ylabel="amplitude / class mean of the day (%)",
                title="motion amplitude over a session")
    axes[0].legend(fontsize=7, ncol=2)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "drift_fatigue.png", dpi=110)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
