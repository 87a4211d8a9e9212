"""The BoMI user's body in the task, checked (issue 53.2): per cell (participant, controller) on a seed
range, with the human operator model on: successes, mean completion time, the share of decisions that
are relevant (not ``metrics.irrelevant``), the longest irrelevant run, and the irrelevant decisions by
context (``tasks.stacking.budget``).  One episode at a time (the machine is shared).

    python benchmarks/body_check.py --seeds 0-9 --cells P1:joystick P1:bomi P4:bomi P5:bomi
    python benchmarks/body_check.py --seeds 0-9 --cells P1:bomi P4:bomi P5:bomi --recovery rezero,backoff,pause
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import Counter

import numpy as np

from tasks.cli.task import RECOVERY_KEY, EpisodeJob, run_job
from tasks.stacking import budget
from tasks.stacking.summary import summarize

HUMAN_ON = (("operator.human.model", "human"),)


def seed_range(text: str) -> range:
    first, _, last = text.partition("-")
    return range(int(first), int(last or first) + 1)


def cell_row(participant: str, operator: str, seeds: range, recovery: str | None = None) -> dict:
    records, contexts, decisions = [], Counter(), 0
    overrides = HUMAN_ON + (((RECOVERY_KEY, recovery),) if recovery else ())
    for seed in seeds:
        log = run_job(EpisodeJob(operator, participant, seed, overrides=overrides))
        record = summarize(log)
        records.append(record)
        if operator == "bomi":
            contexts.update({c.value: n for c, n in budget.irrelevant_by_context(log).items()})
            decisions += len(log.decisions.t)
        print(json.dumps({k: record.get(k) for k in ("participant", "operator", "seed", "success", "completion_time",
                                                       "irrelevant_decisions", "irrelevant_longest_run_ms", "stuck")}, default=str),
              file=sys.stderr, flush=True)
    times = [r["completion_time"] for r in records if r["success"]]
    row = {"cell": f"{participant} {operator}", "recovery": recovery or "none", "seeds": f"{seeds.start}-{seeds.stop - 1}",
           "success": f"{len(times)}/{len(records)}", "mean_time_s": round(float(np.mean(times)), 1) if times else None}
    if operator == "bomi":
        wild = sum(r["irrelevant_decisions"] for r in records)
        row.update({"relevant_pct": round(100.0 * (1.0 - wild / decisions), 2),
                    "longest_irrelevant_ms_max": max(r["irrelevant_longest_run_ms"] for r in records),
                    "longest_irrelevant_ms_mean": round(float(np.mean([r["irrelevant_longest_run_ms"] for r in records])), 1),
                    "irrelevant_by_context": dict(contexts)})
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", required=True, help="first-last, e.g. 0-9")
    parser.add_argument("--cells", nargs="+", default=["P1:joystick", "P1:bomi", "P4:bomi", "P5:bomi"])
    parser.add_argument("--recovery", help='recovery actions, e.g. "rezero,backoff,pause" (default: none)')
    args = parser.parse_args()
    for cell in args.cells:
        participant, operator = cell.split(":")
        print(json.dumps(cell_row(participant, operator, seed_range(args.seeds), args.recovery)), flush=True)


if __name__ == "__main__":
    main()
