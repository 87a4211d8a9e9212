"""Wall time of a sweep on 1 and 2 workers, on the process pool and on a local Ray, and its
projection to a 1,000-episode sweep on more cores.

    python benchmarks/sweep_scaling.py [--seeds 6] [--workers 1,2]

The sweep: ``--seeds`` full BoMI stacking episodes of virtual P1 (development seeds from 0; the
calibration session and the LDA's training included, as in any sweep), run by ``bomi sweep``'s
code into a fresh directory for each engine and worker count.  Cost per episode per core = the
wall time on one worker of the process pool / episodes.  Projection for E episodes on C cores:
start-up + ceil(E / C) x that cost (every core busy until the last round; the episodes' spread in
length is ignored, so it is a lower bound).  Writes benchmarks/results/sweep_scaling.md and .json.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import tempfile
import time
from pathlib import Path

from tasks.cli.engine import ProcessPool, RayCluster
from tasks.cli.sweep import Grid, run_sweep

RESULTS = Path(__file__).resolve().parent / "results"
PROJECTED_EPISODES = 1000
PROJECTED_CORES = (1, 2, 8, 32, 128)


def timed_sweep(grid: Grid, engine) -> tuple[float, list[dict]]:
    with tempfile.TemporaryDirectory() as out:
        started = time.perf_counter()
        records = run_sweep(grid, Path(out), engine, summarize=False).records
        return time.perf_counter() - started, records


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
            wall, records = timed_sweep(grid, make(n))
            outcomes[(engine_name, n)] = [{k: v for k, v in r.items() if k not in ("wall_time", "cpu_time",
                                           "realtime_factor", "realtime_factor_cpu")} for r in records]
            runs.append({"engine": engine_name, "workers": n, "episodes": len(records), "wall_s": wall,
                         "sim_s": sum(r["sim_time"] for r in records),
                         "episode_loop_cpu_s": sum(r["cpu_time"] for r in records)})
            print(runs[-1], flush=True)
    identical = all(o == outcomes[("local", workers[0])] for o in outcomes.values())
    base = next(r for r in runs if r["engine"] == "local" and r["workers"] == 1)
    per_episode = base["wall_s"] / base["episodes"]
    ray_startup = max(0.0, next(r for r in runs if r["engine"] == "ray" and r["workers"] == 1)["wall_s"] - base["wall_s"])
    projection = {c: ray_startup + math.ceil(PROJECTED_EPISODES / c) * per_episode for c in PROJECTED_CORES}
    lines = [f"# Sweep scaling ({args.seeds} full P1 BoMI episodes, seeds 0-{args.seeds - 1})", "",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores shared with other work, "
             f"Python {platform.python_version()}; `python benchmarks/sweep_scaling.py --seeds {args.seeds}`.", "",
             "| engine | workers | wall (s) | per episode (s) | speed-up over 1 local worker | x real time, all workers |",
             "|---|---|---|---|---|---|"]
    for r in runs:
        lines.append(f"| {r['engine']} | {r['workers']} | {r['wall_s']:.1f} | {r['wall_s'] / r['episodes']:.1f} "
                     f"| {base['wall_s'] / r['wall_s']:.2f} | {r['sim_s'] / r['wall_s']:.1f} |")
    lines += ["", f"Records identical (every field but the timing ones) on every engine and worker count: "
                  f"{'yes' if identical else 'NO'}.", "",
              f"Cost per episode per core: {per_episode:.1f} s of wall time (calibration, training and "
              f"{base['sim_s'] / base['episodes']:.0f} s of simulated task on average). Ray's start-up here: "
              f"{ray_startup:.1f} s.", "",
              f"| cores | projected wall time of {PROJECTED_EPISODES} such episodes |", "|---|---|"]
    lines += [f"| {c} | {s / 3600:.2f} h |" for c, s in projection.items()]
    text = "\n".join(lines) + "\n"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "sweep_scaling.md").write_text(text, encoding="utf-8")
    (RESULTS / "sweep_scaling.json").write_text(json.dumps(
        {"seeds": args.seeds, "runs": runs, "identical_records": identical, "cost_per_episode_s": per_episode,
         "ray_startup_s": ray_startup, "projection_s": projection}, indent=2) + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
