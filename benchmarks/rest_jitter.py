"""Why new people's episodes misread motions: the rest they come back to moves from one rest to the next.

Two measurements, both on development material only.

``--p1``: P1's five real days (the published recordings): how far a person's rests spread (the
per-axis standard deviation of the rest holds' mean angles within a day), and whether a motion's
hold follows the rest before it: the slope of the hold's level on the preceding rest's level (within
each class, every angle pooled; 0: the motions are made from a fixed body posture, 1: from wherever
the person last rested), and the within-class variance of the holds measured from the rest before
each against measured from the day's mean rest.

``--people``: synthetic people (tasks/participants/population.py) through the path a new user takes
(both passes in one .mat file, ``bomi twin --no-check``), and the twin run twice in the task on the
same seeds: as fitted, and with still rests (its ``[neutral] rep_std_deg`` set to 0, nothing else
changed). The difference is what the rest-to-rest jitter costs.

    python benchmarks/rest_jitter.py --p1
    python benchmarks/rest_jitter.py --population 601-671
    python benchmarks/rest_jitter.py --people 601,606,610 --first-seed 710 --seeds 3 --name dev

``--population``: the same measures as ``--p1`` on the first pass of synthetic people's protocol.

Writes benchmarks/results/rest_jitter_NAME.{json,md} (``--people``), rest_jitter_p1.md or
rest_jitter_population.md.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from derived_default_task import people_range  # noqa: E402  (this folder)
from new_people_task import bomi  # noqa: E402

from bomi.classifier import NEUTRAL_LABEL  # noqa: E402
from bomi.dataset import data_dir  # noqa: E402
from bomi.neutral import hold_levels  # noqa: E402
from bomi.recording import read_recording, write_logger_mat  # noqa: E402
from tasks.stacking.metrics import success_ci95  # noqa: E402
from tasks.participants.population import draw_person, one_file, pass_recording  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"


def recording_levels(rec) -> list[tuple[int, np.ndarray]]:
    """(label, mean angles of every node) of each run of one label, in order."""
    return hold_levels(rec.labels, np.hstack([rec.nodes[i].angles for i in sorted(rec.nodes)]))


def rest_following(levels: list[tuple[int, np.ndarray]]) -> dict:
    """The rests' spread and how the holds follow the rest before them (see the module docstring)."""
    rests = np.array([level for label, level in levels if label == NEUTRAL_LABEL])
    mean_rest = rests.mean(axis=0)
    pairs: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    previous = None
    for label, level in levels:
        if label == NEUTRAL_LABEL:
            previous = level
        elif previous is not None:
            pairs.setdefault(label, []).append((previous, level))
    x, y, from_previous, from_mean = [], [], [], []
    for label, rows in pairs.items():
        if len(rows) < 2:
            continue
        before, hold = (np.array(side) for side in zip(*rows))
        x.append(before - before.mean(axis=0))
        y.append(hold - hold.mean(axis=0))
        from_previous.append(np.var(hold - before, axis=0, ddof=1).sum())
        from_mean.append(np.var(hold - mean_rest, axis=0, ddof=1).sum())
    x, y = np.concatenate(x).ravel(), np.concatenate(y).ravel()
    return {"rests": len(rests), "rest_spread_deg_median_axis": float(np.median(rests.std(axis=0, ddof=1))),
            "slope_on_preceding_rest": float(x @ y / (x @ x)),
            "hold_variance_from_preceding_rest": float(np.mean(from_previous)),
            "hold_variance_from_mean_rest": float(np.mean(from_mean))}


def following_report(title: str, recordings: dict[str, object]) -> str:
    """``rest_following`` of each recording (name -> Recording) as a table."""
    rows = [(name, rest_following(recording_levels(rec))) for name, rec in recordings.items()]
    lines = [f"# Rest jitter: {title}", "",
             "| recording | rests | rest spread (deg, median axis) | slope of a hold on the rest before it | "
             "hold variance from that rest (deg^2) | from the recording's mean rest (deg^2) |", "|---|---|---|---|---|---|"]
    lines += [f"| {name} | {r['rests']} | {r['rest_spread_deg_median_axis']:.2f} | {r['slope_on_preceding_rest']:.2f} | "
              f"{r['hold_variance_from_preceding_rest']:.1f} | {r['hold_variance_from_mean_rest']:.1f} |"
              for name, r in rows]
    return "\n".join(lines) + "\n"


def p1_report() -> str:
    return following_report("P1's five real days (`python benchmarks/rest_jitter.py --p1`)",
                            {f"day {day}": read_recording(data_dir() / f"day{day}_testp.mat") for day in range(1, 6)})


def population_report(people: list[int], argv: list[str]) -> str:
    return following_report(f"synthetic people, first pass (`python benchmarks/rest_jitter.py {' '.join(argv)}`)",
                            {f"person {p}": pass_recording(draw_person(p), 0) for p in people})


