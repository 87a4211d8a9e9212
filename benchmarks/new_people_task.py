"""New people end to end in the stacking task (issue 41's bars): for each synthetic person, the
path a new user takes, as commands, with no hand edit.

    python benchmarks/new_people_task.py --first-person P --people 30 --first-seed S --seeds 2 \
        [--design-seeds D --design-first-seed 600] [--jobs 2] [--name NAME]

Per person (tasks/participants/population.py; people drawn from ``--first-person`` on): both passes
of the protocol in one logger .mat file (``population.one_file``, ``bomi.recording.write_logger_mat``), then

1. ``bomi twin FILE --out twin.toml``: the passes found, the profile derived, the twin fitted;
2. ``bomi design twin.toml [--seeds D] --first-seed DS``: the candidate layouts on development seeds,
   the recommended profile written (people with fewer than five motions have one candidate);
3. ``bomi benchmark --participants twin.toml --operators bomi --seeds N --first-seed S``: the
   derived default on the task seeds given (held out when the range is fresh); and, when the
   recommendation differs from the default, the same seeds with ``bomi twin FILE --profile
   RECOMMENDED`` (the twin refitted on the recommended profile).

Bars, stated before the run: every person runs the task with the derived profile (each command
exits 0 and each episode ends, success or not); the recommended layout is never slower than the
derived default, pooled over the people whose recommendation differs: its successes at least the
default's, and the mean paired difference of completion time (recommended - default, over the
(person, seed) pairs both succeed) at most 0 (its Student-t 95 % interval reported).

Writes benchmarks/results/new_people_task_NAME.json (every person, every episode record) and .md.

    python benchmarks/new_people_task.py --pool 17200 17300

pools runs already made (their JSON files) into one verdict, as the README reports a bar.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats
from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bomi.recording import write_logger_mat  # noqa: E402
from tasks.participants.population import draw_person, one_file  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"


def bomi(*argv: str, code: Path = ROOT) -> str:
    """A bomi command (the installed entry point's module) with the code of the checkout ``code``, its stdout;
    a failure stops the run with its stderr."""
    ran = subprocess.run([sys.executable, "-m", "tasks.cli", *argv], capture_output=True, text=True, cwd=code)
    if ran.returncode != 0:
        raise SystemExit(f"bomi {' '.join(argv)}: exit {ran.returncode}: {ran.stderr.strip().splitlines()[-1:]}")
    return ran.stdout


def episodes(twin: Path, seeds: range, jobs: int, out: Path) -> list[dict]:
    bomi("benchmark", "--participants", str(twin), "--operators", "bomi", "--seeds", str(len(seeds)),
         "--first-seed", str(seeds.start), "--jobs", str(jobs), "--json", str(out))
    return json.loads(out.read_text())["episodes"]


def person_run(seed: int, args, work: Path) -> dict:
    person = draw_person(seed)
    recording = work / f"person{seed}.mat"
    write_logger_mat(recording, one_file(person))
    twin = work / f"person{seed}_twin.toml"
    bomi("twin", str(recording), "--out", str(twin))
    recommended, design = work / f"person{seed}_design.toml", work / f"person{seed}_design.json"
    design_seeds = () if args.design_seeds is None else ("--seeds", str(args.design_seeds))
    bomi("design", str(twin), *design_seeds, "--first-seed", str(args.design_first_seed),
         "--out", str(recommended), "--json", str(design), "--jobs", str(args.jobs))
    chosen = json.loads(design.read_text())
    candidates = chosen["candidates"]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    default = episodes(twin, seeds, args.jobs, work / f"person{seed}_default.json")
    differs = chosen["recommended"] != candidates[0]["name"]
    mine = default
    if differs:
        twin_rec = work / f"person{seed}_twin_recommended.toml"
        bomi("twin", str(recording), "--profile", str(recommended), "--out", str(twin_rec))
        mine = episodes(twin_rec, seeds, args.jobs, work / f"person{seed}_recommended.json")
    return {"person": seed, "classes": person.n_classes, "default": candidates[0]["name"],
            "recommended": chosen["recommended"], "differs": differs, "reason": chosen.get("reason"),
            "design": [{k: c[k] for k in ("name", "episodes", "successes", "completion_time_mean")} for c in candidates],
            "default_episodes": default, "recommended_episodes": mine}


def summary(people: list[dict]) -> dict:
    ran = [e for p in people for e in p["default_episodes"]]
    differing = [p for p in people if p["differs"]]
    pairs = [(r["completion_time"] - d["completion_time"]) for p in differing
             for d, r in zip(p["default_episodes"], p["recommended_episodes"]) if d["success"] and r["success"]]
    diff = float(np.mean(pairs)) if pairs else None
    ci = None
    if len(pairs) >= 2:
        half = stats.t.ppf(0.975, len(pairs) - 1) * np.std(pairs, ddof=1) / np.sqrt(len(pairs))
        ci = (diff - half, diff + half)
    default_ok = sum(e["success"] for p in differing for e in p["default_episodes"])
    rec_ok = sum(e["success"] for p in differing for e in p["recommended_episodes"])
    return {"people": len(people), "episodes": len(ran), "successes": sum(e["success"] for e in ran),
            "people_with_a_success": sum(any(e["success"] for e in p["default_episodes"]) for p in people),
            "differing": len(differing), "differing_episodes": sum(len(p["default_episodes"]) for p in differing),
            "default_successes_differing": default_ok, "recommended_successes_differing": rec_ok,
            "paired_pairs": len(pairs), "time_difference_mean_s": diff, "time_difference_ci95_s": ci,
            "every_person_ran": all(len(p["default_episodes"]) == len(ran) // len(people) for p in people),
            "never_slower": (rec_ok >= default_ok and (diff is None or diff <= 0.0)) if differing else None}


def markdown(people: list[dict], total: dict, argv: list[str], minutes: float) -> str:
    lines = ["# New people in the stacking task (issue 41)", "",
             f"`python benchmarks/new_people_task.py {' '.join(argv)}` ({minutes:.1f} min)", "",
             "| person | classes | derived default | default: successes, mean time (s) | recommended | "
             "recommended: successes, mean time (s) |", "|---:|---:|---|---|---|---|"]

    def cell(records):
        times = [e["completion_time"] for e in records if e["success"]]
        return f"{len(times)}/{len(records)}, " + (f"{np.mean(times):.1f}" if times else "-")
    for p in people:
        lines.append(f"| {p['person']} | {p['classes']} | {p['default']} | {cell(p['default_episodes'])} | "
                     f"{p['recommended'] if p['differs'] else '(the default)'} | "
                     f"{cell(p['recommended_episodes']) if p['differs'] else '-'} |")
    lines += ["", *verdict(total)]
    return "\n".join(lines) + "\n"


def verdict(total: dict) -> list[str]:
    """The bars' lines of a run's (or pooled runs') ``summary``."""
    ci = total["time_difference_ci95_s"]
    return [f"Every person ran the task with the derived profile: {'yes' if total['every_person_ran'] else 'NO'} "
              f"({total['episodes']} episodes, {total['successes']} successes; {total['people_with_a_success']} of "
              f"{total['people']} people with at least one success).",
              f"Recommendation differs from the default for {total['differing']} people: successes "
              f"{total['recommended_successes_differing']} vs {total['default_successes_differing']} of "
              f"{total['differing_episodes']}; completion time recommended - default over {total['paired_pairs']} "
              f"pairs both successful: " + (f"{total['time_difference_mean_s']:+.1f} s" if total['time_difference_mean_s']
                                             is not None else "-")
              + (f" [{ci[0]:+.1f}, {ci[1]:+.1f}]" if ci else "") + "; never slower: "
              + {True: "met", False: "**missed**", None: "no person to compare"}[total["never_slower"]]]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pool", nargs="+", metavar="NAME", help="pool the runs NAME (their result files) and stop")
    parser.add_argument("--first-person", type=int, help="first population seed")
    parser.add_argument("--people", type=int, default=30)
    parser.add_argument("--first-seed", type=int, help="first task seed of the comparison")
    parser.add_argument("--seeds", type=int, default=2, help="task seeds per person and layout (default %(default)s)")
    parser.add_argument("--design-seeds", type=int, help="bomi design's seeds (default: bomi design's own)")
    parser.add_argument("--design-first-seed", type=int, default=600, help="bomi design's first seed (development)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--name", default=None, help="result files' name (default: the first person)")
    args = parser.parse_args()
    if args.pool:
        runs = [json.loads((RESULTS / f"new_people_task_{n}.json").read_text()) for n in args.pool]
        total = summary([p for run in runs for p in run["people"]])
        print("\n".join(verdict(total)))
        return 0
    if args.first_person is None or args.first_seed is None:
        parser.error("--first-person and --first-seed are required (or --pool)")
    name = args.name or str(args.first_person)
    start, people = time.monotonic(), []
    with tempfile.TemporaryDirectory(prefix="bomi-new-people-") as directory:
        for seed in tqdm(range(args.first_person, args.first_person + args.people), desc="people", unit="person"):
            people.append(person_run(seed, args, Path(directory)))
    total = summary(people)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"new_people_task_{name}.json").write_text(json.dumps({"argv": sys.argv[1:], "summary": total,
                                                                      "people": people}, indent=1) + "\n")
    text = markdown(people, total, sys.argv[1:], (time.monotonic() - start) / 60)
    (RESULTS / f"new_people_task_{name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
