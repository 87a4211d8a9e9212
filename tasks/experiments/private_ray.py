"""A local Ray that nothing beyond this machine's loopback can reach.

Ray 2.60's GCS, raylet, agents, idle workers and driver listen on every interface (its gRPC
servers bind the wildcard address whatever ``_node_ip_address`` says, and no setting changes
that), and whoever reaches the GCS can run code.  So the local Ray and its driver run in a child
process (this module, run by ``engine.run_private``) that first moves into a network namespace of
its own, holding only the loopback interface: a user namespace with it, so no privilege is needed
(as root the network namespace alone is the fallback).  Ray's processes start from that child and
stay in its namespace.  The calling process talks to the child over a socket pair (not the
network): the work and items go down, results, retry reports and failures come back.
"""
from __future__ import annotations

import ctypes
import fcntl
import os
import pickle
import signal
import socket
import struct
import sys
from multiprocessing.connection import Connection
from typing import Any

from tasks.experiments.engine import (EpisodeFailed, Message, die_with, ray_results, restore,
                                      signal_handlers)

LOOPBACK = "127.0.0.1"
CLONE_NEWUSER, CLONE_NEWNET = 0x10000000, 0x40000000  # linux/sched.h
SIOCGIFFLAGS, SIOCSIFFLAGS, IFF_UP = 0x8913, 0x8914, 0x1  # linux/sockios.h, linux/if.h


def private_network() -> str | None:
    """Move this (still single-threaded) process into a new network namespace whose loopback is
    up; None, or why it could not."""
    libc = ctypes.CDLL(None, use_errno=True)
    uid, gid = os.getuid(), os.getgid()
    if libc.unshare(CLONE_NEWUSER | CLONE_NEWNET) == 0:
        for name, text in (("setgroups", "deny"), ("uid_map", f"{uid} {uid} 1"), ("gid_map", f"{gid} {gid} 1")):
            with open(f"/proc/self/{name}", "w") as file:  # this process keeps its own user and group
                file.write(text)
    elif libc.unshare(CLONE_NEWNET) != 0:  # no user namespaces here: as root the network one suffices
        return os.strerror(ctypes.get_errno())
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:  # a new namespace's loopback is down
        request = struct.pack("16sH22x", b"lo", 0)
        flags = struct.unpack("16sH22x", fcntl.ioctl(probe, SIOCGIFFLAGS, request))[1]
        fcntl.ioctl(probe, SIOCSIFFLAGS, struct.pack("16sH22x", b"lo", flags | IFF_UP))
    return None


def _serve(connection: Connection, parent: int) -> None:
    def send(kind: Message, payload: Any = None) -> None:
        connection.send_bytes(pickle.dumps((kind.value, payload)))  # its __main__'s class is not the caller's

    refusal = private_network()
    if refusal is not None:
        send(Message.REFUSED, f"--engine ray: a local Ray needs a private network namespace (so that only this "
                              f"machine reaches it), which this system refuses ({refusal}); use --engine local, "
                              f"or --address of a cluster you have secured")
        return
    # a one-node Ray: its node's address is the loopback, never probed by connecting out (Ray's
    # switch for the one-node Ray of Windows and macOS)
    os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
    import ray  # after the move: nothing below is reachable from the network

    die_with(parent, signal.SIGTERM)  # an orphan shuts its Ray down
    cpus, work, items = pickle.loads(connection.recv_bytes())
    handlers = signal_handlers()  # Ray's start-up replaces them with an abort
    try:  # workers at normal priority, as the pool's (Ray's default is nice 15)
        ray.init(num_cpus=cpus, _node_ip_address=LOOPBACK, include_dashboard=False, log_to_driver=False,
                 logging_level="warning", _system_config={"worker_niceness": 0})
    except (ConnectionError, RuntimeError, ValueError) as exc:
        send(Message.REFUSED, f"--engine ray: Ray did not start ({' '.join(str(exc).split())[:300]})")
        return
    restore(handlers)
    try:
        for i, result in ray_results(ray, work, items, cancel_pending=False,
                                     say=lambda line: send(Message.REPORT, line)):
            send(Message.RESULT, (i, result))
        send(Message.DONE)
    except EpisodeFailed as exc:
        send(Message.FAILED, str(exc))
    finally:  # its workers end with it; cancelling them first races with their replies
        ray.shutdown()  # (Ray 2.60's core worker then aborts: "Tried to complete task that was not pending")


def _interrupt(signum, frame):
    raise KeyboardInterrupt(signal.Signals(signum).name)


def main(argv: list[str]) -> int:
    """The child: ``FD PARENT_PID``; SIGTERM (the caller's stop, or the caller's death) shuts its
    Ray down; the caller's Ctrl-C reaches it too."""
    signal.signal(signal.SIGTERM, _interrupt)
    connection = Connection(int(argv[0]))
    try:
        _serve(connection, int(argv[1]))
    except (KeyboardInterrupt, BrokenPipeError, ConnectionError, EOFError):
        return 1  # the caller stopped (or left): it reports
    finally:
        connection.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
