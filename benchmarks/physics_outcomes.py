"""Did a physics change alter the task's outcomes?  Two ``bomi benchmark --json`` files of the
same participants, operators and task seeds, one before the change and one after, compared as
distributions over the seeds (a physics change alters every trajectory, so records cannot be
identical; what must hold is that the outcomes are drawn from the same distribution).

    bomi benchmark --participants P1 --operators joystick --seeds 60 --first-seed 0 --jobs 1 --json before.json
    (change; the same command) --json after.json
    python benchmarks/physics_outcomes.py --before before.json --after after.json --out NAME

Per operator: success rate (Fisher's exact test), completion time of the successful episodes
(Mann-Whitney U and two-sample Kolmogorov-Smirnov, scipy), cube drops, mode switches and
unintended displacement (Mann-Whitney U), and the paired per-seed difference of completion time.
Writes benchmarks/results/NAME.md, .json and .png (completion time ECDFs).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
COUNTS = ("cube_drops", "mode_switches", "unintended_displacement_mm")


def fail(message: str) -> None:
    print(f"bomi: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def episodes(path: Path) -> dict[str, dict[int, dict]]:
    """Per operator, the episodes by seed."""
    try:
        records = json.loads(path.read_text())["episodes"]
        out: dict[str, dict[int, dict]] = {}
        for episode in records:
            out.setdefault(episode["operator"], {})[episode["seed"]] = episode
    except (OSError, ValueError, KeyError, TypeError) as exc:
        fail(f"{path}: not a `bomi benchmark --json` file ({type(exc).__name__}: {exc})")
    return out


def compare(before: dict[int, dict], after: dict[int, dict]) -> dict:
    if sorted(before) != sorted(after):
        fail("--before and --after hold different task seeds")
    seeds = sorted(before)
    ok_b = [before[s]["success"] for s in seeds]
    ok_a = [after[s]["success"] for s in seeds]
    t_b = np.array([before[s]["completion_time"] for s in seeds if before[s]["success"]])
    t_a = np.array([after[s]["completion_time"] for s in seeds if after[s]["success"]])
    both = [s for s in seeds if before[s]["success"] and after[s]["success"]]
    paired = np.array([after[s]["completion_time"] - before[s]["completion_time"] for s in both])
    row = {"seeds": [seeds[0], seeds[-1]], "n": len(seeds),
           "successes": [int(sum(ok_b)), int(sum(ok_a))],
           "success_p_fisher": float(stats.fisher_exact([[sum(ok_b), len(seeds) - sum(ok_b)],
                                                         [sum(ok_a), len(seeds) - sum(ok_a)]])[1]),
           "time_median": [float(np.median(t_b)), float(np.median(t_a))],
           "time_mean": [float(t_b.mean()), float(t_a.mean())],
           "time_p_mannwhitney": float(stats.mannwhitneyu(t_b, t_a).pvalue),
           "time_p_ks": float(stats.ks_2samp(t_b, t_a).pvalue),
           "paired_time_difference_median": float(np.median(paired)) if len(paired) else None,
           "times": [t_b.tolist(), t_a.tolist()]}
    for key in COUNTS:
        b = np.array([before[s][key] for s in seeds], float)
        a = np.array([after[s][key] for s in seeds], float)
        same = np.array_equal(np.sort(b), np.sort(a))
        row[key] = {"total": [float(b.sum()), float(a.sum())], "mean": [float(b.mean()), float(a.mean())],
                    "p_mannwhitney": 1.0 if same else float(stats.mannwhitneyu(b, a).pvalue)}
    return row


def markdown(record: dict) -> str:
    lines = [f"# Task outcomes before and after a physics change ({record['name']})", "",
             f"`python benchmarks/physics_outcomes.py {record['command']} --out {record['name']}`", "", record["note"], "",
             "| operator | seeds | successes (before / after), Fisher p | completion time median s (before / after) | "
             "Mann-Whitney p | KS p | paired median difference s | cube drops (total) | mode switches (mean), p | "
             "unintended displacement mm (mean), p |", "|---|---|---|---|---|---|---|---|---|---|"]
    for operator, r in record["operators"].items():
        drops, switches, disp = (r[k] for k in COUNTS)
        lines.append(
            f"| {operator} | {r['seeds'][0]}-{r['seeds'][1]} | {r['successes'][0]} / {r['successes'][1]} of {r['n']}, "
            f"{r['success_p_fisher']:.2f} | {r['time_median'][0]:.2f} / {r['time_median'][1]:.2f} | "
            f"{r['time_p_mannwhitney']:.2f} | {r['time_p_ks']:.2f} | {r['paired_time_difference_median']:+.2f} | "
            f"{drops['total'][0]:.0f} / {drops['total'][1]:.0f} | {switches['mean'][0]:.1f} / {switches['mean'][1]:.1f}, "
            f"{switches['p_mannwhitney']:.2f} | {disp['mean'][0]:.0f} / {disp['mean'][1]:.0f}, {disp['p_mannwhitney']:.2f} |")
    lines += ["", f"![completion time ECDFs]({record['name']}.png)"]
    return "\n".join(lines) + "\n"


def figure(record: dict, path: Path) -> None:
    operators = record["operators"]
    fig, axes = plt.subplots(1, len(operators), figsize=(5 * len(operators), 3.6), squeeze=False)
    for ax, (operator, r) in zip(axes[0], operators.items()):
        for times, label in zip(r["times"], ("before", "after")):
            x = np.sort(times)
            ax.step(x, np.arange(1, len(x) + 1) / len(x), where="post", label=f"{label} (n={len(x)})")
        ax.set(title=f"{operator}: completion time, seeds {r['seeds'][0]}-{r['seeds'][1]}",
               xlabel="completion time (s)", ylabel="share of successful episodes")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, required=True, action="append", help="bomi benchmark --json file(s)")
    parser.add_argument("--after", type=Path, required=True, action="append", help="the same runs after the change")
    parser.add_argument("--out", default="physics_outcomes", help="name of the result files in benchmarks/results")
    parser.add_argument("--note", default="", help="a line saying what changed between the two runs")
    args = parser.parse_args()
    for path in args.before + args.after:
        if not path.is_file():
            fail(f"{path}: no such file")
    before, after = {}, {}
    for paths, into in ((args.before, before), (args.after, after)):
        for path in paths:
            into.update(episodes(path))
    record = {"name": args.out, "note": args.note,
              "command": " ".join([f"--before {p}" for p in args.before] + [f"--after {p}" for p in args.after]),
              "operators": {op: compare(before[op], after[op]) for op in before if op in after}}
    if not record["operators"]:
        fail("--before and --after share no operator")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.out}.json").write_text(json.dumps(record, indent=1))
    (RESULTS / f"{args.out}.md").write_text(markdown(record))
    figure(record, RESULTS / f"{args.out}.png")
    print(markdown(record))


if __name__ == "__main__":
    main()
