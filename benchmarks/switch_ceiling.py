"""The ceiling of any mode-switching assistance for the BoMI users: a counterfactual bound, not a
system anyone could build.

    python benchmarks/switch_ceiling.py [--participants P4,P5] [--seeds 10] [--first-seed 800] [--jobs 1]
        [--none BENCH.json...] [--name switch_ceiling]

On the same seeds, each BoMI episode without assistance ("none") and with free switches ("free"):
every mode switch the scripted user decides on costs nothing: the arm goes straight to the mode
the user's press was meant to reach (``Goal.mode``, the planner's own intent, which no real
assistance can see), the button posture is never performed (the participant holds the neutral
posture instead) and no press is counted.  The user still decides to switch (their reaction to
what they see, letting go of the move before) and then moves as usual.  What is left of the
completion time is what no mode-switching assistance can remove; the gap to "none" is the most
any can save.  Writes benchmarks/results/NAME.md and .json: per participant successes, completion
time, its change against "none" on the seeds both finished (ratio of the means, 95 % bootstrap
interval over seeds; ``assist_benchmark.change``), the user's mode switches (free ones included).
``--none``: the episodes without assistance are taken from ``bomi benchmark --assist none --json``
files of the same seeds (the same episodes) instead of being run again.
Seeds 0-999 are for development.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
from tqdm import tqdm

from sim.env import ArmSim
from sim.joystick import JoystickState, Mode
from tasks.cli.engine import ProcessPool
from tasks.cli.task import DEFAULT_VOTE, EpisodeJob, episode_record
from tasks.stacking.episode import OperatorChannel, calibrated_channel, run_episode, summarize
from tasks.participants.participant import load_participant
from tasks.operators.planner import DEFAULT_OPERATOR_FILE, REST, StickIntent, load_operator
from tasks.stacking.task import TaskConfig
from tasks.operators.stick import arm_profile

sys.path.insert(0, str(Path(__file__).resolve().parent))
from assist_benchmark import RESULTS, TIME_LIMIT, change, summary  # noqa: E402

NONE, FREE = "none", "free"


class FreeSwitches:
    """An ``OperatorChannel`` around another in which the user's mode presses cost nothing: a press
    puts ``arm`` straight in the mode it is meant to reach, and the channel underneath sees the
    person at rest instead of the button's posture.  ``free_switches`` counts them."""

    def __init__(self, channel: OperatorChannel, arm: ArmSim):
        self.channel, self.arm = channel, arm
        self.combine_axes, self.controls, self.body_reaction = channel.combine_axes, channel.controls, \
            channel.body_reaction
        self.free_switches = 0

    def command(self, intent: StickIntent, t: float, t_end: float, seen: np.ndarray | None = None,
                mode: Mode = Mode.TRANSLATION) -> JoystickState:
        if intent.button is not None and intent.goal.mode is not None:
            if self.arm.mode is not intent.goal.mode:
                self.arm.switch_mode(intent.goal.mode)
                self.free_switches += 1
            intent = replace(REST, goal=intent.goal)
        return self.channel.command(intent, t, t_end, seen, mode)

    def log_fields(self) -> dict:
        return self.channel.log_fields()

    def caption(self) -> str | None:
        return self.channel.caption()


class CeilingJob(NamedTuple):
    participant: str
    seed: int
    free: bool
    time_limit: float = TIME_LIMIT


def ceiling_record(job: CeilingJob) -> dict:
    """One BoMI episode without assistance, with or without free switches: its metrics (without:
    ``bomi benchmark``'s own episode)."""
    if not job.free:
        return {**episode_record(EpisodeJob("bomi", job.participant, job.seed, job.time_limit, assist=frozenset())),
                "free_switches": 0}
    params = load_participant(job.participant)
    profile = arm_profile(params.profile)
    channel = calibrated_channel(params, job.seed, replace(profile.post, vote_length=DEFAULT_VOTE), profile)
    arm = ArmSim(layout=channel.controls.layout)
    wrapped = FreeSwitches(channel, arm)
    log = run_episode(wrapped, operator="bomi", participant=job.participant, seed=job.seed,
                      operator_file=load_operator(DEFAULT_OPERATOR_FILE), sim=arm,
                      task_config=TaskConfig(time_limit=job.time_limit))
    return {**summarize(log), "assist": FREE, "free_switches": wrapped.free_switches}


