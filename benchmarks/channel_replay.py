"""What the BoMI channel costs per control tick, without the planner and the physics around it.

    python benchmarks/channel_replay.py [--seeds 910 911] [--repeats 5]

For each task seed (development seeds: 0-999), a BoMI episode of virtual P1 is run once as
``bomi run-task`` runs it (``run_job``: calibration, then the task), and every call of
``BomiChannel.command`` (the person's intent, the tick, the hand's speed, the mode) is recorded,
with a copy of the channel as calibration left it.  The calls are then replayed on fresh copies of
that channel, ``--repeats`` times: the virtual participant's synthesis and link, the frame parser and
the streaming chain (fusion, windows, features, LDA, vote), exactly the work of the episode's ticks
(each replay's decisions are checked equal to the episode's).  Reported: CPU microseconds per tick
(``time.process_time``), the least of the repeats (the one least disturbed by other processes on a
shared machine) and their median.  The replay runs with warmer caches than the episode, where every
tick also steps the physics: read differences, not absolute episode costs.
Writes benchmarks/results/channel_replay.md and .json.
"""
from __future__ import annotations

import argparse
import copy
import json
import statistics
import sys
import time
from pathlib import Path

from tqdm import tqdm

import tasks.cli.task as task_cli
from tasks.stacking.episode import BomiChannel

RESULTS = Path(__file__).resolve().parent / "results"


def recorded_episode(seed: int) -> tuple[BomiChannel, BomiChannel, list[tuple[tuple, dict]]]:
    """A BoMI episode of P1 on task ``seed``: a copy of its channel as calibration left it, the channel
    after the episode, and every call of its ``command`` (copies of the arguments)."""
    built, calls = [], []
    calibrated, command = task_cli.calibrated_channel, BomiChannel.command

    def keep_a_copy(*args, **kwargs):
        channel = calibrated(*args, **kwargs)
        built.append((copy.deepcopy(channel), channel))
        return channel

    def recorded(self, *args, **kwargs):
        calls.append(copy.deepcopy((args, kwargs)))
        return command(self, *args, **kwargs)

    task_cli.calibrated_channel, BomiChannel.command = keep_a_copy, recorded
    try:
        task_cli.run_job(task_cli.EpisodeJob("bomi", "P1", seed))
    finally:
        task_cli.calibrated_channel, BomiChannel.command = calibrated, command
    (fresh, used), = built
    return fresh, used, calls


def replay(fresh: BomiChannel, calls: list[tuple[tuple, dict]]) -> tuple[float, BomiChannel]:
    """CPU seconds of the recorded calls on a copy of ``fresh``, and that copy after them."""
    channel = copy.deepcopy(fresh)
    started = time.process_time()
    for args, kwargs in calls:
        channel.command(*args, **kwargs)
    return time.process_time() - started, channel


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[910, 911], help="task seeds (development: 0-999)")
    parser.add_argument("--repeats", type=int, default=5, help="replays per seed (the least is reported)")
    args = parser.parse_args()
    if args.repeats < 1:
        print("bomi: error: --repeats: must be at least 1", file=sys.stderr)
        return 2
    rows = []
    for seed in tqdm(args.seeds, desc="seeds", unit="seed", file=sys.stderr):
        fresh, used, calls = recorded_episode(seed)
        per_tick = []
        for _ in range(args.repeats):
            seconds, replayed = replay(fresh, calls)
            if replayed._rows != used._rows:
                print(f"bomi: error: seed {seed}: the replay decided otherwise than the episode", file=sys.stderr)
                return 1
            per_tick.append(seconds / len(calls) * 1e6)
        rows.append({"seed": seed, "ticks": len(calls), "us_per_tick_min": min(per_tick),
                     "us_per_tick_median": statistics.median(per_tick), "repeats": args.repeats})
    lines = ["# BoMI channel per control tick, replayed (`python benchmarks/channel_replay.py "
             f"--seeds {' '.join(map(str, args.seeds))} --repeats {args.repeats}`)", "",
             "| seed | ticks | CPU us/tick (least) | CPU us/tick (median) |", "|---|---|---|---|"]
    lines += [f"| {r['seed']} | {r['ticks']} | {r['us_per_tick_min']:.1f} | {r['us_per_tick_median']:.1f} |"
              for r in rows]
    text = "\n".join(lines) + "\n"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "channel_replay.md").write_text(text, encoding="utf-8")
    (RESULTS / "channel_replay.json").write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
