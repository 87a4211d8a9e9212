"""The assistance layer measured: each cell (participant x operator) with and without assistance on
the same seeds.

    python benchmarks/assist_benchmark.py [--cells P4:bomi,P5:bomi,P1:bomi,P4:joystick,P1:joystick]
        [--seeds 20] [--first-seed 3000] [--assist none --assist auto-mode] [--jobs 2] [--figure-only]

Writes benchmarks/results/NAME.md, .json and .png (``--name``, default assist) after every cell (a cut-short run keeps the
cells it finished).  The joystick operator (the scripted user on a stick with the controls of
the participant's profile) depends only on those controls: one cell per layout (P4 and P5 share
"2-axis, B1").  Per cell: successes, completion time (mean +- sd of
the successes), its change against the first setting on the seeds both finished (ratio of the
means, 95 % bootstrap interval over seeds), user mode switches, automatic switches, wrong-goal
switches (tasks.stacking.episode.WRONG_GOAL_WINDOW_S), unintended displacement.  Seeds 0-999 are for
development; report held-out seeds (a fresh range of 10000-19999; 1000-4999 are spent) only after
the assistance is frozen.
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tasks.operators.assist import assist_label, parse_assist  # noqa: E402
from tasks.experiments.engine import ProcessPool  # noqa: E402
from tasks.experiments.jobs import benchmark_jobs, run_many  # noqa: E402
from tasks.stacking.summary import WRONG_GOAL_WINDOW_S
from tasks.stacking.channels import participant_controls
from tasks.operators.params import DEFAULT_OPERATOR_FILE

RESULTS = Path(__file__).resolve().parent / "results"
TIME_LIMIT = 600.0
BOOTSTRAP = 2000
DROP_BAR = 0.25  # P4 BoMI: completion time drops by at least this with auto-mode
SLOWER_BAR = 0.05  # no cell slower than this


def cell_name(participant: str, operator: str) -> str:
    return f"joystick ({participant_controls(participant).label})" if operator == "joystick" else f"{participant} BoMI"


def change(base: list[dict], assisted: list[dict], rng: np.random.Generator) -> dict:
    """Mean completion time with / without on the seeds both finished, with a bootstrap interval."""
    by_seed = {r["seed"]: r for r in base}
    pairs = [(by_seed[r["seed"]]["completion_time"], r["completion_time"]) for r in assisted
             if r["success"] and r["seed"] in by_seed and by_seed[r["seed"]]["success"]]
    if not pairs:
        return {"paired_seeds": 0, "ratio": None, "ratio_low": None, "ratio_high": None}
    before, after = np.array(pairs).T
    picks = rng.integers(0, len(pairs), size=(BOOTSTRAP, len(pairs)))
    ratios = after[picks].mean(axis=1) / before[picks].mean(axis=1)
    return {"paired_seeds": len(pairs), "ratio": float(after.mean() / before.mean()),
            "ratio_low": float(np.percentile(ratios, 2.5)), "ratio_high": float(np.percentile(ratios, 97.5))}


def summary(records: list[dict]) -> dict:
    done = [r["completion_time"] for r in records if r["success"]]
    mean = lambda key: statistics.fmean(r[key] for r in records) if all(key in r for r in records) else None  # noqa: E731
    return {"episodes": len(records), "successes": len(done),
            "completion_time_mean": statistics.fmean(done) if done else None,
            "completion_time_sd": statistics.stdev(done) if len(done) > 1 else None,
            "mode_switches": mean("mode_switches"), "automatic_switches": mean("automatic_switches"),
            "wrong_goal_switches": mean("wrong_goal_switches"), "refused_switches": mean("refused_switches"),
            "undone_switches": mean("undone_switches"), "grasp_helps": mean("grasp_helps"),
            "unintended_displacement_mm": mean("unintended_displacement_mm")}


def table(cells: dict, settings: list[str]) -> list[dict]:
    rng = np.random.default_rng(0)
    rows = []
    for name, by_setting in cells.items():
        base = by_setting.get(settings[0])
        for setting in settings:
            records = by_setting.get(setting)
            if records is None:
                continue
            row = {"cell": name, "assist": setting, **summary(records)}
            row.update(change(base, records, rng) if base is not None and setting != settings[0]
                       else {"paired_seeds": None, "ratio": None, "ratio_low": None, "ratio_high": None})
            rows.append(row)
    return rows


def _f(value, spec=".1f") -> str:
    return "-" if value is None else format(value, spec)


def markdown(rows: list[dict]) -> str:
    lines = ["| cell | assist | successes | completion time (s) | time vs none (95 % CI) | user mode switches "
             "| automatic switches | wrong-goal switches | refused / undone switches | grasp helps "
             "| unintended displacement (mm) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        sd = f" ± {r['completion_time_sd']:.1f}" if r["completion_time_sd"] is not None else ""
        vs = "-" if r["ratio"] is None else (f"{100 * (r['ratio'] - 1):+.1f} % ({100 * (r['ratio_low'] - 1):+.1f} .. "
                                             f"{100 * (r['ratio_high'] - 1):+.1f}), {r['paired_seeds']} seeds")
        lines.append(f"| {r['cell']} | {r['assist']} | {r['successes']}/{r['episodes']} | "
                     f"{_f(r['completion_time_mean'])}{sd} | {vs} | {_f(r['mode_switches'])} | "
                     f"{_f(r['automatic_switches'])} | {_f(r['wrong_goal_switches'])} | "
                     f"{_f(r.get('refused_switches'))} / {_f(r.get('undone_switches'))} | {_f(r['grasp_helps'])} | "
                     f"{_f(r['unintended_displacement_mm'], '.0f')} |")
    return "\n".join(lines)


def bars(rows: list[dict]) -> list[str]:
    """The issue's bars, each as a line saying met or missed (with the gap)."""
    out = []
    p4 = {r["assist"]: r for r in rows if r["cell"] == "P4 BoMI"}
    if "none" in p4 and "auto-mode" in p4 and p4["auto-mode"]["ratio"] is not None:
        drop = 1 - p4["auto-mode"]["ratio"]
        fewer = p4["auto-mode"]["successes"] < p4["none"]["successes"]
        met = drop >= DROP_BAR and not fewer
        out.append(f"- P4 BoMI completion time with auto-mode: a drop of {100 * drop:.1f} % (bar >= {100 * DROP_BAR:.0f} %), "
                   f"successes {p4['auto-mode']['successes']} vs {p4['none']['successes']}: "
                   f"{'met' if met else 'MISSED'}")
    for r in rows:
        if r["ratio"] is not None:
            slower = r["ratio"] - 1
            out.append(f"- {r['cell']} with {r['assist']}: {100 * slower:+.1f} % time "
                       f"(bar: no slower than +{100 * SLOWER_BAR:.0f} %): {'met' if slower <= SLOWER_BAR else 'MISSED'}")
    return out


