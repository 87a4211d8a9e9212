"""The timeline figure, like the paper's: for each episode where the hand is relative to the target
(the cube the other is stacked on; with the task's phases shaded and the joystick mode as a coloured band), then for a BoMI
episode the classifier output per decision (wrong outputs inside the excused transition apart
from misclassified ones), the amplitude the profile uses and nu(t). Legends sit right of the
panels, never over the data."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from tasks.stacking import failures, metrics  # noqa: E402
from tasks.stacking.metrics import task_phases  # noqa: E402

if TYPE_CHECKING:
    from tasks.stacking.record import EpisodeLog

# The world axes as the joystick moves the hand along them (docs/sim.md): what "hand - B" is per line.
AXES = (("x", "x: left +, right -", "tab:blue"), ("y", "y: back +, forward -", "tab:orange"),
        ("z", "z: up +, down -", "tab:green"))
# What each class (a joystick function, docs/sim.md) does, for the class axis: in translation mode
# F/B/R/L move the hand forward/back/right/left and Rr/Lr (the stick twisted) up/down; in the
# wrist mode they turn the hand; B1/B2 are the buttons that change the mode.
FUNCTION_WORDS = {"F": "forward", "B": "back", "R": "right", "L": "left", "Rr": "twist right: up",
                  "Lr": "twist left: down", "B1": "button 1: next mode", "B2": "button 2: previous mode"}
MODE_COLOURS = {"translation": "#4c72b0", "sideways": "#64b5cd", "height": "#8172b2", "wrist": "#dd8452", "fingers": "#55a868"}
AMPLITUDE_LABELS = {"gamma": "gamma: angle change\nfrom neutral (deg)",
                    "along_class": "amplitude along\nthe class (deg)"}
LEGEND = {"loc": "upper left", "bbox_to_anchor": (1.005, 1.0), "fontsize": 7, "borderaxespad": 0.0}

def _shade_phases(ax, log: "EpisodeLog") -> list[tuple[float, float, str]]:
    """Every other task phase shaded; returns (start s, end s, phase) for the labels."""
    t, spans = log.t, []
    for k, (start, end, phase) in enumerate(task_phases(log.goals)):
        t0, t1 = t[start], t[min(end, len(t) - 1)]
        if k % 2:
            ax.axvspan(t0, t1, color="0.92", lw=0, zorder=0)
        spans.append((float(t0), float(t1), phase))
    return spans

PHASE_POINTS = 8  # the phase labels' font size

def _label_phases(ax, spans: list[tuple[float, float, str]]) -> None:
    """Each phase's name inside the top of the panel, where it fits (a phase too short for its name
    keeps only its shading)."""
    (left, right), width_px = ax.get_xlim(), ax.get_window_extent().width
    char_px = 0.62 * PHASE_POINTS * ax.figure.dpi / 72  # a character of the label
    for t0, t1, phase in spans:
        if (t1 - t0) / (right - left) * width_px >= (len(phase) + 1) * char_px:
            ax.text((t0 + t1) / 2, 0.97, phase, transform=ax.get_xaxis_transform(), ha="center", va="top",
                    fontsize=PHASE_POINTS, color="0.2", clip_on=False,
                    bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "none", "alpha": 0.7})

def _mode_band(ax, log: "EpisodeLog") -> list[Patch]:
    """The joystick mode as a coloured band along the bottom of ``ax``; a tick at each switch."""
    modes, t = list(log.mode), log.t
    starts = [0] + [k for k in range(1, len(modes)) if modes[k] != modes[k - 1]]
    transform = ax.get_xaxis_transform()
    for start, end in zip(starts, starts[1:] + [len(modes) - 1]):
        ax.axvspan(t[start], t[end], ymin=0.0, ymax=0.05, color=MODE_COLOURS.get(modes[start], "0.5"), lw=0)
    for start in starts[1:]:
        ax.plot([t[start]] * 2, [0.0, 0.09], transform=transform, color="black", lw=0.6)
    return [Patch(color=MODE_COLOURS[m], label=f"mode: {m}") for m in MODE_COLOURS if m in set(modes)]

def timeline_figure(logs: list["EpisodeLog"], path: Path | str) -> Path:
    """Write the figure for one or more episodes (any BoMI episode adds the decision panels)."""
    bomi_log = next((log for log in logs if log.decisions is not None), None)
    rows = len(logs) + (3 if bomi_log is not None else 0)
    fig, axes = plt.subplots(rows, 1, figsize=(12.5, 2.3 * rows), sharex=True, squeeze=False)
    axes = axes[:, 0]
    phases = []
    for ax, log in zip(axes, logs):
        rel = 100.0 * (log.hand_pos - log.target_pos)
        phases.append((ax, _shade_phases(ax, log)))
        for i, (_, label, colour) in enumerate(AXES):
            ax.plot(log.t, rel[:, i], color=colour, lw=1, label=label)
        ax.axhline(0, color="0.6", lw=0.5)
        ax.margins(y=0.22)  # room for the mode band below the lines and the phase names above
        switches = metrics.count_changes(log.mode)
        verdict = f"done in {log.completion_time:.1f} s" if log.success else f"failed: {log.failure}"
        ax.set_title(f"{log.operator} operator, {log.participant}, seed {log.seed}: {verdict}, {switches} mode "
                     f"switches. Lines: the hand's position minus the target's (the cube to stack on), per axis",
                     fontsize=9)
        ax.set_ylabel("hand - target (cm)")
        modes = _mode_band(ax, log)
        handles, _ = ax.get_legend_handles_labels()
        ax.legend(handles=handles + modes + [Patch(color="0.92", label="task phase (named at the\ntop, shaded "
                                                                        "every other):\nreach / carry cube k")],
                  **LEGEND)
    if bomi_log is not None:
        _decision_panels(axes[len(logs):], bomi_log)
    for ax, log in zip(axes, logs):  # a failed episode's stuck period, over its panel (and the decisions'); recoveries
        if not log.success:
            _mark_stuck([ax, *axes[len(logs):]] if log is bomi_log else [ax], failures.stuck_period(log))
        _mark_recoveries(ax, log)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    for ax, spans in phases:
        _label_phases(ax, spans)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

STUCK_COLOUR = "tab:red"
RECOVERY_COLOUR = "tab:purple"

def _mark_recoveries(ax, log: "EpisodeLog") -> None:
    """Each recovery action (tasks/operators/recovery.py): a line where it started, named, and the time the arm
    stood still for it shaded."""
    for event in log.recoveries:
        ax.axvline(event.start_s, color=RECOVERY_COLOUR, lw=1.0, ls="--")
        if event.end_s > event.start_s:
            ax.axvspan(event.start_s, event.end_s, color=RECOVERY_COLOUR, alpha=0.15, lw=0)
        ax.text(event.start_s, 0.98, f" {event.action.value}", transform=ax.get_xaxis_transform(), ha="left",
                va="top", fontsize=7, color=RECOVERY_COLOUR)

def _mark_stuck(axes, period: "failures.StuckPeriod | None") -> None:
    """The stuck period (the longest span without progress) hatched on ``axes``, named with its
    mechanism and evidence on the first (tasks/stacking/failures.py)."""
    if period is None:
        return
    for ax in axes:
        ax.axvspan(period.start_s, period.end_s, facecolor="none", edgecolor=STUCK_COLOUR, hatch="//", lw=0.8,
                   alpha=0.35, zorder=0)
    evidence = [f"{period.mode_switches} mode switches"]
    if period.neutral_share is not None:
        evidence.append(f"{100 * period.neutral_share:.0f} % of motion read as neutral "
                        f"(longest {period.neutral_run_s:.0f} s)")
    axes[0].text(period.start_s, 0.1, f" stuck {period.duration_s:.0f} s: {period.mechanism.value}; "
                 + ", ".join(evidence), transform=axes[0].get_xaxis_transform(), ha="left", va="bottom",
                 fontsize=7, color=STUCK_COLOUR, bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8})

def decision_kinds(intended: np.ndarray, decided: np.ndarray, allowance: int, neutral: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks over the decisions: equal to the intended class; excused (late: the previous class or
    neutral within the ``allowance`` decisions after an intent change, ``metrics.excused``);
    misclassified (the rest, ``metrics.misclassified``)."""
    right = np.asarray(decided) == np.asarray(intended)
    return (right, metrics.excused(intended, decided, allowance, neutral),
            metrics.misclassified(intended, decided, allowance, neutral))

