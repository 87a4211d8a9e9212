"""Figures a person reads without the README: completion time per group of episodes (``bomi
benchmark``'s script, ``bomi sweep``), one per-cell metric against one swept setting (``bomi
sweep``) and confusion matrices (``bomi evaluate``)."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import ticker  # noqa: E402

from tasks.experiments.summary import shown_name  # noqa: E402


def completion_time_figure(groups: Sequence[tuple[str, Sequence[dict]]], path: Path, title: str,
                           references: Mapping[str, float] | None = None) -> None:
    """Completion time of every episode, one column per (label, episode records) group: successes
    as dots with their mean as a line, failed episodes as red crosses where they stopped;
    ``references`` (label -> seconds) as dashed lines."""
    fig, ax = plt.subplots(figsize=(min(1.4 * len(groups) + 2, 24), 4.8))
    jitter = np.random.default_rng(0)
    for x, (_, records) in enumerate(groups):
        done = [r["completion_time"] for r in records if r["success"]]
        failed = [r["sim_time"] for r in records if not r["success"]]
        colour = "tab:green" if all(r["operator"] == "joystick" for r in records) else "tab:blue"
        ax.scatter(x + jitter.uniform(-0.15, 0.15, len(done)), done, s=14, color=colour, alpha=0.8)
        if failed:
            ax.scatter([x] * len(failed), failed, marker="x", color="red", s=40)
        if done:
            ax.hlines(np.mean(done), x - 0.3, x + 0.3, color="black")
    for label, seconds in (references or {}).items():
        ax.axhline(seconds, color="gray", linestyle="--", linewidth=0.8)
        ax.text(len(groups) - 0.5, seconds, f"{label} {seconds:.0f} s", ha="right", va="bottom", fontsize=8)
    labels = ["\n".join(shown_name(line) for line in label.split("\n")) for label, _ in groups]   # files by name
    ax.set_xticks(range(len(groups)), labels, fontsize=7 if len(groups) > 8 else 9)
    ax.set_yscale("log")
    values = [v for _, records in groups for r in records for v in (r["completion_time"] if r["success"]
                                                                     else r["sim_time"],) if v and v > 0]
    values += [v for v in (references or {}).values() if v > 0]
    if values:
        label_log_axis(ax.yaxis, min(values), max(values))
    ax.set_ylabel("completion time (s, log scale)\nx: where a failed episode stopped")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def log_subs(low: float, high: float) -> tuple[float, ...]:
    """The leading digits of a log axis's labelled ticks over [low, high]: every digit within a factor
    of 5 (70, 80, 90, 100 s), 1-2-3-5-7 within two decades, 1-2-5 beyond."""
    span = np.log10(high / low)
    return (tuple(float(d) for d in range(1, 10)) if span < np.log10(5.0)
            else (1.0, 2.0, 3.0, 5.0, 7.0) if span < 2.0 else (1.0, 2.0, 5.0))


def label_log_axis(axis, low: float, high: float) -> None:
    """Labelled ticks (plain numbers: 70, 80, 100, not 7 x 10^1) on a log axis showing [low, high]: at
    least three on any range (``log_subs``), the other digits as unlabelled minor ticks."""
    axis.set_major_locator(ticker.LogLocator(base=10.0, subs=log_subs(low, high)))
    axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_locator(ticker.LogLocator(base=10.0, subs=tuple(float(d) for d in range(1, 10))))
    axis.set_minor_formatter(ticker.NullFormatter())


# What each summary column plotted against a setting is, with its unit
METRIC_LABELS = {"completion_time_mean": "completion time, mean of successes (s)",
                 "successes": "successful episodes", "success_rate": "success rate (share of episodes)",
                 "accuracy_all_decisions": "accuracy over every decision (share)",
                 "accuracy_excused_transitions": "accuracy, transitions excused (share)",
                 "excused_share": "share of decisions excused", "relevant_share": "relevant outputs (share)",
                 "irrelevant_per_min": "irrelevant outputs per minute", "longest_error_run_ms":
                 "longest misclassified run (ms)", "mode_switches": "mode switches per episode",
                 "unintended_displacement_mm": "unintended displacement (mm)",
                 "latency_ms_median": "latency from motion onset, median (ms)", "cube_drops": "cube drops"}
# Settings whose values crowd towards 1 (0.9, 0.99, 0.999): plotted as 1 - value on a log axis
TOWARD_ONE = ("rejection_threshold",)


def setting_label(setting: str) -> str:
    """A setting's name as an axis reads it: its last part, where it lives, and its unit."""
    short = setting.rsplit(".", 1)[-1]
    units = {"time_limit": " (s of simulated time)", "vote_length": " (decisions, 16 ms each)",
             "reaction_time": " (s)", "reaction_s": " (s)"}
    where = f" [{setting.rsplit('.', 1)[0]}]" if "." in setting else ""
    return f"{short.replace('_', ' ')}{units.get(short, '')}{where}"


