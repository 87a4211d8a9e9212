"""Where episodes run: a process pool on this machine, or Ray (the optional ``ray`` extra).

Every engine takes a picklable function and items and yields ``(index, result)`` as each item
finishes, in whatever order they finish: the caller (``bomi benchmark``, ``bomi sweep``) puts
them in order, shows progress and saves them.  A result depends only on its item (an episode
depends only on its settings and seed), so the engine, the worker and the order change nothing.

A local Ray (no cluster address) runs in a private network namespace (``private_ray``): Ray 2.60's
GCS, raylet and workers listen on every interface whatever their node address, and nothing outside
this machine must reach them.
"""
from __future__ import annotations

import ctypes
import os
import pickle
import signal
import socket
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from enum import Enum
from multiprocessing.connection import Connection
from typing import Any, Protocol

from tqdm import tqdm

from bomi.errors import BomiError

RAY_INSTALL = 'pip install -e ".[ray]"'
PRIVATE_RAY = "tasks.experiments.private_ray"  # the module a private local Ray's driver runs
STOP_WAIT_S = 60.0  # for a private Ray's driver to shut its Ray down before it is killed
RAY_CONNECT_TIMEOUT_S = 10.0  # a Ray address that accepts no connection by then is refused
MAX_JOBS = os.cpu_count() or 1  # more local processes than CPUs only slow every episode down


class EngineKind(str, Enum):
    LOCAL = "local"
    RAY = "ray"


def report(message: str) -> None:
    """A line on stderr that does not break a progress bar."""
    tqdm.write(message, file=sys.stderr)


def is_interruption(exc: BaseException) -> bool:
    """A Ctrl-C (or SIGTERM/SIGHUP, which the long commands turn into one): a KeyboardInterrupt, or
    the SystemError a compiled (numba) call returns when the KeyboardInterrupt is raised while it runs."""
    return isinstance(exc, KeyboardInterrupt) or (isinstance(exc, SystemError)
                                                  and isinstance(exc.__cause__, KeyboardInterrupt))


class Engine(Protocol):
    def run(self, work: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """``(index, work(items[index]))`` for every item, as each finishes."""
        ...


class EpisodeFailed(RuntimeError):
    """An item's work raised (or its worker died) and, on Ray, did so again when retried."""


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with(parent: int, sig: signal.Signals = signal.SIGKILL) -> None:
    """This process gets ``sig`` from the kernel when ``parent`` dies, however it dies (kill -9
    included); it ends at once if ``parent`` died before that took effect."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, sig)
    if os.getppid() != parent:
        os._exit(1)


def _worker_init(driver: int) -> None:
    """In each pool worker: Ctrl-C is the driver's to handle (it stops the workers), and the worker
    dies with the driver."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for sig in (signal.SIGTERM, signal.SIGHUP):  # not the driver's handler (a KeyboardInterrupt traceback)
        signal.signal(sig, signal.SIG_DFL)         # when the driver stops the pool: ended quietly
    die_with(driver)


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


def ray_results(ray, work: Callable[[Any], Any], items: Sequence[Any], *, cancel_pending: bool,
                say: Callable[[str], None] = report) -> Iterator[tuple[int, Any]]:
    """``work`` over ``items`` as Ray tasks of one CPU each on the Ray this process has joined.  A
    task whose worker fails (an exception, a crashed or lost worker) is reported (``say``) with its
    item and run once more; a second failure raises EpisodeFailed.  ``cancel_pending``: tasks left
    unfinished (interrupted, failed) are cancelled (a shared cluster's workers are freed)."""
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
                say(f"bomi: {items[i]}: failed on a Ray worker ({type(exc).__name__}: {reason}); retrying once")
                pending[remote.remote(items[i])] = (i, 1)
                continue
            yield i, result
    finally:
        if cancel_pending:
            for ref in pending:
                ray.cancel(ref, force=True)


def signal_handlers() -> dict[signal.Signals, Any]:
    """This process's handlers of the signals Ray's start-up replaces with its own (abort)."""
    return {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT)}


def restore(handlers: dict[signal.Signals, Any]) -> None:
    for sig, handler in handlers.items():
        if handler is not None:
            signal.signal(sig, handler)


