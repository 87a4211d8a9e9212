"""The `bomi` command line: the one place that wires bomi/, sim/ and tasks/ together.

It lives on the composing side (tasks/) so that bomi/, the signal chain, imports neither sim/ nor
tasks/ and installs and runs without MuJoCo.

Each command module exposes ``register(subparsers)`` which adds its sub-commands and sets
``func`` on them; ``func(args)`` returns the process exit code. Only the module that owns
the command being run is imported, so `bomi train` does not pay for loading MuJoCo.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from importlib.metadata import version

from bomi.errors import BomiError
from sim.errors import SimError

# module -> the sub-commands its register() adds (tests/test_cli.py checks they agree)
COMMAND_MODULES: dict[str, tuple[str, ...]] = {
    "tasks.cli.chain": ("train", "evaluate", "reproduce", "fuse"),
    "tasks.cli.stream": ("emulate", "capture", "record"),
    "tasks.cli.sim": ("sim-check", "render"),
    "tasks.cli.task": ("run-task", "benchmark", "demo"),
    "tasks.cli.sweep": ("sweep",),
    "tasks.cli.live": ("live",),
}


def _modules_for(argv: list[str]) -> list[str]:
    """The command module of the first positional argument, or all of them (for help and errors)."""
    command = next((arg for arg in argv if not arg.startswith("-")), None)
    owners = [module for module, commands in COMMAND_MODULES.items() if command in commands]
    return owners or list(COMMAND_MODULES)


def build_parser(modules: list[str] | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="bomi", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"%(prog)s {version('bomi-jaco')}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES if modules is None else modules:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser(_modules_for(argv)).parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (BomiError, SimError) as exc:
        print(f"bomi: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bomi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
