"""The BoMI episode's set-up, stage by stage: CPU seconds of the virtual participant's calibration
session (synthesis), its recording (parse, rows, fusion) and the LDA's training, per task seed.

    python benchmarks/setup_cost.py [--seeds 931 932 933] [--repeats 3] [--participant P1]

What ``tasks.stacking.episode.calibrated_model`` does before a BoMI episode's first tick (the warm-up and
neutral calibration of the channel, ~0.05 s, are not included), charged as
``benchmarks/side_by_side.py`` charges it: ``time.process_time`` (every thread of the process), one
process pinned to one core, after one untimed set-up (a sweep worker's steady state: imports,
parsed files and compiled kernels cached). Each stage runs ``--repeats`` times a seed and its least
CPU is kept (the stage's own cost, the least disturbed by other work on the machine); the table
gives each seed and the median over the seeds. Writes benchmarks/results/setup_cost.md.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import time
from pathlib import Path

from bomi.chain import train
from tasks.stacking.episode import arm_profile, calibration_order
from tasks.participants.participant import calibration_session, load_participant, session_recording

RESULTS = Path(__file__).resolve().parent / "results"
STAGES = ("calibration session (synthesis)", "its recording (parse, rows, fusion)", "LDA training")


def least_cpu(call, repeats: int):
    """(the least CPU seconds of ``repeats`` calls, the last call's result)."""
    best, out = float("inf"), None
    for _ in range(repeats):
        cpu = time.process_time()
        out = call()
        best = min(best, time.process_time() - cpu)
    return best, out


def setup_cost(params, profile, seed: int, repeats: int) -> list[float]:
    """CPU seconds of each of STAGES for ``seed``."""
    order = calibration_order(params, profile)
    synthesis, session = least_cpu(lambda: calibration_session(params, profile, seed, order=order), repeats)
    recording, rec = least_cpu(lambda: session_recording(session, profile), repeats)
    training, _ = least_cpu(lambda: train([rec], profile), repeats)
    return [synthesis, recording, training]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[931, 932, 933], help="task seeds (development: 0-999)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each stage a seed (the least CPU is kept)")
    parser.add_argument("--participant", default="P1")
    parser.add_argument("--out", default="setup_cost", help="name of the report in benchmarks/results/")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    params = load_participant(args.participant)
    profile = arm_profile(params.profile)
    setup_cost(params, profile, args.seeds[0], 1)   # untimed: a worker that has run one episode before
    load = os.getloadavg()[0]
    rows = {seed: setup_cost(params, profile, seed, args.repeats) for seed in args.seeds}
    medians = [statistics.median(row[k] for row in rows.values()) for k in range(len(STAGES))]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).resolve().parent).stdout.strip() or "unknown"
    seeds = " ".join(str(seed) for seed in args.seeds)
    lines = [f"# The BoMI episode's set-up, CPU s ({args.participant}, seeds {seeds})", "",
             f"`python benchmarks/setup_cost.py --seeds {seeds} --repeats {args.repeats}` at commit {commit}; "
             f"one core, the least of {args.repeats} runs of each stage; 1-min load average {load:.2f} before, "
             f"{os.getloadavg()[0]:.2f} after.", "",
             "| seed | " + " | ".join(STAGES) + " | all |", "|---" * (len(STAGES) + 2) + "|"]
    for seed, row in rows.items():
        lines.append(f"| {seed} | " + " | ".join(f"{v:.3f}" for v in row) + f" | {sum(row):.3f} |")
    total = statistics.median(sum(row) for row in rows.values())
    lines.append("| **median** | " + " | ".join(f"**{v:.3f}**" for v in medians) + f" | **{total:.3f}** |")
    text = "\n".join(lines) + "\n"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.out}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
