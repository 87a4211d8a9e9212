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
import importlib.abc
import importlib.util
import os
import sys
import traceback
import types
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from bomi.errors import BomiError
from sim.errors import SimError


@dataclass(frozen=True)
class Command:
    module: str   # the module whose register() adds it
    summary: str  # its line in `bomi --help`
    about: str = ""  # more for `bomi NAME --help`, after the summary: what it reads, writes, and how to go on


COMMANDS: dict[str, Command] = {
    "train": Command("tasks.cli.chain", "train an LDA model on labelled recordings",
                     "Reads .mat or .csv recordings whose Etiquette column labels each sample with its class; "
                     "writes a model (.json or .npz, never a pickle) for `bomi evaluate` and `bomi live`. "
                     "Without --profile the nodes, features and classes are derived from the recording."),
    "evaluate": Command("tasks.cli.chain", "train on one recording, test on others",
                        "--train is a recording (trained here) or a model file; each --test recording is "
                        "classified window by window: accuracy and a confusion matrix per file, printed and "
                        "drawn (rows: the true class, normalised per row)."),
    "reproduce": Command("tasks.cli.chain", "the paper's reliability-over-days table beside ours (P1 data)"),
    "fuse": Command("tasks.cli.chain", "recompute Pitch/Roll/Yaw columns from the raw ACC/GYRO/MAG columns"),
    "split": Command("tasks.cli.chain", "write each pass of the protocol a recording holds as a recording of its own",
                     "Passes are found by the pauses (or restarts) of the Time clock, as every command that reads "
                     "a recording finds them (bomi/passes.py)."),
    "emulate": Command("tasks.cli.stream", "play a recording or a virtual participant as base-station frames "
                                           "onto a pty, socket or port"),
    "capture": Command("tasks.cli.stream", "record what a base-station stream carries, without prompts"),
    "record": Command("tasks.cli.stream", "guided calibration: prompt each motion, record it labelled, "
                                          "optionally train"),
    "sim-check": Command("tasks.cli.sim", "drive the simulated arm through every joystick function"),
    "render": Command("tasks.cli.sim", "render a short scripted motion of the arm to MP4"),
    "run-task": Command("tasks.cli.task", "one stacking episode with the joystick or the BoMI operator",
                        "The task of the paper: stack the cube at A onto the cube at B with the simulated JACO. "
                        "The joystick operator is a scripted user on a 3-axis stick; the BoMI operator is a "
                        "virtual participant calibrated first, whose body motions go through the whole chain."),
    "benchmark": Command("tasks.cli.task", "many episodes in parallel; table beside the paper's figures",
                         "Runs --seeds episodes per participant and operator (task seeds 0-999 are for "
                         "development) and prints successes, completion time and decision figures with 95 % "
                         "intervals (none for fewer than 5 episodes)."),
    "demo": Command("tasks.cli.task", "one joystick and one BoMI episode (P1 or --participant): table, "
                                      "timeline figure, MP4",
                    "The first command to run. Writes demo_out/timeline.png (what the BoMI decided over the "
                    "episode), demo_out/bomi_episode.mp4 and demo_out/demo.json; run again, it replaces them."),
    "sweep": Command("tasks.cli.sweep", "episodes over a grid of participants x settings x seeds, resumable"),
    "live": Command("tasks.cli.live", "drive the simulated arm from a live base-station stream"),
    "design": Command("tasks.cli.design", "choose a person's layout by simulation: candidate mappings run by their twin, "
                                          "ranked", "Candidates (tasks/operators/design.py): the motions in label order or by "
                      "opposites, with buttons alone or with automatic mode switching; each runs --seeds episodes; "
                      "ranked by successes, then completion time (95 % intervals); written as a profile: the derived "
                      "default unless a candidate beats it beyond chance on the same seeds."),
    "twin": Command("tasks.cli.twin", "fit a virtual participant (a twin) to a person's calibration recording(s)"),
    "synth": Command("tasks.cli.twin", "a virtual participant performs its source recording's protocol: a new "
                                       "recording"),
    "trial": Command("tasks.cli.trial", "the paper's session: N trials per controller, scored, logged, reported"),
    "replay": Command("tasks.cli.trial", "re-run a logged trial of `bomi trial` (or re-score it with another model)"),
}
COMMAND_MODULES: tuple[str, ...] = tuple(dict.fromkeys(command.module for command in COMMANDS.values()))


def add_command(subparsers: argparse._SubParsersAction, name: str, **kwargs) -> argparse.ArgumentParser:
    """The parser of sub-command ``name``, listed with its summary from COMMANDS, which is also its
    description in ``bomi NAME --help`` unless it has a longer one."""
    command = COMMANDS[name]
    kwargs.setdefault("description", " ".join([command.summary[0].upper() + command.summary[1:] + ".", command.about]))
    return subparsers.add_parser(name, help=COMMANDS[name].summary, **kwargs)


def _modules_for(argv: list[str]) -> list[str]:
    """The module of the command named by the first positional argument; none without one (help,
    --version and an unknown command need only the summaries)."""
    name = next((arg for arg in argv if not arg.startswith("-")), None)
    return [COMMANDS[name].module] if name in COMMANDS else []