def _decision_panels(axes, log: "EpisodeLog") -> None:
    d = log.decisions
    right, excused, errors = decision_kinds(d.intended, d.decided, log.allowance, log.neutral)
    ax_class, ax_amplitude, ax_nu = axes
    for ax in axes:
        _shade_phases(ax, log)
    ax_class.step(d.t, d.intended, where="post", color="0.7", lw=2, label="intended")
    ax_class.scatter(d.t[right], d.decided[right], s=2, color="tab:blue", label="output = intended")
    ax_class.scatter(d.t[excused], d.decided[excused], s=10, facecolors="none", edgecolors="tab:orange",
                     linewidths=0.7, label=f"other class, excused:\nwithin {1000 * log.allowance * log.sample_period:.0f}"
                                       " ms of an\nintent change")
    ax_class.scatter(d.t[errors], d.decided[errors], s=8, color="red", label="misclassified")
    ax_class.set_yticks(range(len(log.class_names)),
                        [f"{name} ({FUNCTION_WORDS[name]})" if name in FUNCTION_WORDS else name
                         for name in log.class_names], fontsize=7)
    ax_class.set_ylim(-0.6, len(log.class_names) - 0.4)
    ax_class.set_ylabel("class: the joystick\nfunction it drives", fontsize=8)
    ax_class.legend(**LEGEND)
    ax_amplitude.plot(d.t, d.gamma, color="tab:purple", lw=0.8)
    ax_amplitude.axhline(0, color="0.6", lw=0.5)
    ax_amplitude.set_ylabel(AMPLITUDE_LABELS.get(log.amplitude, f"{log.amplitude} (deg)"), fontsize=8)
    ax_nu.plot(d.t, d.nu, color="tab:brown", lw=0.8)
    ax_nu.set_ylabel("nu: stick\ndeflection (0-1)", fontsize=8)
    ax_nu.set_ylim(-0.05, 1.05)
    for ax in axes:
        ax.grid(alpha=0.3)
    every = 100 * metrics.accuracy_all_decisions(d.intended, d.decided)
    scored = 100 * metrics.accuracy_excused_transitions(d.intended, d.decided, log.allowance, log.neutral)
    amplitude = ("signed angle change along the class's own mean direction (profile [proportional] "
                 "amplitude = along_class)" if log.amplitude == "along_class" else
                 "the paper's gamma (profile [proportional] amplitude = gamma)")
    ax_class.set_title(f"BoMI decisions: accuracy {every:.1f} % over all decisions, {scored:.1f} % with "
                       f"{1000 * log.allowance * log.sample_period:.0f} ms after each intent change excused "
                       f"({int(errors.sum())} misclassified, {int(excused.sum())} excused)", fontsize=9)
    ax_amplitude.set_title(f"amplitude of the decided class: {amplitude}", fontsize=8)
    ax_nu.set_title("nu: the amplitude scaled by the calibrated range, the stick's deflection", fontsize=8)
