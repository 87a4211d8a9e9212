"""The `bomi` command line: the one place that wires bomi/, sim/ and tasks/ together.

It lives on the composing side (tasks/) so that bomi/, the signal chain, imports neither sim/ nor
tasks/ and installs and runs without MuJoCo.

Each command module exposes ``register(subparsers)`` which adds its sub-commands (through
``add_command``, which gives each its one-line summary from ``COMMANDS``) and sets ``func`` on
them; ``func(args)`` returns the process exit code. Only the module that owns the command being
run is imported, so `bomi train` does not pay for loading MuJoCo, and `bomi --help` (which lists
the summaries) imports none of them.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
from collections.abc import Collection
from dataclasses import dataclass
from importlib.metadata import version

from bomi.errors import BomiError
from sim.errors import SimError


@dataclass(frozen=True)
class Command:
    module: str   # the module whose register() adds it
    summary: str  # its line in `bomi --help`


COMMANDS: dict[str, Command] = {
    "train": Command("tasks.cli.chain", "train an LDA model on labelled recordings"),
    "evaluate": Command("tasks.cli.chain", "train on one recording, test on others"),
    "reproduce": Command("tasks.cli.chain", "the paper's reliability-over-days table beside ours (P1 data)"),
    "fuse": Command("tasks.cli.chain", "recompute Pitch/Roll/Yaw columns from the raw ACC/GYRO/MAG columns"),
    "emulate": Command("tasks.cli.stream", "play a recording or a virtual participant as base-station frames "
                                           "onto a pty, socket or port"),
    "capture": Command("tasks.cli.stream", "record what a base-station stream carries, without prompts"),
    "record": Command("tasks.cli.stream", "guided calibration: prompt each motion, record it labelled, "
                                          "optionally train"),
    "sim-check": Command("tasks.cli.sim", "drive the simulated arm through every joystick function"),
    "render": Command("tasks.cli.sim", "render a short scripted motion of the arm to MP4"),
    "run-task": Command("tasks.cli.task", "one stacking episode with the joystick or the BoMI operator"),
    "benchmark": Command("tasks.cli.task", "many episodes in parallel; table beside the paper's figures"),
    "demo": Command("tasks.cli.task", "one joystick and one BoMI episode (P1 or --participant): table, timeline "
                                      "figure, MP4"),
    "sweep": Command("tasks.cli.sweep", "episodes over a grid of participants x settings x seeds, resumable"),
    "live": Command("tasks.cli.live", "drive the simulated arm from a live base-station stream"),
    "twin": Command("tasks.cli.twin", "fit a virtual participant (a twin) to a person's calibration recording(s)"),
    "synth": Command("tasks.cli.twin", "a virtual participant performs its source recording's protocol: a new "
                                       "recording"),
    "trial": Command("tasks.cli.trial", "the paper's session: N trials per controller, scored, logged, reported"),
    "replay": Command("tasks.cli.trial", "re-run a logged trial of `bomi trial` (or re-score it with another model)"),
}
COMMAND_MODULES: tuple[str, ...] = tuple(dict.fromkeys(command.module for command in COMMANDS.values()))


def add_command(subparsers: argparse._SubParsersAction, name: str, **kwargs) -> argparse.ArgumentParser:
    """The parser of sub-command ``name``, listed with its summary from COMMANDS."""
    return subparsers.add_parser(name, help=COMMANDS[name].summary, **kwargs)


def _modules_for(argv: list[str]) -> list[str]:
    """The module of the command named by the first positional argument; none without one (help,
    --version and an unknown command need only the summaries)."""
    name = next((arg for arg in argv if not arg.startswith("-")), None)
    return [COMMANDS[name].module] if name in COMMANDS else []


class OneLineParser(argparse.ArgumentParser):
    """argparse with its usage errors as the one line every bad input gets: ``bomi: error: ...``, exit 2."""

    def error(self, message: str) -> None:
        command = self.prog.removeprefix("bomi").strip()
        hint = f" (see bomi {command} --help)" if command else " (see bomi --help)"
        self.exit(2, f"bomi: error: {' '.join(message.split())}{hint}\n")


def build_parser(modules: Collection[str] = COMMAND_MODULES) -> argparse.ArgumentParser:
    """The parser with every option of the commands of ``modules``; the other commands are listed only."""
    parser = OneLineParser(prog="bomi", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"%(prog)s {version('bomi-jaco')}")
    parser.add_argument("--debug", action="store_true",
                        help="show the Python traceback of an internal error (a bug, not bad input)")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMAND_MODULES:
        if module in modules:
            importlib.import_module(module).register(subparsers)
        else:
            for name in (name for name, command in COMMANDS.items() if command.module == module):
                add_command(subparsers, name)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        code = _run(sys.argv[1:] if argv is None else argv)
        sys.stdout.flush()  # here, not at exit, so that a closed pipe is handled below
        return code
    except BrokenPipeError:  # the reader went away (`bomi evaluate ... | head`): stop quietly, as `cat` does
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a tool stopped by a closed pipe


def _run(argv: list[str]) -> int:
    try:
        args = build_parser(_modules_for(argv)).parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error already reported in one line
        return exc.code if isinstance(exc.code, int) else 2
    try:
        return int(args.func(args) or 0)
    except (BomiError, SimError) as exc:  # bad input: files, options, ports, streams
        print(f"bomi: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bomi: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        raise
    except Exception as exc:  # a bug: one line, the traceback only when asked for
        if args.debug:
            traceback.print_exc()
        print(f"bomi: internal error: {type(exc).__name__}: {' '.join(str(exc).split())} "
              f"(a bug; rerun with --debug for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
