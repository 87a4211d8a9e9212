"""`bomi run-task`, `bomi benchmark`, `bomi demo`: stacking episodes from the command line
(the work: tasks/experiments/)."""
from __future__ import annotations

import argparse
from pathlib import Path

from bomi.errors import BomiError
from bomi.files import atomic_output
from tasks.cli import add_command
from tasks.cli.engine import add_engine_arguments, engine_from_args
from tasks.cli.options import add_force, check_outputs, episode_seconds, positive_int, seed_count
from tasks.cli.options import seed as seed_option
from tasks.experiments.demo import DEMO_VIDEO_SPEEDUP, run_demo
from tasks.experiments.jobs import DEFAULT_VOTE, EpisodeJob, benchmark_jobs, job_assist, run_job, run_many, with_recovery
from tasks.experiments.summary import aggregate, benchmark_payload, comparison, write_json
from tasks.experiments.tables import terminal_comparison, terminal_mechanisms, terminal_table
from tasks.operators.assist import ASSIST_HELP, assist_option
from tasks.operators.params import DEFAULT_OPERATOR_FILE, load_operator, parse_recovery_actions
from tasks.stacking.vocabulary import NO_RECOVERY, RecoveryAction
from tasks.operators.stick import arm_profile
from tasks.participants.participant import load_participant
from tasks.stacking.episode import OPERATORS
from tasks.stacking.channels import participant_controls
from tasks.stacking.summary import summarize
from tasks.stacking.timeline import timeline_figure

RECOVERY_HELP = (f"what the scripted user does after a while without progress (docs/task.md, Recovery): "
                 f"{NO_RECOVERY}, or a comma list of {', '.join(a.value for a in RecoveryAction)} "
                 f"(default: the operator file's [recovery] actions, shipped: {NO_RECOVERY})")


def recovery_option(text: str) -> str:
    """``--recovery`` for argparse: the actions, checked, as given."""
    try:
        parse_recovery_actions(text, "")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text



