"""Episode speed side by side, in one run on one core: dm_control's own JACO stacking task
(``stack_2_bricks_features``, random actions) against ``run_job`` of our joystick and BoMI episodes.

    python benchmarks/side_by_side.py [--rounds 3] [--seed 0]

Each episode runs in a fresh process (nothing cached from an earlier one; imports done before the
clock starts) and is timed from building its environment (for the BoMI: the virtual participant's
calibration session and the LDA's training included) to its end, as x real time (simulated
seconds per wall-clock second, and per second of this process's CPU time: on a shared machine
the CPU figure is the steadier one).  The three kinds take turns ``--rounds`` times; the median
of each is reported, and our episodes' ratios to dm_control's (bars: joystick >= 1.0, BoMI >=
0.5).  Writes benchmarks/results/side_by_side.md and .json.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import platform
import statistics
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from dm_control import manipulation

from tasks.cli.task import EpisodeJob, run_job

RESULTS = Path(__file__).resolve().parent / "results"


def dm_control_stacking(seed: int) -> float:
    """One episode of dm_control's JACO stacking task with uniform random actions; its simulated time."""
    env = manipulation.load("stack_2_bricks_features", seed=seed)
    spec, rng = env.action_spec(), np.random.default_rng(seed)
    step = env.reset()
    while not step.last():
        step = env.step(rng.uniform(spec.minimum, spec.maximum))
    return float(env.physics.data.time)


def our_episode(operator: str, seed: int) -> float:
    """One of our stacking episodes of virtual P1 (``bomi run-task``'s code); its simulated time."""
    log = run_job(EpisodeJob(operator, "P1", seed))
    return float(log.t[-1] + (log.t[1] - log.t[0]))


def timed(kind: str, seed: int) -> dict:
    wall, cpu = time.perf_counter(), time.process_time()
    sim = KINDS[kind](seed)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return {"sim_s": sim, "wall_s": wall, "cpu_s": cpu, "x_wall": sim / wall, "x_cpu": sim / cpu}


KINDS: dict[str, Callable[[int], float]] = {
    "dm_control stack_2_bricks_features (random actions)": dm_control_stacking,
    "ours: joystick episode (P1)": lambda seed: our_episode("joystick", seed),
    "ours: BoMI episode (P1, calibration included)": lambda seed: our_episode("bomi", seed),
}
BARS = {"ours: joystick episode (P1)": 1.0, "ours: BoMI episode (P1, calibration included)": 0.5}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0, help="task seed (development seeds 0-999)")
    args = parser.parse_args()
    runs: dict[str, list[dict]] = {name: [] for name in KINDS}
    fresh = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), max_tasks_per_child=1)
    with fresh:
        for _ in range(args.rounds):
            for name in KINDS:
                runs[name].append(fresh.submit(timed, name, args.seed).result())
    medians = {name: {key: statistics.median(r[key] for r in rs) for key in rs[0]} for name, rs in runs.items()}
    reference = medians[next(iter(KINDS))]
    lines = [f"# Episode speed side by side ({args.rounds} rounds, seed {args.seed}, each episode alone in a fresh process)", "",
             f"Machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}; "
             "`python benchmarks/side_by_side.py`. x real time = simulated s / s, set-up included; medians.", "",
             "| episode | simulated (s) | wall (s) | x real time (wall) | x real time (CPU) | ratio to dm_control "
             "(wall) | ratio (CPU) | bar |", "|---|---|---|---|---|---|---|---|"]
    for name, m in medians.items():
        bar = f">= {BARS[name]}" if name in BARS else ""
        lines.append(f"| {name} | {m['sim_s']:.1f} | {m['wall_s']:.2f} | {m['x_wall']:.1f} | {m['x_cpu']:.1f} "
                     f"| {m['x_wall'] / reference['x_wall']:.2f} | {m['x_cpu'] / reference['x_cpu']:.2f} | {bar} |")
    text = "\n".join(lines) + "\n"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "side_by_side.md").write_text(text, encoding="utf-8")
    (RESULTS / "side_by_side.json").write_text(json.dumps({"seed": args.seed, "runs": runs, "medians": medians},
                                                          indent=2) + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
