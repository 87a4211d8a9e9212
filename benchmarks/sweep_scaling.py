"""Throughput of ``bomi sweep`` on 1 and 2 workers, on the process pool and on a local Ray, in
episodes per hour, and its projection to a 1,000-episode study on a 64-core Ray cluster.

    python benchmarks/sweep_scaling.py [--seeds 6] [--workers 1,2]

The sweep: ``--seeds`` full BoMI stacking episodes of virtual P1 (development seeds from 0; the
calibration session and the LDA's training included, as in any sweep), run by ``bomi sweep``'s
code into a fresh directory for each engine and worker count.  Charged: the sweep's wall time from
the call to its last record (the workers' start-up and imports included), and for the process pool
the CPU seconds of its worker processes (``getrusage(RUSAGE_CHILDREN)``: the cost on a core no one
else uses; Ray's workers are not this process's children, so only their wall time is known).
Projection for E episodes on C cores: start-up + ceil(E / C) x the cost of one episode (a lower
bound: every core busy until the last round), and that plus the longest episode of the sweep (the
last round waits for it).  The machine is shared: the 1-min load average before and after each
run is written beside it.  Writes benchmarks/results/sweep_scaling.md and .json.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import tempfile
import time
from pathlib import Path

from tasks.cli.engine import ProcessPool, RayCluster
from tasks.cli.sweep import Grid, run_sweep

RESULTS = Path(__file__).resolve().parent / "results"
PROJECTED_EPISODES = 1000
PROJECTED_CORES = (1, 2, 8, 64)


def timed_sweep(grid: Grid, engine) -> tuple[float, float, list[dict]]:
    """Wall seconds, CPU seconds of the finished child processes, the records."""
    with tempfile.TemporaryDirectory() as out:
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        started = time.perf_counter()
        records = run_sweep(grid, Path(out), engine, summarize=False).records
        wall = time.perf_counter() - started
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        return wall, after.ru_utime + after.ru_stime - children.ru_utime - children.ru_stime, records


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--workers", default="1,2")
    args = parser.parse_args()
    workers = [int(w) for w in args.workers.split(",")]
    grid = Grid(participants=("P1",), operators=("bomi",), seeds=tuple(range(args.seeds)), vary={},
                metric="completion_time_mean", setting=None, source="sweep_scaling")
    runs, outcomes = [], {}
    for engine_name, make in (("local", ProcessPool), ("ray", lambda n: RayCluster(None, n))):
        for n in workers:
            load = os.getloadavg()[0]
            wall, cpu, records = timed_sweep(grid, make(n))
            outcomes[(engine_name, n)] = [{k: v for k, v in r.items() if k not in ("wall_time", "cpu_time",
                                           "realtime_factor", "realtime_factor_cpu")} for r in records]
            runs.append({"engine": engine_name, "workers": n, "episodes": len(records), "wall_s": wall,
                         "workers_cpu_s": cpu if engine_name == "local" else None,
                         "episodes_per_hour": 3600 * len(records) / wall,
                         "sim_s": sum(r["sim_time"] for r in records), "longest_sim_s": max(r["sim_time"] for r in records),
                         "load_before": load, "load_after": os.getloadavg()[0]})
            print(runs[-1], flush=True)
    identical = all(o == outcomes[("local", workers[0])] for o in outcomes.values())
    base = next(r for r in runs if r["engine"] == "local" and r["workers"] == 1)
    ray_one = next(r for r in runs if r["engine"] == "ray" and r["workers"] == 1)
    ray_startup = max(0.0, ray_one["wall_s"] - base["wall_s"])
    costs = {"CPU (an idle core)": base["workers_cpu_s"] / base["episodes"],
             "wall (this shared machine)": base["wall_s"] / base["episodes"]}
    longest = base["longest_sim_s"] / (base["sim_s"] / base["episodes"])   # the longest episode, in mean episodes
    projection = {name: {c: (ray_startup + math.ceil(PROJECTED_EPISODES / c) * cost,
                             ray_startup + (math.ceil(PROJECTED_EPISODES / c) - 1 + longest) * cost)
                         for c in PROJECTED_CORES} for name, cost in costs.items()}
    lines = [f"# Sweep throughput ({args.seeds} full P1 BoMI episodes, seeds 0-{args.seeds - 1}, per engine and worker count)", "",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores shared with other work, "
             f"Python {platform.python_version()}; `python benchmarks/sweep_scaling.py --seeds {args.seeds} "
             f"--workers {args.workers}` at commit {os.popen('git rev-parse --short HEAD').read().strip()}.", "",
             "| engine | workers | wall (s) | episodes per hour | speed-up over 1 pool worker | workers' CPU (s) "
             "| x real time, all workers | load average before / after |",
             "|---|---|---|---|---|---|---|---|"]
    for r in runs:
        cpu = f"{r['workers_cpu_s']:.1f}" if r["workers_cpu_s"] is not None else "n/a (Ray)"
        lines.append(f"| {r['engine']} | {r['workers']} | {r['wall_s']:.1f} | {r['episodes_per_hour']:.0f} "
                     f"| {base['wall_s'] / r['wall_s']:.2f} | {cpu} | {r['sim_s'] / r['wall_s']:.1f} "
                     f"| {r['load_before']:.1f} / {r['load_after']:.1f} |")
    lines += ["", f"Records identical (every field but the timing ones) on every engine and worker count: "
                  f"{'yes' if identical else 'NO'}.", "",
              f"Cost of one episode on one pool worker: {costs['CPU (an idle core)']:.1f} s of CPU, "
              f"{costs['wall (this shared machine)']:.1f} s of wall time here ({base['sim_s'] / base['episodes']:.0f} s "
              f"of simulated task on average, the longest {longest:.2f} x the mean; calibration and training included). "
              f"Ray's start-up here: {ray_startup:.1f} s (its 1-worker wall time minus the pool's).", "",
              f"| cores (Ray) | {PROJECTED_EPISODES} episodes at the CPU cost (idle cores): lower bound - with the longest "
              f"episode last | at this machine's wall cost |", "|---|---|---|"]
    for c in PROJECTED_CORES:
        cpu_low, cpu_high = projection["CPU (an idle core)"][c]
        wall_low, wall_high = projection["wall (this shared machine)"][c]
        lines.append(f"| {c} | {cpu_low / 60:.1f} - {cpu_high / 60:.1f} min | {wall_low / 60:.1f} - {wall_high / 60:.1f} min |")
    text = "\n".join(lines) + "\n"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "sweep_scaling.md").write_text(text, encoding="utf-8")
    (RESULTS / "sweep_scaling.json").write_text(json.dumps(
        {"seeds": args.seeds, "runs": runs, "identical_records": identical, "cost_per_episode_s": costs,
         "ray_startup_s": ray_startup, "projection_s": projection}, indent=2) + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
