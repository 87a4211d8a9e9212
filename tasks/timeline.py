"""The timeline figure, like the paper's: where the hand is relative to B for both operators,
the classifier output per decision (misclassified ones in red), gamma(t) and nu(t)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from tasks import metrics  # noqa: E402

if TYPE_CHECKING:
    from tasks.episode import EpisodeLog


def timeline_figure(logs: list["EpisodeLog"], path: Path | str) -> Path:
    """Write the figure for one or more episodes (any BoMI episode adds the decision panels)."""
    bomi_log = next((log for log in logs if log.decisions is not None), None)
    rows = len(logs) + (3 if bomi_log is not None else 0)
    fig, axes = plt.subplots(rows, 1, figsize=(11, 2.2 * rows), sharex=True, squeeze=False)
    axes = axes[:, 0]
    for ax, log in zip(axes, logs):
        rel = 100.0 * (log.hand_pos - log.target_pos)
        for i, (axis, colour) in enumerate(zip("xyz", ("tab:blue", "tab:orange", "tab:green"))):
            ax.plot(log.t, rel[:, i], color=colour, lw=1, label=axis)
        verdict = f"done in {log.completion_time:.1f} s" if log.success else f"failed: {log.failure}"
        ax.set_title(f"{log.operator} operator, {log.participant}, seed {log.seed}: {verdict}", fontsize=9)
        ax.set_ylabel("hand - B (cm)")
        ax.axhline(0, color="0.6", lw=0.5)
        ax.legend(loc="upper right", fontsize=7, ncol=3)
    if bomi_log is not None:
        _decision_panels(axes[len(logs):], bomi_log)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _decision_panels(axes, log: "EpisodeLog") -> None:
    d = log.decisions
    errors = metrics.misclassified(d.intended, d.decided, log.allowance)
    ax_class, ax_gamma, ax_nu = axes
    ax_class.step(d.t, d.intended, where="post", color="0.7", lw=2, label="intended")
    ax_class.scatter(d.t[~errors], d.decided[~errors], s=2, color="tab:blue", label="output")
    ax_class.scatter(d.t[errors], d.decided[errors], s=8, color="red", label="misclassified")
    ax_class.set_yticks(range(len(log.class_names)), log.class_names, fontsize=7)
    ax_class.set_ylabel("class")
    ax_class.legend(loc="upper right", fontsize=7, ncol=3)
    ax_gamma.plot(d.t, d.gamma, color="tab:purple", lw=0.8)
    ax_gamma.set_ylabel("gamma (deg)")
    ax_nu.plot(d.t, d.nu, color="tab:brown", lw=0.8)
    ax_nu.set_ylabel("nu")
    ax_nu.set_ylim(-0.05, 1.05)
    for ax in axes:
        ax.grid(alpha=0.3)
    every = 100 * metrics.accuracy_all_decisions(d.intended, d.decided)
    excused = 100 * metrics.accuracy_excused_transitions(d.intended, d.decided, log.allowance)
    ax_class.set_title(f"BoMI decisions: accuracy {every:.1f} % over all decisions, {excused:.1f} % with "
                       f"{1000 * log.allowance * log.sample_period:.0f} ms after each intent change excused", fontsize=9)