class RayCluster:
    """Ray tasks of one CPU each (``ray_results``): on the cluster at ``address``; without one, on
    a Ray this process has already joined, or else on a private local Ray of ``cpus`` CPUs that
    only this machine's loopback reaches (``private_ray``)."""

    def __init__(self, address: str | None = None, cpus: int | None = None):
        self.address, self.cpus = address, cpus

    def run(self, work: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        ray = import_ray()
        if ray.is_initialized():  # the caller's own Ray: used as it is, its workers freed after
            yield from ray_results(ray, work, items, cancel_pending=True)
        elif self.address is None:
            yield from run_private(work, items, self.cpus)
        else:
            yield from self._on_cluster(ray, work, items)

    def _on_cluster(self, ray, work: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        check_ray_address(self.address)
        # the caller's handling of SIGTERM (a sweep keeps what finished) is put back after Ray's start-up
        handlers = signal_handlers()
        try:
            ray.init(address=self.address, include_dashboard=False, log_to_driver=False, logging_level="warning")
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise BomiError(f"--address {self.address}: Ray did not start ({' '.join(str(exc).split())[:300]})"
                            ) from None
        restore(handlers)
        try:
            yield from ray_results(ray, work, items, cancel_pending=False)
        finally:  # the driver leaves; the cluster ends this job's tasks
            ray.shutdown()


# ------------------------------------------------------------------------------------ a private local Ray
class Message(str, Enum):
    RESULT = "result"    # (index, result)
    REPORT = "report"    # a line for the user (a retried episode)
    FAILED = "failed"    # an episode failed twice: EpisodeFailed's text
    REFUSED = "refused"  # no private namespace, or Ray did not start: a BomiError's text
    DONE = "done"


def run_private(work: Callable[[Any], Any], items: Sequence[Any], cpus: int | None) -> Iterator[tuple[int, Any]]:
    """``(index, work(items[index]))`` from a private local Ray of ``cpus`` CPUs (``private_ray``,
    in a child process), as each finishes (``ray_results``'s retry and failure rules); the child and
    its Ray end when this generator does (finished, failed or interrupted), or die with this process."""
    from ray import cloudpickle  # work may be a closure: pickled by value, as Ray does

    ours, theirs = socket.socketpair()
    env = os.environ | {"PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}  # the work's modules, found
    child = subprocess.Popen([sys.executable, "-m", PRIVATE_RAY, str(theirs.fileno()), str(os.getpid())],
                             pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, env=env)
    theirs.close()
    connection = Connection(ours.detach())
    try:
        connection.send_bytes(cloudpickle.dumps((cpus, work, list(items))))
        while True:
            try:
                value, payload = pickle.loads(connection.recv_bytes())
            except (EOFError, ConnectionError):
                raise BomiError(f"--engine ray: the private local Ray ended unexpectedly (exit code "
                                f"{child.wait()}); its logs are in /tmp/ray/session_latest/logs") from None
            kind = Message(value)
            if kind is Message.RESULT:
                yield payload
            elif kind is Message.REPORT:
                report(payload)
            elif kind is Message.FAILED:
                raise EpisodeFailed(payload)
            elif kind is Message.REFUSED:
                raise BomiError(payload)
            else:
                return
    finally:
        connection.close()
        _stop(child)


def _stop(child: subprocess.Popen) -> None:
    """The child shuts its Ray down (SIGTERM) or, failing that within STOP_WAIT_S, is killed."""
    if child.poll() is None:
        child.send_signal(signal.SIGTERM)
        try:
            child.wait(STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()


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


def make_engine(kind: EngineKind, jobs: int, address: str | None = None) -> Engine:
    """The engine asked for; bad settings (or Ray missing) fail here, before any work."""
    if jobs < 1:
        raise BomiError(f"--jobs must be at least 1, got {jobs}")
    if jobs > MAX_JOBS and not (kind is EngineKind.RAY and address is not None):
        raise BomiError(f"--jobs {jobs}: at most {MAX_JOBS}, this machine's CPUs (more processes only slow "
                        f"each episode down)")
    if kind is EngineKind.RAY:
        import_ray()
        return RayCluster(address, jobs)
    if address is not None:
        raise BomiError("--address is for --engine ray")
    return ProcessPool(jobs)