class _Version(argparse.Action):
    """--version, reading the installed version only when asked (importlib.metadata is slow to load)."""

    def __call__(self, parser, namespace, values, option_string=None):
        from importlib.metadata import version
        print(f"{parser.prog} {version('bomi-jaco')}")
        parser.exit()


class OneLineParser(argparse.ArgumentParser):
    """argparse with its usage errors as the one line every bad input gets: ``bomi: error: ...``, exit 2."""

    def error(self, message: str) -> None:
        command = self.prog.removeprefix("bomi").strip()
        hint = f" (see bomi {command} --help)" if command else " (see bomi --help)"
        self.exit(2, f"bomi: error: {' '.join(message.split())}{hint}\n")


# The libraries that make a command module slow to import (seconds, together) and that no parser
# needs: a sub-command's --help builds its parser with each replaced by an inert placeholder.
HELP_ONLY_PLACEHOLDERS = ("numpy", "sklearn", "scipy", "matplotlib", "mujoco", "dm_control", "pinocchio", "coal",
                          "imageio", "ray", "serial", "tqdm", "h5py", "pyarrow", "pandas", "pygame")


class _Placeholder(types.ModuleType):
    """Stands for a library, and for anything taken from it, while a parser is built for --help:
    every attribute, call, item, operation or base class of it is another placeholder. No command
    runs then, so nothing ever uses one (tests/test_cli.py checks each command's help is the same
    with the real libraries)."""

    __path__: list[str] = []  # a package: its submodules are placeholders too

    def __getattr__(self, name: str) -> "_Placeholder":
        if name.startswith("__") and name.endswith("__"):
            raise AttributeError(name)
        return _Placeholder(f"{self.__name__}.{name}")

    def __call__(self, *args, **kwargs) -> "_Placeholder":
        return self

    def __mro_entries__(self, bases: tuple) -> tuple:
        return ()

    def __getitem__(self, key) -> "_Placeholder":
        return self

    def __iter__(self) -> Iterator:
        return iter(())

    def __fspath__(self) -> str:
        return self.__name__

    __or__ = __ror__ = __add__ = __radd__ = __mul__ = __rmul__ = __sub__ = __rsub__ = __truediv__ = \
        __rtruediv__ = __neg__ = lambda self, *other: self


class _PlaceholderImporter(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in HELP_ONLY_PLACEHOLDERS:
            return importlib.util.spec_from_loader(name, self, is_package=True)
        return None

    def create_module(self, spec) -> _Placeholder:
        return _Placeholder(spec.name)

    def exec_module(self, module) -> None:
        pass


@contextmanager
def _placeholder_libraries() -> Iterator[None]:
    """While the body runs, the HELP_ONLY_PLACEHOLDERS not yet imported import as placeholders;
    afterwards every module imported meanwhile is forgotten (a later real import loads them for real)."""
    before = set(sys.modules)
    importer = _PlaceholderImporter()
    sys.meta_path.insert(0, importer)
    try:
        yield
    finally:
        sys.meta_path.remove(importer)
        for name in set(sys.modules) - before:
            del sys.modules[name]


def wants_help(argv: list[str]) -> bool:
    return any(arg in ("-h", "--help") for arg in argv)


def build_parser(modules: Collection[str] = COMMAND_MODULES, *, for_help: bool = False) -> argparse.ArgumentParser:
    """The parser with every option of the commands of ``modules``; the other commands are listed only.
    ``for_help``: only to print help (no command will run), built without loading the heavy libraries."""
    if for_help:
        try:
            with _placeholder_libraries():
                return build_parser(modules)
        except Exception:  # a module that computes something from a library at import: the slow, real way
            pass
    parser = OneLineParser(prog="bomi", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action=_Version, nargs=0, help="show the program's version number and exit")
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
    args = None
    try:
        args = build_parser(_modules_for(argv), for_help=wants_help(argv)).parse_args(argv)
        return int(args.func(args) or 0)
    except SystemExit as exc:  # --help, --version, or a usage error already reported in one line
        return exc.code if isinstance(exc.code, int) else 2
    except (BomiError, SimError) as exc:  # bad input: files, options, ports, streams
        print(f"bomi: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bomi: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        raise
    except SystemError as exc:
        from tasks.experiments.engine import is_interruption
        if not is_interruption(exc):
            return _internal_error(exc, args, argv)
        print("bomi: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # the system refused (a full disk, a name too long, no permission): not a bug
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"bomi: error: {where}{exc.strerror or type(exc).__name__}", file=sys.stderr)
        return 2
    except Exception as exc:
        return _internal_error(exc, args, argv)


def _internal_error(exc: Exception, args, argv: list[str]) -> int:
    """A bug (in a command, or in loading one): one line, the traceback when asked for."""
    if args.debug if args is not None else "--debug" in argv:
        traceback.print_exception(exc)
    print(f"bomi: internal error: {type(exc).__name__}: {' '.join(str(exc).split())} "
          f"(a bug; rerun with --debug for the traceback)", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
