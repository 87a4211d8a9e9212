"""Speed never changes results silently: the records of a fixed set of development episodes,
written once and compared field for field after every speed-up.

    python benchmarks/records_identity.py --write before.json     # at the commit before the change
    python benchmarks/records_identity.py --compare before.json   # after it: every field equal?

The episodes: virtual P1 and P4, joystick and BoMI (calibration, LDA training and task), task
seeds 0-3 (development seeds; a fixed set, chosen before any speed-up).  A record is what ``bomi
benchmark``/``bomi sweep`` store for an episode (``tasks.cli.task.episode_record``) without its
four timing fields, plus a SHA-256 of every array the episode logged (hand and cube trajectories,
modes, the BoMI's decisions with their gamma and nu): equal digests mean bit-identical
trajectories, not just equal summaries.  ``--compare`` lists every differing field and exits 1
if any differ.  Writes benchmarks/results/records_identity.md.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tasks.cli.task import EpisodeJob, run_job
from tasks.episode import summarize

RESULTS = Path(__file__).resolve().parent / "results"
TIMING_FIELDS = ("wall_time", "cpu_time", "realtime_factor", "realtime_factor_cpu")
SEEDS = range(4)
JOBS = [EpisodeJob(operator, participant, seed) for participant in ("P1", "P4") for operator in ("joystick", "bomi")
        for seed in SEEDS]


def log_digest(log) -> str:
    """SHA-256 over every array and sequence the episode logged, in a fixed order."""
    digest = hashlib.sha256()
    parts = [log.t, log.hand_pos, log.intended_dir, log.cube_pos, log.touching, log.target_pos, log.pushing,
             np.array(log.mode), np.array(log.goals), np.array(log.stages)]
    if log.decisions is not None:
        d = log.decisions
        parts += [d.t, d.intended, d.decided, d.gamma, d.nu]
    for part in parts:
        array = np.ascontiguousarray(part)
        digest.update(str(array.dtype).encode() + str(array.shape).encode() + array.tobytes())
    return digest.hexdigest()


def record(job: EpisodeJob) -> dict:
    log = run_job(job)
    out = {k: v for k, v in summarize(log).items() if k not in TIMING_FIELDS}
    return json.loads(json.dumps(out | {"log_sha256": log_digest(log)}))  # as stored: JSON round trip


def differences(before: dict, after: dict) -> list[str]:
    lines = []
    for key in sorted(before.keys() | after.keys()):
        a, b = before.get(key), after.get(key)
        for field in sorted((a or {}).keys() | (b or {}).keys()):
            if (a or {}).get(field) != (b or {}).get(field):
                lines.append(f"{key}: {field}: {(a or {}).get(field)!r} -> {(b or {}).get(field)!r}")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--write", type=Path, help="write the records to this JSON file")
    what.add_argument("--compare", type=Path, help="compare the records with this JSON file")
    args = parser.parse_args()
    if args.compare is not None and not args.compare.is_file():
        print(f"bomi: error: --compare: {args.compare}: no such file", file=sys.stderr)
        return 2
    if args.write is not None and args.write.exists():
        print(f"bomi: error: --write: {args.write} exists (not overwritten)", file=sys.stderr)
        return 2
    records = {str(job): record(job) for job in tqdm(JOBS, desc="episodes", unit="episode", file=sys.stderr)}
    if args.write is not None:
        args.write.write_text(json.dumps(records, indent=1) + "\n", encoding="utf-8")
        return 0
    before = json.loads(args.compare.read_text(encoding="utf-8"))
    diff = differences(before, records)
    text = "\n".join([f"# Records before and after (`python benchmarks/records_identity.py --compare {args.compare}`)",
                      "", f"{len(records)} episodes: P1 and P4, joystick and BoMI, seeds {SEEDS.start}-{SEEDS.stop - 1}; "
                      "every field of each record but the four timing ones, and a SHA-256 of every logged array.", "",
                      f"Identical, field for field: {'yes' if not diff else 'NO'}.", *(f"- {d}" for d in diff)]) + "\n"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "records_identity.md").write_text(text, encoding="utf-8")
    print(text)
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