def rows(records: list[dict], participants: list[str]) -> list[dict]:
    rng = np.random.default_rng(0)
    out = []
    for p in participants:
        base = [r for r in records if r["participant"] == p and r["assist"] == NONE]
        free = [r for r in records if r["participant"] == p and r["assist"] == FREE]
        out.append({"participant": p, "setting": NONE, **summary(base)})
        out.append({"participant": p, "setting": FREE, **summary(free), **change(base, free, rng),
                    "free_switches": float(np.mean([r["free_switches"] for r in free]))})
    return out


def markdown(table: list[dict]) -> str:
    lines = ["| participant (BoMI) | switches | successes | completion time (s) | time vs none (95 % CI) "
             "| user mode switches (free ones) |", "|---|---|---|---|---|---|"]
    for r in table:
        vs = "-" if r.get("ratio") is None else (f"{100 * (r['ratio'] - 1):+.1f} % ({100 * (r['ratio_low'] - 1):+.1f} "
                                                  f".. {100 * (r['ratio_high'] - 1):+.1f}), {r['paired_seeds']} seeds")
        mean = "-" if r["completion_time_mean"] is None else f"{r['completion_time_mean']:.1f}"
        free = f" ({r['free_switches']:.1f})" if "free_switches" in r else ""
        lines.append(f"| {r['participant']} | {r['setting']} | {r['successes']}/{r['episodes']} | {mean} | {vs} "
                     f"| {r['mode_switches']:.1f}{free} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", default="P4,P5")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=800)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--none", nargs="+", action="extend", type=Path, metavar="BENCH.json",
                        help="take the episodes without assistance from these `bomi benchmark --assist none --json` files")
    parser.add_argument("--name", default="switch_ceiling")
    args = parser.parse_args()
    if not (0 <= args.first_seed and args.first_seed + args.seeds <= 1000):
        parser.error("--first-seed/--seeds: a bound is measured on development seeds (0-999) only")
    participants = args.participants.split(",")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    given = [r for path in args.none or [] for r in json.loads(path.read_text(encoding="utf-8"))["episodes"]
             if r["operator"] == "bomi" and r["assist"] == NONE and r["participant"] in participants and r["seed"] in seeds]
    have = {(r["participant"], r["seed"]) for r in given}
    jobs = [CeilingJob(p, s, free) for p in participants for free in (False, True) for s in seeds
            if free or (p, s) not in have]
    done = dict(tqdm(ProcessPool(args.jobs).run(ceiling_record, jobs), total=len(jobs), desc="episodes", unit="ep"))
    records = given + [done[i] for i in range(len(jobs))]
    table = rows(records, participants)
    text = "\n".join([
        f"# Ceiling of mode-switching assistance (counterfactual): development seeds {args.first_seed}.."
        f"{args.first_seed + args.seeds - 1}", "",
        f"Command: `python benchmarks/switch_ceiling.py --participants {args.participants} --seeds {args.seeds} "
        f"--first-seed {args.first_seed} --jobs {args.jobs}"
        f"{' --none ' + ' '.join(p.name for p in args.none) if args.none else ''}`. \"free\": every mode switch the scripted user "
        "decides on is made at no cost (no button posture, no press): a bound no assistance can reach, "
        "not a system.", "",
        f"Machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}. "
        f"Time limit {TIME_LIMIT:.0f} s; time change: mean time free / none on the seeds both finished, 95 % "
        "bootstrap interval over those seeds.", "", markdown(table), ""])
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.name}.md").write_text(text, encoding="utf-8")
    (RESULTS / f"{args.name}.json").write_text(json.dumps({"rows": table, "episodes": records}, indent=2) + "\n",
                                               encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
