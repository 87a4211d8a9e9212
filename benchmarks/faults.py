"""Faults, made and run through the command line: damaged files and bad option values through every
command (``bad-input``), the human-in-the-loop session's faults (``session``: kills, signals, a full
disk, damaged or mixed session files, a stale calibration) and the live loop's safety bars end to
end (``live``: neutral hold, a lost stream, bad sensors, corrupted bytes, a flood, filming). The
README's rows "damaged files and option values", "session faults" and "`bomi live`" come from here.

    python benchmarks/faults.py bad-input [--per-kind 40] [--seed 0]
    python benchmarks/faults.py session [--timeout 300] [--only NAME,NAME]
    python benchmarks/faults.py live --seeds 11000 [--participants P1 P4] [--bars ...]

Every command runs as ``python -m tasks.cli`` in a process of its own (cwd a temporary directory,
never the repository): nothing of the command line is imported here. The frame parser's fuzzing is
in tests/test_frames.py; the live loop's breaks and another sitting in tests/test_live_safety.py and
tests/test_live_breaks.py. What each group does and how an outcome is classified: the comment that opens
its module in tasks/experiments/faults/.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from tasks.experiments.faults.bad_input import run_bad_input
from tasks.experiments.faults.live import BARS, run_live
from tasks.experiments.faults.sessions import run_sessions

RESULTS = Path(__file__).resolve().parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    groups = parser.add_subparsers(dest="group", required=True)
    bad = groups.add_parser("bad-input", help="damaged files and bad option values through every command")
    bad.add_argument("--per-kind", type=int, default=40, help="damaged files per kind of file (default 40)")
    bad.add_argument("--seed", type=int, default=0)
    bad.add_argument("--timeout", type=float, default=180.0)
    bad.set_defaults(run=lambda a: run_bad_input(a.per_kind, a.seed, a.timeout, RESULTS))
    session = groups.add_parser("session", help="the session fault corpus")
    session.add_argument("--timeout", type=float, default=300.0, help="seconds a command may run (default 300)")
    session.add_argument("--only", help="comma-separated case names (default: every case)")
    session.set_defaults(run=lambda a: run_sessions(a.timeout, a.only, RESULTS))
    live = groups.add_parser("live", help="the live loop's safety bars, end to end")
    live.add_argument("--seeds", type=int, nargs="+", required=True)
    live.add_argument("--participants", nargs="+", default=["P1", "P4"])
    live.add_argument("--bars", nargs="+", choices=sorted(BARS), default=list(BARS))
    live.add_argument("--out", type=Path, default=RESULTS / "live_safety.md")
    live.set_defaults(run=lambda a: run_live(a.seeds, a.participants, a.bars, a.out))
    args = parser.parse_args()
    args.run(args)


if __name__ == "__main__":
    main()
