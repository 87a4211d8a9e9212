"""`bomi sweep GRID.toml --out DIR`: every combination of the settings a grid file lists, over seeds.

The grid file (TOML; benchmarks/grids/p4_vote_rejection.toml is a commented example):

    participants = ["P4"]                    # shipped names (P1, P4, P5) or participant files (a twin
                                             # from `bomi twin`), a relative file relative to the grid file
    operators = ["bomi"]                     # joystick and/or bomi
    seeds = {first = 0, count = 20}          # or a list: seeds = [0, 1, 2]   (task seeds 0-999: development)

    [vary]                                   # each a list of values; every combination is a cell
    vote_length = [1, 5, 9]                  # the BoMI's majority vote, in decisions (the commands' --vote)
    time_limit = [600.0]                     # s of simulated time per episode
    profile.post_processing.rejection_threshold = [0.9, 0.99]   # any key of the participant's profile,
    participant.reaction_s = [0.5]           # of the participant file,
    operator.timing.reaction_time = [0.3]    # or of the scripted user's operator.toml

    [figure]                                 # optional
    metric = "completion_time_mean"          # a column of the summary rows
    setting = "vote_length"                  # one of [vary] (default: the first)

Each (participant, operator, combination) is a cell of len(seeds) episodes. The joystick reads no
profile, participant or vote setting: its cells drop them (and are not run again per BoMI setting).

Resuming and extending: every finished episode is appended at once to DIR/episodes.jsonl (one
JSON line: a key hashing its settings, the settings, the metrics). Run the same command again --
after Ctrl-C, a crash, or with more seeds or values added to the grid -- and only the episodes
whose key is not in the file run; DIR/summary.md and .json, DIR/completion_time.png and
DIR/<metric>_vs_<setting>.png are then regenerated from every record of the grid (they are the
sweep's own files, replaced without --force). The file's records are checked first: one edited
out of shape, or whose settings are not its key's, stops the sweep with one line naming its
record (its line number), before any episode runs. Ctrl-C (or SIGTERM, SIGHUP) keeps every finished
episode and stops the workers; a second sweep on the same DIR while one runs stops with one line.
A file in DIR that the sweep would write but that is a symbolic link or not a regular file is
refused, never written through.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from tasks.cli import add_command
from tasks.cli.engine import add_engine_arguments, engine_from_args
from tasks.experiments.engine import report
from tasks.experiments.sweep import RESULTS_FILE, load_grid, run_sweep
from tasks.experiments.tables import terminal_mechanisms


def cmd_sweep(args: argparse.Namespace) -> int:
    grid = load_grid(args.grid)
    engine = engine_from_args(args)
    result = run_sweep(grid, args.out, engine)
    if result.table is not None:
        print(result.table)
        print(terminal_mechanisms(result.records))
        print(f"wrote {args.out / 'summary.md'} (every column), {args.out / 'summary.json'} and figures in {args.out}")
    if result.interrupted:
        report(f"bomi: interrupted: {len(result.records)} of the grid's {result.total} episodes are saved in "
               f"{args.out / RESULTS_FILE} ({result.ran} run now); rerun the same command to run the rest")
        return 130
    return 0


def register(subparsers) -> None:
    sweep = add_command(subparsers, "sweep", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sweep.add_argument("grid", type=Path, help="the grid file (TOML; format above)")
    sweep.add_argument("--out", type=Path, required=True,
                       help="directory for episodes.jsonl, the summary and figures (made if missing; "
                            "an existing one is resumed or extended)")
    add_engine_arguments(sweep)
    sweep.set_defaults(func=cmd_sweep)
