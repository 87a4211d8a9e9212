"""`bomi design`: a person's layout chosen by simulation with their twin (tasks/operators/design.py)."""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from bomi.profiles import save_profile
from tasks.cli import add_command
from tasks.cli.engine import add_engine_arguments, engine_from_args
from tasks.cli.options import add_force, check_outputs, episode_seconds, seed, seed_count
from tasks.experiments.design import candidate_jobs, design_payload
from tasks.experiments.jobs import run_many
from tasks.experiments.summary import write_json
from tasks.operators.design import Score, candidates, ranked, recommend
from tasks.operators.stick import arm_profile
from tasks.participants.participant import load_participant


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(subparsers, "design")
    p.add_argument("twin", metavar="TWIN", help="the person's twin (bomi twin's TOML file)")
    p.add_argument("--seeds", type=seed_count, default=5, help="task seeds per candidate (default %(default)s: the "
                                                                 "fewest on which a candidate can beat the default)")
    p.add_argument("--first-seed", type=seed, default=0,
                   help="the first task seed (default %(default)s; seeds 0-999 are for development)")
    p.add_argument("--time-limit", type=episode_seconds, default=600.0, help="seconds of simulated time before an "
                                                                             "episode fails (default %(default)s)")
    p.add_argument("--out", required=True, type=Path, help="the recommended profile (TOML) to write")
    p.add_argument("--json", type=Path, help="every candidate's episodes and scores as JSON")
    add_engine_arguments(p)
    add_force(p)
    p.set_defaults(func=design_command)


def design_command(args: argparse.Namespace) -> int:
    outputs = check_outputs({"--out": (args.out, (".toml",)), "--json": (args.json, (".json",))},
                            inputs=[args.twin], force=args.force)
    engine = engine_from_args(args)
    params = load_participant(args.twin)
    base = arm_profile(params.profile)
    pressing = {cls.function: cls.label for cls in base.classes}
    options = candidates({label: motion.posture_deg for label, motion in params.classes.items()},
                         [pressing[b] for b in ("B1", "B2") if b in pressing])
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    print(f"{params.name}: {len(params.classes)} motions; {len(options)} candidate(s) x {len(seeds)} seed(s) "
          f"({seeds.start}-{seeds.stop - 1}), the derived default first:")
    with tempfile.TemporaryDirectory(prefix="bomi-design-") as directory:
        jobs = []
        for k, (option, episodes) in enumerate(candidate_jobs(args.twin, base, options, seeds, args.time_limit,
                                                              Path(directory)), start=1):
            print(f"  {k}. {option.name}: {', '.join(f'c{label} {f}' for label, f in option.functions)}")
            jobs += episodes
        records = run_many(jobs, engine)
    scores = [Score.of(option, records[k * len(seeds):(k + 1) * len(seeds)]) for k, option in enumerate(options)]
    order = ranked(scores)
    print("ranked by successes [Wilson 95 % interval], then mean completion time of the successes [Student-t 95 %]:")
    for place, score in enumerate(order, start=1):
        print(f"  {place}. {score.candidate.name}: {score.text()}")
    chosen, reason = recommend(scores)
    best = chosen.candidate
    save_profile(outputs["--out"], best.profile(base), overwrite=args.force)
    print(f"recommended: {best.name}: {reason}")
    print(f"wrote {outputs['--out']} (use it: bomi twin RECORDING --profile {outputs['--out']} "
          f"--out TWIN.toml, bomi train RECORDING --profile {outputs['--out']} ...)")
    if outputs["--json"]:
        write_json(outputs["--json"], design_payload(args.twin, seeds, best, reason, scores, records),
                   overwrite=args.force)
    return 0
