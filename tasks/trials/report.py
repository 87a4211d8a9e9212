"""The session report: the paper's trial table (each trial's time, mode switches and accuracy,
beside P1's trials in the paper and, when one is named, a virtual participant's prediction for the
same cube placements) and the timeline figure (``tasks.stacking.timeline``) of each controller's best trial."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from bomi import paper
from tasks.stacking.record import EpisodeLog
from tasks.stacking.timeline import timeline_figure


def _cell(value, spec: str = ".2f") -> str:
    return "-" if value is None else format(value, spec)


def _pct(value) -> str:
    return "-" if value is None else f"{100 * value:.1f} %"


def best_trial(records: Sequence[dict]) -> dict | None:
    """The successful trial done fastest (None if none succeeded)."""
    done = [r for r in records if r["success"]]
    return min(done, key=lambda r: r["completion_time"]) if done else None


def trial_table(records: Sequence[dict], predictions: Sequence[dict] = ()) -> str:
    header = "| trial | controller | who | success | time (s) | mode switches | accuracy (all decisions) |"
    lines = [header, "|---" * (header.count("|") - 1) + "|"]
    for r in records:
        verdict = "yes" if r["success"] else f"no: {r['failure']}"
        lines.append(f"| {r['trial']} | {r['operator']} | {r['participant']} | {verdict} | "
                     f"{_cell(r['completion_time'])} "
                     f"| {r['mode_switches']} | {_pct(r.get('accuracy_all_decisions'))} |")
    for k, r in enumerate(predictions, start=1):
        lines.append(f"| prediction {k} | {r['operator']} | {r['participant']} (simulated, seed {r['seed']}) "
                     f"| {'yes' if r['success'] else 'no'} | {_cell(r['completion_time'])} | {r['mode_switches']} "
                     f"| {_pct(r.get('accuracy_all_decisions'))} |")
    for controller, times in paper.TRIALS_S.items():
        lines.append(f"| paper | {controller} | P1 (Fall et al.) | 3/3 | {' / '.join(f'{t:.2f}' for t in times)} | - | "
                     f"{_pct(paper.TASK['realtime_accuracy']) if controller == 'bomi' else '-'} |")
    return "\n".join(lines)


def times_figure(records: Sequence[dict], predictions: Sequence[dict], path: Path) -> Path:
    """Each trial's completion time per controller (a failed trial: an empty bar to its end), beside
    P1's trials in the paper and the prediction's episodes."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    controllers = list(dict.fromkeys(r["operator"] for r in records))
    fig, ax = plt.subplots(figsize=(2.2 + 2.6 * len(controllers), 3.6))
    for x, controller in enumerate(controllers):
        mine = [r for r in records if r["operator"] == controller]
        width = 0.6 / max(1, len(mine))
        for k, r in enumerate(mine):
            left = x - 0.3 + k * width
            height = r["completion_time"] if r["success"] else r["sim_time"]
            ax.bar(left, height, width * 0.9, align="edge", color="tab:blue" if r["success"] else "none",
                   edgecolor="tab:blue", label="trial (empty: failed, drawn to its end)" if x == k == 0 else None)
            ax.text(left + width * 0.45, height, str(r["trial"]), ha="center", va="bottom", fontsize=7)
        paper_times = paper.TRIALS_S.get(controller, ())
        ax.scatter([x + 0.38] * len(paper_times), paper_times, marker="_", s=200, color="black",
                   label="P1 in the paper" if x == 0 else None)
        predicted = [r["completion_time"] for r in predictions if r["operator"] == controller and r["success"]]
        ax.scatter([x + 0.44] * len(predicted), predicted, marker="x", color="tab:grey",
                   label="prediction (simulated)" if x == 0 and predicted else None)
    ax.set_xticks(range(len(controllers)), controllers)
    ax.set_xlim(-0.5, len(controllers) - 0.5)
    ax.set_ylabel("completion time (s)")
    ax.set_title("Trials: time from the first command to the stack standing still", fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(out: Path, records: Sequence[dict], logs: dict[int, EpisodeLog],
                 predictions: Sequence[tuple[dict, EpisodeLog]] = (), note: str = "") -> list[Path]:
    """report.md and one timeline figure per controller (its best trial, above the prediction's best
    episode of that controller when there is one); returns the files written."""
    written, figures = [], []
    for controller in dict.fromkeys(r["operator"] for r in records):
        best = best_trial([r for r in records if r["operator"] == controller])
        if best is None:
            figures.append(f"No {controller} trial succeeded: no timeline figure.")
            continue
        if best["trial"] not in logs:   # run before the session was resumed: its ticks are in its session file
            figures.append(f"{controller}: the best trial, trial {best['trial']}, ran before the session was resumed: "
                           f"no timeline figure (`bomi replay` re-runs it).")
            continue
        predicted = {id(r): log for r, log in predictions if r["operator"] == controller}
        twin = best_trial([r for r, _ in predictions if r["operator"] == controller])
        shown = [logs[best["trial"]]] + ([predicted[id(twin)]] if twin is not None else [])
        path = timeline_figure(shown, out / f"timeline_{controller}.png")
        written.append(path)
        beside = (f", above the prediction's best {controller} episode ({twin['participant']}, seed {twin['seed']}, "
                  f"{twin['completion_time']:.2f} s)" if twin is not None else "")
        figures.append(f"![{controller}: trial {best['trial']}]({path.name})\n\n{controller}: the best trial, "
                       f"trial {best['trial']} ({best['completion_time']:.2f} s){beside}.")
    times = times_figure(records, [r for r, _ in predictions], out / "trial_times.png")
    written.insert(0, times)
    text = "\n\n".join(["# Trial session", note, "## Trials", trial_table(records, [r for r, _ in predictions]),
                        f"![trial times]({times.name})",
                        "Time: from the first command to the stack standing still (the task's success), the "
                        "time limit counted from the go. Accuracy: every decision against the class the "
                        "stand-in performed (- for a person: nobody knows what they intended).",
                        "## Timelines", *figures]) + "\n"
    report = out / "report.md"
    report.write_text(text, encoding="utf-8")
    return [report, *written]
