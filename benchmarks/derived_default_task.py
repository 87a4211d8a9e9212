"""The derived default profile of new people in the stacking task, at the code of any checkout, and
two such runs compared person by person: how a change to the derivation (e.g. which motions become
the mode buttons) moves success and time.

    python benchmarks/derived_default_task.py --people 400-417 --first-seed 640 --seeds 2 --name after
    git worktree add /tmp/before f89e803
    python benchmarks/derived_default_task.py --code /tmp/before --people 400-417 --first-seed 640 \\
        --seeds 2 --name before
    python benchmarks/derived_default_task.py --compare before after

Per person (tasks/participants/population.py, drawn by this checkout so both runs see the same
people): both passes of the protocol in one logger .mat file, then at the code of ``--code``
``bomi twin FILE --no-check`` and ``bomi benchmark --participants TWINS --operators bomi
[--recovery R]``. No
design step (benchmarks/new_people_task.py runs the whole path). Development people and seeds only.

Writes benchmarks/results/derived_default_NAME.json (every episode's record); ``--compare A B`` writes
benchmarks/results/derived_default_A_vs_B.md: per person the profile's buttons and successes, and
the successes pooled with Wilson 95 % intervals.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from new_people_task import bomi  # noqa: E402  (this folder: the same bomi command runner)

from bomi.derived import BUTTON_NAMES  # noqa: E402
from bomi.recording import write_logger_mat  # noqa: E402
from tasks.stacking.metrics import success_ci95  # noqa: E402
from tasks.participants.population import draw_person, one_file  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"


def people_range(text: str) -> list[int]:
    """'400-417' or '400,403' -> the population seeds."""
    if "-" in text:
        first, last = (int(part) for part in text.split("-"))
        return list(range(first, last + 1))
    return [int(part) for part in text.split(",")]


def buttons(profile: Path) -> str:
    """The profile's mode buttons as 'B1 c3, B2 c5' (or 'auto-mode')."""
    classes = tomllib.loads(profile.read_text())["classes"]
    pressed = [f"{c['function']} {c['name']}" for c in classes if c["function"] in BUTTON_NAMES]
    return ", ".join(sorted(pressed)) or "auto-mode"


def run(args) -> int:
    code = Path(args.code).resolve()
    people = people_range(args.people)
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="bomi-derived-") as directory:
        work = Path(directory)
        twins, layout = [], {}
        for seed in tqdm(people, desc="twins", unit="person"):
            recording = work / f"p{seed}.mat"
            write_logger_mat(recording, one_file(draw_person(seed)))
            twin = work / f"p{seed}_twin.toml"
            bomi("twin", str(recording), "--out", str(twin), "--no-check", code=code)
            twins.append(str(twin))
            layout[seed] = buttons(work / f"p{seed}_twin.profile.toml")
        out = work / "episodes.json"
        print(f"benchmark: {len(twins)} people x {args.seeds} seeds from {args.first_seed}", flush=True)
        bomi("benchmark", "--participants", ",".join(twins), "--operators", "bomi", "--seeds", str(args.seeds),
             "--first-seed", str(args.first_seed), "--jobs", str(args.jobs), "--json", str(out),
             *(["--recovery", args.recovery] if args.recovery else []), code=code)
        episodes = json.loads(out.read_text())["episodes"]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=code).stdout.strip()
    record = {"argv": sys.argv[1:], "commit": commit, "minutes": (time.monotonic() - start) / 60, "people": {
        seed: {"buttons": layout[seed],
               "episodes": [e | {"mechanism": (e["stuck"] or {}).get("mechanism")}  # the whole record
                            for e in episodes if Path(e["participant"]).name == f"p{seed}_twin.toml"]}
        for seed in people}}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"derived_default_{args.name}.json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"{sum(e['success'] for p in record['people'].values() for e in p['episodes'])} successes "
          f"({record['minutes']:.1f} min, commit {commit})")
    return 0


def successes(person: dict) -> str:
    return f"{sum(e['success'] for e in person['episodes'])}/{len(person['episodes'])}"


def compare(a_name: str, b_name: str) -> int:
    a, b = (json.loads((RESULTS / f"derived_default_{n}.json").read_text()) for n in (a_name, b_name))
    lines = [f"# The derived default in the task: {a_name} ({a['commit']}) vs {b_name} ({b['commit']})", "",
             f"`python benchmarks/derived_default_task.py {' '.join(a['argv'])}` ({a['minutes']:.1f} min),",
             f"`python benchmarks/derived_default_task.py {' '.join(b['argv'])}` ({b['minutes']:.1f} min),",
             f"`python benchmarks/derived_default_task.py --compare {a_name} {b_name}`", "",
             f"| person | {a_name}: buttons | successes | {b_name}: buttons | successes | {b_name}'s failures |",
             "|---:|---|---|---|---|---|"]
    for seed, pa in a["people"].items():
        pb = b["people"][seed]
        failed = ", ".join(f"{e['seed']}: {e['mechanism']}" for e in pb["episodes"] if not e["success"])
        lines.append(f"| {seed} | {pa['buttons']} | {successes(pa)} | {pb['buttons']} | {successes(pb)} | {failed or '-'} |")
    for name, run_ in ((a_name, a), (b_name, b)):
        outcomes = [e["success"] for p in run_["people"].values() for e in p["episodes"]]
        low, high = success_ci95(sum(outcomes), len(outcomes))
        lines.append(f"\n{name}: {sum(outcomes)}/{len(outcomes)} successes ({100 * sum(outcomes) / len(outcomes):.0f} %, "
                     f"Wilson 95 % [{100 * low:.0f}, {100 * high:.0f}] %)")
    text = "\n".join(lines) + "\n"
    (RESULTS / f"derived_default_{a_name}_vs_{b_name}.md").write_text(text)
    print(text)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two runs' result files by name")
    parser.add_argument("--code", default=str(ROOT), help="the checkout whose bomi runs (default: this one)")
    parser.add_argument("--people", default="400-417", help="population seeds, 'FIRST-LAST' or a list (development)")
    parser.add_argument("--first-seed", type=int, default=640, help="first task seed (development)")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--recovery", default=None, help="bomi benchmark's --recovery (default: the operator file's)")
    parser.add_argument("--name", default="run", help="result file's name")
    args = parser.parse_args()
    return compare(*args.compare) if args.compare else run(args)


if __name__ == "__main__":
    sys.exit(main())