def still_rests(twin: Path, out: Path) -> None:
    """A copy of the twin file whose rests do not move from one to the next ([neutral] rep_std_deg 0)."""
    text = twin.read_text()
    head, rest = text.split("[neutral]", 1)
    neutral, classes = rest.split("[[classes]]", 1)
    neutral, n = re.subn(r"rep_std_deg = \[\[.*\]\]", lambda m: re.sub(r"-?\d+\.\d+", "0.0", m.group(0)), neutral)
    if n != 1:
        raise SystemExit(f"{twin}: no [neutral] rep_std_deg to set")
    out.write_text(head + "[neutral]" + neutral + "[[classes]]" + classes)


def run_people(people: list[int], seeds: range, jobs: int) -> dict:
    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="bomi-rest-jitter-") as tmp:
        for person in tqdm(people, desc="people", unit="person"):
            folder = Path(tmp) / str(person)
            folder.mkdir()
            write_logger_mat(folder / "me.mat", one_file(draw_person(person)))
            twin = folder / f"p{person}_twin.toml"
            bomi("twin", str(folder / "me.mat"), "--out", str(twin), "--no-check")
            still = folder / f"p{person}_still_twin.toml"
            still_rests(twin, still)
            results[str(person)] = {}
            for variant, path in (("as fitted", twin), ("still rests", still)):
                out = folder / f"{variant}.json"
                bomi("benchmark", "--participants", str(path), "--operators", "bomi", "--seeds", str(len(seeds)),
                     "--first-seed", str(seeds.start), "--jobs", str(jobs), "--json", str(out))
                results[str(person)][variant] = [
                    {k: e[k] for k in ("seed", "success", "completion_time", "failure", "accuracy_all_decisions",
                                       "accuracy_excused_transitions")} for e in json.loads(out.read_text())["episodes"]]
    return results


def people_report(results: dict, argv: list[str]) -> str:
    lines = ["# Rest jitter: synthetic people, the twin as fitted and with still rests", "",
             f"`python benchmarks/rest_jitter.py {' '.join(argv)}`", "",
             "| variant | successes (95 % interval) | median time of successes (s) | accuracy, transitions excused "
             "(mean) | failures |", "|---|---|---|---|---|"]
    for variant in ("as fitted", "still rests"):
        episodes = [e for person in results.values() for e in person[variant]]
        wins = [e for e in episodes if e["success"]]
        low, high = success_ci95(len(wins), len(episodes))
        median = f"{np.median([e['completion_time'] for e in wins]):.1f}" if wins else "-"
        failures = Counter(e["failure"] for e in episodes if not e["success"])
        lines.append(f"| {variant} | {len(wins)}/{len(episodes)} ({100 * low:.0f}-{100 * high:.0f} %) | {median} | "
                     f"{100 * np.mean([e['accuracy_excused_transitions'] for e in episodes]):.1f} % | "
                     f"{', '.join(f'{k}: {v}' for k, v in failures.items()) or '-'} |")
    lines += ["", "| person | as fitted | still rests |", "|---|---|---|"]
    lines += [f"| {person} | {sum(e['success'] for e in r['as fitted'])}/{len(r['as fitted'])} | "
              f"{sum(e['success'] for e in r['still rests'])}/{len(r['still rests'])} |" for person, r in results.items()]
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--p1", action="store_true", help="measure P1's five real days")
    parser.add_argument("--population", help="population seeds to measure as --p1 measures P1, e.g. 601-671")
    parser.add_argument("--people", help="population seeds, e.g. 601-610 or 601,606 (development people only)")
    parser.add_argument("--first-seed", type=int, default=710, help="first task seed (development: 0-999)")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--name", default="dev")
    args = parser.parse_args()
    if args.p1:
        report = p1_report()
        (RESULTS / "rest_jitter_p1.md").write_text(report)
        print(report)
    if args.population:
        people = people_range(args.population)
        if max(people) >= 1000:
            print("bomi: error: --population: development people only (0-999)", file=sys.stderr)
            return 2
        report = population_report(people, sys.argv[1:])
        (RESULTS / "rest_jitter_population.md").write_text(report)
        print(report)
    if args.people:
        people = people_range(args.people)
        if not (0 <= args.first_seed and args.first_seed + args.seeds <= 1000) or max(people) >= 1000:
            print("bomi: error: --people and the task seeds are development ranges (0-999) here", file=sys.stderr)
            return 2
        started = time.time()
        results = run_people(people, range(args.first_seed, args.first_seed + args.seeds), args.jobs)
        report = people_report(results, sys.argv[1:])
        report += f"\n{(time.time() - started) / 60:.1f} min\n"
        (RESULTS / f"rest_jitter_{args.name}.json").write_text(json.dumps(results, indent=1))
        (RESULTS / f"rest_jitter_{args.name}.md").write_text(report)
        print(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
