"""How long `bomi --help` (and each command's --help) takes, and what it imports.

Runs ``python -m tasks.cli [COMMAND] --help`` in fresh interpreters from this source tree and,
with ``--before DIR``, from another checkout (e.g. ``git archive 63c8e14 | tar -x -C DIR``, the
commit before `bomi --help` stopped importing the command modules), ``--repeat`` times each, and
reports the median wall time and the median CPU time (user + system: what the command itself costs,
whatever else the machine is doing). Also reports the cumulative import time of the top-level help
(``python -X importtime``) and the heavy libraries it loads. Writes
benchmarks/results/cli_startup.md and .json.

    python benchmarks/cli_startup.py [--repeat 7] [--before DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("sklearn", "scipy", "mujoco", "pinocchio", "matplotlib", "dm_control", "numba")
sys.path.insert(0, str(ROOT))
from tasks.cli import COMMANDS  # noqa: E402  (every sub-command, from the command table)


def _environment(tree: Path) -> dict[str, str]:
    return os.environ | {"PYTHONPATH": str(tree), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def wall_times(tree: Path, argv: list[str], repeat: int) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system) seconds of each of ``repeat`` runs."""
    walls, cpus = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "tasks.cli", *argv], cwd=tree, env=_environment(tree),
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        walls.append(time.perf_counter() - start)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return walls, cpus


def import_profile(tree: Path) -> tuple[float, list[str]]:
    """Cumulative import time (s) of everything `bomi --help` imports, and the heavy libraries among it."""
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "tasks.cli", "--help"], cwd=tree,
                          env=_environment(tree), capture_output=True, text=True, check=True)
    total, heavy = 0, set()
    for line in done.stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line or "cumulative" in line:
            continue
        _, cumulative, name = line.removeprefix("import time:").split("|")
        if not name.startswith("  "):  # top level: cumulative includes everything below it
            total += int(cumulative)
        heavy |= {name.strip().split(".")[0]} & set(HEAVY)
    return total / 1e6, sorted(heavy)


def measure(tree: Path, repeat: int) -> dict:
    rows = []
    for argv in (["--help"], *([command, "--help"] for command in COMMANDS)):
        walls, cpus = wall_times(tree, argv, repeat)
        rows.append({"command": "bomi " + " ".join(argv), "median_s": statistics.median(walls),
                     "max_s": max(walls), "cpu_median_s": statistics.median(cpus), "runs": len(walls)})
        print(f"{tree}: {rows[-1]['command']:<22} median {rows[-1]['median_s']:.2f} s", file=sys.stderr)
    imports_s, heavy = import_profile(tree)
    return {"tree": str(tree), "rows": rows, "help_import_time_s": imports_s, "help_heavy_imports": heavy}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="runs per command (default %(default)s)")
    parser.add_argument("--before", type=Path, help="another source tree to measure beside this one (default: none)")
    args = parser.parse_args()
    trees = {"before": args.before, "now": ROOT} if args.before else {"now": ROOT}
    results = {tag: measure(tree, args.repeat) for tag, tree in trees.items()}
    record = {"python": platform.python_version(), "load_average": os.getloadavg()[0], "repeat": args.repeat,
              "trees": results}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "cli_startup.json").write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    lines = [f"CLI start-up: median wall time of {args.repeat} runs each in a fresh interpreter, machine load "
             f"average {record['load_average']:.1f} on {os.cpu_count()} CPUs (`python benchmarks/cli_startup.py"
             f"{' --before DIR' if args.before else ''}`).", "",
             "| command | " + " | ".join(f"{tag}: wall median / max, CPU median (s)" for tag in results) + " |",
             "|---|" + "---|" * len(results)]
    for i, row in enumerate(results["now"]["rows"]):
        lines.append(f"| `{row['command']}` | " + " | ".join(
            f"{r['rows'][i]['median_s']:.2f} / {r['rows'][i]['max_s']:.2f}, {r['rows'][i]['cpu_median_s']:.2f}"
            for r in results.values()) + " |")
    lines += ["", "`bomi --help` imports (python -X importtime, cumulative):"]
    lines += [f"- {tag}: {r['help_import_time_s']:.2f} s; heavy libraries loaded: "
              f"{', '.join(r['help_heavy_imports']) or 'none'}" for tag, r in results.items()]
    (RESULTS / "cli_startup.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