def metric_figure(series: Mapping[str, Sequence[tuple[object, float | None, tuple[float, float] | None]]],
                  path: Path, metric: str, setting: str) -> None:
    """``metric`` against ``setting``: one line per series (label -> (setting value, value, 95 %
    interval or None) points); a numeric setting on a numeric axis (a threshold near 1 as 1 - it on
    a log axis, ticks showing the threshold), any other in the grid's order."""
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    values = [v for points in series.values() for v, _, _ in points]
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    toward_one = numeric and setting.endswith(TOWARD_ONE) and all(0 < v < 1 for v in values)
    order = {v: k for k, v in enumerate(dict.fromkeys(map(str, values)))}
    for label, points in series.items():
        points = [(v, y, ci) for v, y, ci in points if y is not None]
        if not points:
            continue
        xs = [(1 - v if toward_one else v) if numeric else order[str(v)] for v, _, _ in points]
        ys = [y for _, y, _ in points]
        lows = [y - ci[0] if ci else 0.0 for _, y, ci in points]
        highs = [ci[1] - y if ci else 0.0 for _, y, ci in points]
        ax.errorbar(xs, ys, yerr=[lows, highs], marker="o", capsize=3,
                    label=" ".join(shown_name(word) for word in label.split(" ")))   # files by name
    if toward_one:
        ax.set_xscale("log")
        ticks = sorted(set(values))
        ax.set_xticks([1 - v for v in ticks], [f"{v:g}" for v in ticks])
        ax.minorticks_off()
        ax.invert_xaxis()  # the threshold grows to the right
        ax.set_xlabel(f"{setting_label(setting)} (log scale of 1 - threshold)")
    else:
        if not numeric:
            ax.set_xticks(range(len(order)), list(order))
        ax.set_xlabel(setting_label(setting))
    ax.set_ylabel(METRIC_LABELS.get(metric, metric))
    ax.set_title(f"{METRIC_LABELS.get(metric, metric)}\nper cell against {setting.rsplit('.', 1)[-1]} "
                 f"(bars: 95 % interval, none for fewer than 5 episodes)", fontsize=9)
    if len(series) > 1:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def accuracy_allowance_figure(rows: Sequence[dict], path: Path, references: Mapping[str, float] | None = None) -> None:
    """Each row's ``accuracy_vs_allowance`` curve (rows without decisions are left out): accuracy
    against the allowance excused after every intent change (0 s: every decision scored), the
    allowance the tables use dotted; ``references`` (label -> accuracy) dashed."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for row in rows:
        curve = row.get("accuracy_vs_allowance")
        if curve is None:
            continue
        line, = ax.plot(curve["allowance_s"], 100 * np.array(curve["accuracy"]), marker=".",
                        label=f"{row['participant']} ({row['layout']})")
        ax.axvline(row["excused_allowance_ms"] / 1000.0, color=line.get_color(), linestyle=":", linewidth=0.8)
    for label, accuracy in (references or {}).items():
        ax.axhline(100 * accuracy, color="gray", linestyle="--", linewidth=0.8)
        ax.text(0.0, 100 * accuracy, label, fontsize=7, va="bottom")
    ax.set_xlabel("allowance excused after each intent change (s)")
    ax.set_ylabel("BoMI accuracy (%)")
    ax.set_title("Accuracy against the excused allowance (dotted: the tables')", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def confusion_figure(path: Path, matrices: Sequence[tuple[str, np.ndarray]], names: Sequence[str]) -> None:
    """One confusion matrix per (title, counts) pair, rows the true class and columns the output,
    both labelled with ``names``. Colour and the large number are the share of the row (so a rare
    class's errors show as plainly as the neutral class's), the small number the count."""
    k = len(names)
    side = max(4.5, 0.62 * k + 2.2)
    fig, axes = plt.subplots(1, len(matrices), figsize=(side * len(matrices), side), squeeze=False)
    for ax, (title, counts) in zip(axes[0], matrices):
        totals = counts.sum(axis=1, keepdims=True)
        shares = np.divide(counts, totals, out=np.zeros(counts.shape), where=totals > 0)
        ax.imshow(100 * shares, cmap="Blues", vmin=0, vmax=100)
        for i in range(k):
            for j in range(k):
                if counts[i, j]:
                    dark = shares[i, j] > 0.6
                    ax.text(j, i - 0.12, f"{100 * shares[i, j]:.0f}%" if shares[i, j] >= 0.005 else "<1%",
                            ha="center", va="center", fontsize=8, color="white" if dark else "black")
                    ax.text(j, i + 0.25, f"{counts[i, j]:,}", ha="center", va="center", fontsize=5.5,
                            color="white" if dark else "0.3")
        ax.set_xticks(range(k), names, rotation=40, ha="right", fontsize=7)
        ax.set_yticks(range(k), [f"{name} ({int(n):,})" for name, n in zip(names, totals[:, 0])], fontsize=7)
        ax.set_xlabel("output of the classifier")
        ax.set_ylabel("true class (windows)")
        ax.set_title(title, fontsize=9)
    fig.suptitle("Confusion matrices: share of each true class's windows per output (row sums 100 %); "
                 "small numbers: windows", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