def figure(cells: dict, settings: list[str], path: Path) -> None:
    """Per cell: each seed's completion time without and with assistance (a line joins a seed's
    pair; x: failed), and the mean user and automatic mode switches."""
    names = list(cells)
    fig, (ax_time, ax_switch) = plt.subplots(1, 2, figsize=(4 + 2.6 * len(names), 4.8))
    width = 0.8 / len(settings)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for x, name in enumerate(names):
        by_setting = cells[name]
        offsets = {s: x - 0.4 + width * (i + 0.5) for i, s in enumerate(settings)}
        seeds = sorted({r["seed"] for records in by_setting.values() for r in records})
        for seed in seeds:
            points = [(offsets[s], r["completion_time"] if r["success"] else TIME_LIMIT)
                      for s in settings for r in by_setting.get(s, []) if r["seed"] == seed]
            if len(points) > 1:
                ax_time.plot(*zip(*points), color="0.8", linewidth=0.6, zorder=1)
        for i, setting in enumerate(settings):
            records = by_setting.get(setting, [])
            done = [r["completion_time"] for r in records if r["success"]]
            ax_time.scatter([offsets[setting]] * len(done), done, s=12, color=colours[i], zorder=2,
                            label=setting if x == 0 else None)
            failed = sum(not r["success"] for r in records)
            if failed:
                ax_time.scatter([offsets[setting]] * failed, [TIME_LIMIT] * failed, marker="x", color="red", zorder=3)
            if done:
                ax_time.hlines(np.mean(done), offsets[setting] - width / 2, offsets[setting] + width / 2, color="black")
            if records:
                user = np.mean([r["mode_switches"] for r in records])
                auto = np.mean([r["automatic_switches"] for r in records])
                ax_switch.bar(offsets[setting], user, width, color=colours[i], label=f"{setting}: user" if x == 0 else None)
                ax_switch.bar(offsets[setting], auto, width, bottom=user, color=colours[i], alpha=0.35, hatch="//",
                              label=f"{setting}: automatic" if x == 0 else None)
    for ax in (ax_time, ax_switch):
        ax.set_xticks(range(len(names)), names)
    ax_time.set_yscale("log")
    ax_time.set_ylabel("completion time (s, log)")
    ax_time.set_title("every seed (grey: the same seed; bar: mean)", fontsize=9)
    ax_time.legend(fontsize=8)
    ax_switch.set_ylabel("mode switches per episode")
    ax_switch.set_title("user (solid) and automatic (hatched) mode switches", fontsize=9)
    ax_switch.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write(cells: dict, settings: list[str], args: argparse.Namespace, todo: list[str]) -> str:
    rows = table(cells, settings)
    seeds = sorted({r["seed"] for by in cells.values() for records in by.values() for r in records})
    text = "\n".join([
        f"# Assistance benchmark: seeds {seeds[0]}..{seeds[-1]} (episodes per cell and setting: the successes "
        f"column's denominator; the same seeds with and without)", "",
        (f"Episodes of `bomi benchmark --participants P --operators O --seeds N --first-seed S --assist A --json F` "
         f"runs (one per cell and setting), merged with `python benchmarks/assist_benchmark.py --fresh --merge "
         f"{' '.join(Path(p).name for p in args.merge)}`" if getattr(args, "merge", None) else
         f"Command: `python benchmarks/assist_benchmark.py --cells {args.cells} --seeds {args.seeds} "
         f"--first-seed {args.first_seed} {' '.join('--assist ' + s for s in settings)} --jobs {args.jobs}`"), "",
        f"Machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}. "
        f"Time limit {TIME_LIMIT:.0f} s. Wrong-goal switch: an automatic switch whose mode the user left by "
        f"their own press within {WRONG_GOAL_WINDOW_S:g} s.", "",
        markdown(rows), "", "Bars (issue 14):", "", *bars(rows), "",
        *([f"Not measured in this run: {', '.join(todo)}.", ""] if todo else [])])
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.name}.md").write_text(text, encoding="utf-8")
    (RESULTS / f"{args.name}.json").write_text(json.dumps(
        {"seeds": seeds, "settings": settings, "rows": rows,
         "not_measured": todo, "episodes": {name: by for name, by in cells.items()}}, indent=2) + "\n",
        encoding="utf-8")
    figure(cells, settings, RESULTS / f"{args.name}.png")
    return text


