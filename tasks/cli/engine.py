"""The engine options of `bomi benchmark`, `bomi design` and `bomi sweep` (tasks/experiments/engine.py
runs the episodes): --engine, --jobs, --address."""
from __future__ import annotations

import argparse
import os

from tasks.cli.options import positive_int
from tasks.experiments.engine import Engine, EngineKind, make_engine


def add_engine_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--engine", choices=[k.value for k in EngineKind], default=EngineKind.LOCAL.value,
                        help="where the episodes run: a local process pool or a Ray cluster (default %(default)s)")
    parser.add_argument("--jobs", type=positive_int, default=os.cpu_count() or 1,
                        help="parallel episodes on this machine: the pool's processes, or the CPUs of a local Ray "
                             "(default: the number of CPUs, %(default)s)")
    parser.add_argument("--address", help="--engine ray: the Ray cluster to join (e.g. HEAD:6379 or auto); "
                                          "default: start a local Ray with --jobs CPUs, reachable only from this "
                                          "machine")


def engine_from_args(args: argparse.Namespace) -> Engine:
    """The engine the options ask for; bad options (or Ray missing) fail before any work."""
    return make_engine(EngineKind(args.engine), args.jobs, args.address)