# ------------------------------------------------------------------------------------ commands
def _names(text: str, allowed: tuple[str, ...] | None, what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise BomiError(f"--{what}: empty list")
    if allowed is not None:
        bad = [n for n in names if n not in allowed]
        if bad:
            raise BomiError(f"--{what}: unknown {', '.join(bad)} (expected {', '.join(allowed)})")
    return names


def cmd_run_task(args: argparse.Namespace) -> int:
    outputs = check_outputs({"--video": (args.video, (".mp4",)), "--plot": (args.plot, (".png",)),
                             "--json": (args.json, (".json",))}, force=args.force)
    load_operator(args.operator_file)  # a bad file fails before any simulation
    load_participant(args.participant)  # for the joystick too: a typo is not silently ignored
    job = with_recovery(EpisodeJob(args.operator, args.participant, args.seed, args.time_limit,
                                   str(args.operator_file), args.vote, assist=args.assist), args.recovery)
    job_assist(job, arm_profile(load_participant(job.participant).profile))  # a bad profile fails before simulating
    participant_controls(job.participant)  # so does one without the task's controls (a twin's derived profile)
    if outputs["--video"]:
        with atomic_output(outputs["--video"], overwrite=args.force) as video:
            log = run_job(job, video=video, progress=True)
    else:
        log = run_job(job, progress=True)
    summary = summarize(log)
    print(terminal_table(aggregate([summary])))
    if outputs["--plot"]:
        with atomic_output(outputs["--plot"], overwrite=args.force) as plot:
            timeline_figure([log], plot)
    if outputs["--json"]:
        write_json(outputs["--json"], summary, overwrite=args.force)
    _print_written({outputs["--video"]: "the episode filmed (4x speed)", outputs["--plot"]: "timeline figure",
                    outputs["--json"]: "metrics of the episode"})
    return 0 if log.success else 1


def _print_written(files: dict[Path | None, str]) -> None:
    """The files a command wrote, each with what it holds (None: not asked for)."""
    written = {path: what for path, what in files.items() if path is not None}
    if written:
        width = max(len(str(path)) for path in written)
        print("wrote:\n" + "\n".join(f"  {str(path):<{width}}  {what}" for path, what in written.items()))


def cmd_benchmark(args: argparse.Namespace) -> int:
    outputs = check_outputs({"--json": (args.json, (".json",))}, force=args.force)
    load_operator(args.operator_file)
    participants = _names(args.participants, None, "participants")
    for name in participants:  # every name checked here, not inside a worker after others finished
        load_participant(name)
    jobs = benchmark_jobs(participants, _names(args.operators, OPERATORS, "operators"),
                          args.seeds, args.time_limit, str(args.operator_file), args.vote, args.first_seed,
                          args.assist)
    jobs = [with_recovery(job, recovery) for recovery in args.recovery or [None] for job in jobs]
    for job in {(j.participant, j.operator): j for j in jobs}.values():  # a bad profile fails before simulating
        job_assist(job, arm_profile(load_participant(job.participant).profile))
        participant_controls(job.participant)
    records = run_many(jobs, engine_from_args(args))
    rows = aggregate(records)
    print(terminal_table(rows))
    if comparison(rows):
        print("\n" + terminal_comparison(rows))
    print("\n" + terminal_mechanisms(records))
    if not outputs["--json"]:
        print("(every column, the episodes and the comparison in full: --json FILE)")
    if outputs["--json"]:
        write_json(outputs["--json"], benchmark_payload(records), overwrite=args.force)
    return 0


DEMO_FILES = ("timeline.png", "bomi_episode.mp4", "demo.json")


DEMO_OUT = Path("demo_out")  # demo's own directory when --out names none: its files are replaced on each run


def cmd_demo(args: argparse.Namespace) -> int:
    out = Path(args.out or DEMO_OUT)
    replace = args.force or args.out is None
    if out.exists() and not out.is_dir():
        raise BomiError(f"{out}: --out must be a directory, this is a file")
    if not out.parent.is_dir():
        raise BomiError(f"{out}: directory {out.parent} does not exist")
    out.mkdir(exist_ok=True)
    figure, video, record = check_outputs({name: (out / name, ()) for name in DEMO_FILES}, force=args.force,
                                          defaults=DEMO_FILES if args.out is None else ()).values()
    participant_controls(args.participant)  # a bad participant or profile fails before simulating
    summaries = run_demo(args.participant, args.seed, args.time_limit, args.assist, figure, video, record, replace)
    print(terminal_table(aggregate(summaries)))
    print(f"\nOne seed ({args.seed}), one episode per operator: a single draw of the cube placement and of the "
          f"virtual participant's body and noise. The README's figures are means over 20 seeds "
          f"(`bomi benchmark`).")
    _print_written({figure: "timeline: the hand relative to the target, the BoMI's decisions, amplitude and nu",
                    video: f"the BoMI episode filmed at {DEMO_VIDEO_SPEEDUP:g}x speed",
                    record: "metrics of both episodes (JSON)"})
    return 0


def register(subparsers) -> None:
    run = add_command(subparsers, "run-task")
    run.add_argument("--operator", choices=OPERATORS, required=True,
                     help="who drives the arm: the scripted user on a joystick, or a virtual participant "
                          "through the BoMI (calibrated first)")
    run.add_argument("--participant", default="P1",
                     help="virtual participant: P1, P4, P5 or a TOML file (default %(default)s)")
    run.add_argument("--seed", type=seed_option, default=0,
                     help="task seed: cube placement, the participant's body and noise (default %(default)s)")
    _episode_options(run)
    run.add_argument("--recovery", type=recovery_option, help=RECOVERY_HELP)
    run.add_argument("--video", type=Path, help="also film the episode to this MP4 (4x speed)")
    run.add_argument("--plot", type=Path, help="also write the timeline figure (PNG) here")
    run.add_argument("--json", type=Path, help="also write the episode's metrics (JSON) here")
    add_force(run)
    run.set_defaults(func=cmd_run_task)

    bench = add_command(subparsers, "benchmark")
    bench.add_argument("--participants", default="P1",
                       help="comma-separated virtual participants: P1, P4, P5 or TOML files (a twin from "
                            "`bomi twin`), e.g. P1,P4,P5 (default %(default)s)")
    bench.add_argument("--operators", default="joystick,bomi",
                       help=f"comma-separated operators out of {','.join(OPERATORS)} (default %(default)s)")
    bench.add_argument("--seeds", type=seed_count, default=20, help="how many seeds per participant and operator "
                                                             "(default %(default)s)")
    bench.add_argument("--first-seed", type=seed_option, default=0, help="the first seed (default %(default)s)")
    add_engine_arguments(bench)
    _episode_options(bench)
    bench.add_argument("--recovery", type=recovery_option, action="append",
                       help=RECOVERY_HELP + "; given more than once, the episodes are run under each, "
                            "e.g. --recovery none --recovery rezero,backoff,pause")
    bench.add_argument("--json", type=Path, help="also write the table and every episode's metrics (JSON) here")
    add_force(bench)
    bench.set_defaults(func=cmd_benchmark)

    demo = add_command(subparsers, "demo")
    demo.add_argument("--seed", type=seed_option, default=0, help="task seed of both episodes (default %(default)s)")
    demo.add_argument("--participant", default="P1",
                      help="virtual participant: P1, P4, P5 or a TOML file (a twin from `bomi twin`; "
                           "default %(default)s)")
    demo.add_argument("--time-limit", type=episode_seconds, default=600.0,
                      help="seconds of simulated time per episode (default %(default)s)")
    demo.add_argument("--out", type=Path,
                      help=f"directory for timeline.png, bomi_episode.mp4 and demo.json (default {DEMO_OUT}/, whose "
                           f"files are replaced on each run; in a directory you name, only with --force)")
    demo.add_argument("--assist", type=assist_option, help=ASSIST_HELP)
    add_force(demo)
    demo.set_defaults(func=cmd_demo)


def _episode_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--time-limit", type=episode_seconds, default=600.0,
                        help="seconds of simulated time before an episode fails (default %(default)s)")
    parser.add_argument("--operator-file", type=Path, default=DEFAULT_OPERATOR_FILE,
                        help="the scripted user's settings (TOML; default: the shipped tasks/operators/operator.toml)")
    parser.add_argument("--assist", type=assist_option, help=ASSIST_HELP)
    parser.add_argument("--vote", type=positive_int, default=DEFAULT_VOTE,
                        help="BoMI: majority vote over this many decisions (default %(default)s)")
