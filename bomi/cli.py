"""The `bomi` command line: the one place that wires bomi/, sim/ and tasks/ together.

Each command module exposes ``register(subparsers)`` which adds its sub-commands and sets
``func`` on them; ``func(args)`` returns the process exit code.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from bomi.errors import BomiError
from sim.errors import SimError

COMMAND_MODULES: list[str] = ["sim.commands", "bomi.stream_commands", "bomi.chain_commands", "tasks.commands"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="bomi", description=__doc__.splitlines()[0])
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
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