def _stem(text: str) -> str:
    if not text or Path(text).name != text or text.startswith("."):
        raise argparse.ArgumentTypeError(f"{text!r} is not a plain file name")
    return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", default="P4:bomi,P5:bomi,P1:bomi,P4:joystick,P1:joystick",
                        help="participant:operator, in the order to run them")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=3000)
    parser.add_argument("--assist", action="append", help="a setting (repeat; the first is the reference)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--figure-only", action="store_true", help="redraw the figure from the saved JSON")
    parser.add_argument("--merge", nargs="+", type=Path, metavar="BENCH.json",
                        help="add the episodes of `bomi benchmark --json` files (run with --assist on the same seeds) "
                             "to the saved results and rewrite them, instead of running")
    parser.add_argument("--fresh", action="store_true", help="with --merge: start from no saved results")
    parser.add_argument("--name", default="assist", type=_stem,
                        help="the results' file name in benchmarks/results/ without suffix (default: assist)")
    args = parser.parse_args()
    settings = [assist_label(parse_assist(s)) for s in (args.assist or ["none", "auto-mode"])]
    if args.figure_only:
        saved = json.loads((RESULTS / f"{args.name}.json").read_text(encoding="utf-8"))
        figure(saved["episodes"], saved["settings"], RESULTS / f"{args.name}.png")
        return
    if args.merge:
        saved_file = RESULTS / f"{args.name}.json"
        saved = json.loads(saved_file.read_text(encoding="utf-8")) if saved_file.exists() and not args.fresh else \
            {"episodes": {}, "settings": settings, "not_measured": []}
        cells = saved["episodes"]
        for path in args.merge:
            for r in json.loads(path.read_text(encoding="utf-8"))["episodes"]:
                by_setting = cells.setdefault(cell_name(r["participant"], r["operator"]), {})
                by_setting.setdefault(r["assist"], []).append(r)
        merged = [name for name in saved["not_measured"] if name not in cells]
        print(write(cells, saved["settings"], args, merged))
        return
    pairs = [tuple(c.split(":")) for c in args.cells.split(",")]
    cells: dict[str, dict[str, list[dict]]] = {}
    for k, (participant, operator) in enumerate(pairs):
        name = cell_name(participant, operator)
        jobs = [job for setting in settings
                for job in benchmark_jobs([participant], [operator], args.seeds, TIME_LIMIT, str(DEFAULT_OPERATOR_FILE),
                                          first_seed=args.first_seed, assist=parse_assist(setting))]
        records = run_many(jobs, ProcessPool(args.jobs))
        cells[name] = {s: [r for r in records if r["assist"] == s] for s in settings}
        text = write(cells, settings, args, [cell_name(*p) for p in pairs[k + 1:]])
    print(text)


if __name__ == "__main__":
    main()
