"""Where episodes run: a process pool on this machine, or a Ray cluster (the optional ``ray`` extra).

Both engines take a picklable function and items and yield ``(index, result)`` as each item
finishes, in whatever order they finish: the caller (``bomi benchmark``, ``bomi sweep``) puts
them in order, shows progress and saves them.  A result depends only on its item (an episode
depends only on its settings and seed), so the engine, the worker and the order change nothing.
"""
from __future__ import annotations

import argparse
import ctypes
import os
import signal
import socket
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from enum import Enum
from typing import Any, Protocol

from tqdm import tqdm

from bomi.errors import BomiError
from tasks.cli.options import positive_int

RAY_INSTALL = 'pip install -e ".[ray]"'
RAY_CONNECT_TIMEOUT_S = 10.0  # a Ray address that accepts no connection by then is refused
LOCAL_RAY_IP = "127.0.0.1"    # a local Ray binds its node here (not every interface)
MAX_JOBS = os.cpu_count() or 1  # more local processes than CPUs only slow every episode down


class EngineKind(str, Enum):
    LOCAL = "local"
    RAY = "ray"


def report(message: str) -> None:
    """A line on stderr that does not break a progress bar."""
    tqdm.write(message, file=sys.stderr)


class Engine(Protocol):
    def run(self, work: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """``(index, work(items[index]))`` for every item, as each finishes."""
        ...


class EpisodeFailed(RuntimeError):
    """An item's work raised (or its worker died) and, on Ray, did so again when retried."""


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _worker_init(driver: int) -> None:
    """In each pool worker: Ctrl-C is the driver's to handle (it stops the workers), and the worker
    is killed by the kernel when the driver dies, however it dies (kill -9 included)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for sig in (signal.SIGTERM, signal.SIGHUP):  # not the driver's handler (a KeyboardInterrupt traceback)
        signal.signal(sig, signal.SIG_DFL)         # when the driver stops the pool: ended quietly
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != driver:  # the driver died before the line above took effect
        os._exit(1)


class ProcessPool:
    """``workers`` processes on this machine (concurrent.futures); they die with the driver."""

    def __init__(self, workers: int):
        self.workers = workers

    def run(self, work: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        pool = ProcessPoolExecutor(max_workers=self.workers, initializer=_worker_init, initargs=(os.getpid(),))
        futures = {pool.submit(work, item): i for i, item in enumerate(items)}
        finished = False
        try:
            for future in as_completed(futures):
                i = futures[future]
                try:
                    result = future.result()
                except Exception as exc:
                    raise EpisodeFailed(f"{items[i]}: {type(exc).__name__}: {exc}") from exc
                yield i, result
            finished = True
        finally:  # interrupted or failed: nothing queued starts, nothing running goes on
            for future in futures:
                future.cancel()
            if not finished:
                for process in list((getattr(pool, "_processes", None) or {}).values()):
                    process.terminate()
            pool.shutdown(wait=True, cancel_futures=True)


class RayCluster:
    """Ray tasks of one CPU each, on the cluster at ``address`` or, without one, on a local Ray
    started with ``cpus`` CPUs.  A task whose worker fails (an exception, a crashed or lost
    worker) is reported with its item and run once more; a second failure stops the run."""

    def __init__(self, address: str | None = None, cpus: int | None = None):
        self.address, self.cpus = address, cpus

    def run(self, work: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        ray = import_ray()
        started_here = not ray.is_initialized()
        if started_here:  # a local Ray's workers at normal priority, as the pool's (Ray's default is nice 15)
            # a local Ray's node listens on this machine's loopback only, not on every interface
            local = {} if self.address else {"num_cpus": self.cpus, "_node_ip_address": LOCAL_RAY_IP,
                                              "_system_config": {"worker_niceness": 0}}
            # Ray's start-up replaces the driver's SIGTERM handling with its own (abort); the
            # caller's (a sweep keeps what finished, then shuts Ray down) is put back
            handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT)}
            if self.address is not None:
                check_ray_address(self.address)
            try:
                ray.init(address=self.address, include_dashboard=False, log_to_driver=False,
                         logging_level="warning", **local)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                where = f"--address {self.address}" if self.address else "--engine ray"
                raise BomiError(f"{where}: Ray did not start ({' '.join(str(exc).split())[:300]})") from None
            for sig, handler in handlers.items():
                if handler is not None:
                    signal.signal(sig, handler)
        remote = ray.remote(num_cpus=1, max_retries=0)(work)  # the one retry is ours, and reported
        pending = {remote.remote(item): (i, 0) for i, item in enumerate(items)}
        try:
            while pending:
                (ref,), _ = ray.wait(list(pending), num_returns=1)
                i, failures = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayError as exc:
                    reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                    if failures:
                        raise EpisodeFailed(f"{items[i]}: failed twice on Ray workers ({reason})") from exc
                    report(f"bomi: {items[i]}: failed on a Ray worker ({type(exc).__name__}: {reason}); retrying once")
                    pending[remote.remote(items[i])] = (i, 1)
                    continue
                yield i, result
        finally:
            if started_here:   # its workers end with it; cancelling them first races with their replies
                ray.shutdown()  # (Ray 2.60's core worker then aborts: "Tried to complete task that was not pending")
            else:               # a cluster's workers are shared: free them
                for ref in pending:
                    ray.cancel(ref, force=True)


def check_ray_address(address: str, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """A one-line BomiError unless something accepts a connection at the Ray address ``address``
    (HOST:PORT, ray://HOST:PORT) within ``timeout_s``: Ray itself retries a dead address forever.
    "auto" (the cluster this machine runs) is left to Ray, which fails at once without one."""
    if address == "auto":
        return
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise BomiError(f"--address {address}: expected HOST:PORT (e.g. 10.0.0.5:6379), ray://HOST:PORT or auto")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as exc:
        why = "no answer" if isinstance(exc, TimeoutError) else (exc.strerror or type(exc).__name__)
        raise BomiError(f"--address {address}: no Ray cluster answers there ({why}; waited at most {timeout_s:g} s)"
                        ) from None


def import_ray():
    """The ray module, or a one-line error saying how to install it."""
    try:
        import ray
    except ImportError:
        raise BomiError(f"--engine ray: Ray is not installed; install the optional extra: {RAY_INSTALL}") from None
    return ray


def add_engine_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--engine", choices=[k.value for k in EngineKind], default=EngineKind.LOCAL.value,
                        help="where the episodes run: a local process pool or a Ray cluster (default %(default)s)")
    parser.add_argument("--jobs", type=positive_int, default=os.cpu_count() or 1,
                        help="parallel episodes on this machine: the pool's processes, or the CPUs of a local Ray "
                             "(default: the number of CPUs, %(default)s)")
    parser.add_argument("--address", help="--engine ray: the Ray cluster to join (e.g. HEAD:6379 or auto); "
                                          "default: start a local Ray with --jobs CPUs")


def engine_from_args(args: argparse.Namespace) -> Engine:
    """The engine the options ask for; bad options (or Ray missing) fail before any work."""
    if args.jobs < 1:
        raise BomiError(f"--jobs must be at least 1, got {args.jobs}")
    if args.jobs > MAX_JOBS and not (args.engine == EngineKind.RAY.value and args.address is not None):
        raise BomiError(f"--jobs {args.jobs}: at most {MAX_JOBS}, this machine's CPUs (more processes only slow "
                        f"each episode down)")
    if args.engine == EngineKind.RAY.value:
        import_ray()
        return RayCluster(args.address, args.jobs)
    if args.address is not None:
        raise BomiError("--address is for --engine ray")
    return ProcessPool(args.jobs)
