"""What a process tree serves on the network, read from /proc as `ss -lptn` would: each process's
listening TCP and bound UDP sockets in the tables of its own network namespace."""
from __future__ import annotations

import ipaddress
import os
import socket
import threading
import time
from collections.abc import Callable

TCP_LISTEN = "0A"  # include/net/tcp_states.h


def _address(hex_address: str) -> tuple[str, int]:
    """/proc/net/{tcp,udp}{,6}'s local address: little-endian 32-bit words, then the port."""
    hex_ip, hex_port = hex_address.split(":")
    raw = bytes.fromhex(hex_ip)
    words = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
    family = socket.AF_INET if len(raw) == 4 else socket.AF_INET6
    return socket.inet_ntop(family, words), int(hex_port, 16)


def socket_inodes(pid: int) -> set[str] | None:
    """The sockets (``socket:[inode]``) among process ``pid``'s open files; None if it has ended."""
    try:
        return {os.readlink(f"/proc/{pid}/fd/{fd}") for fd in os.listdir(f"/proc/{pid}/fd")}
    except OSError:  # ended meanwhile
        return None


def network_namespace(pid: int) -> str | None:
    """Process ``pid``'s network namespace (``net:[inode]``); None if it has ended."""
    try:
        return os.readlink(f"/proc/{pid}/ns/net")
    except OSError:
        return None


def socket_tables(pid: int) -> dict[str, list[list[str]]] | None:
    """The TCP and UDP tables (their rows' fields) of process ``pid``'s own network namespace, as
    /proc/PID/net/ shows them (as `ss -lptn` reads them); None if it has ended."""
    tables = {}
    for protocol in ("tcp", "tcp6", "udp", "udp6"):
        try:
            with open(f"/proc/{pid}/net/{protocol}") as table:
                tables[protocol] = [line.split() for line in table.read().splitlines()[1:]]
        except OSError:
            return None
    return tables


def served_in(inodes: set[str], tables: dict[str, list[list[str]]]) -> list[tuple[str, str, int]]:
    """(protocol, address, port) of every TCP socket listening and UDP socket bound to a port in
    ``tables`` (a namespace's, ``socket_tables``) that is one of ``inodes`` (a process's, ``socket_inodes``)."""
    found = []
    for protocol, rows in tables.items():
        for fields in rows:
            address, port = _address(fields[1])
            if f"socket:[{fields[9]}]" in inodes and port and (protocol.startswith("udp") or fields[3] == TCP_LISTEN):
                found.append((protocol, address, port))
    return found


def is_loopback(address: str) -> bool:
    ip = ipaddress.ip_address(address)
    return ip.is_loopback or (ip.version == 6 and ip.ipv4_mapped is not None and ip.ipv4_mapped.is_loopback)


def descendants(pid: int) -> list[int]:
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as stat:
                    parents[int(entry)] = int(stat.read().rsplit(")", 1)[1].split()[1])
            except OSError:
                pass
    found, todo = [], [pid]
    while todo:
        pid = todo.pop()
        kids = [child for child, parent in parents.items() if parent == pid]
        found += kids
        todo += kids
    return found


class ServedSockets:
    """While open, every 0.3 s: the sockets served by the processes ``roots()`` names and all their
    descendants, as {(pid, protocol, address, port): the process's command line}."""

    def __init__(self, roots: Callable[[], list[int]]):
        self.roots, self.seen = roots, {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def __enter__(self) -> "ServedSockets":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=10)

    def _watch(self) -> None:
        while not self._stop.is_set():
            processes = [p for root in self.roots() for p in (root, *descendants(root))]
            inodes = {pid: socket_inodes(pid) for pid in processes}
            # each namespace's tables read once, after its processes' files (Ray's ~15 processes share
            # one: /proc/PID/net/* costs ~2 ms a table, each process reading its own kept a core busy)
            tables: dict[str, dict | None] = {}
            for pid in processes:
                namespace = network_namespace(pid)
                if inodes[pid] is None or namespace is None:
                    continue
                if tables.get(namespace) is None:   # its namespace's first, or the process read from had ended
                    tables[namespace] = socket_tables(pid)
                for served in served_in(inodes[pid], tables[namespace] or {}):
                    try:
                        with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
                            self.seen[(pid, *served)] = cmdline.read().replace(b"\0", b" ")[:100].decode()
                    except OSError:
                        pass
            time.sleep(0.3)

    def beyond_loopback(self) -> dict:
        return {key: command for key, command in self.seen.items() if not is_loopback(key[2])}

    def commands(self) -> str:
        return " ".join(self.seen.values())


def descendants_running(parent: int, module: str) -> list[int]:
    """The descendants of ``parent`` whose command line names ``module``."""
    found = []
    for pid in descendants(parent):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
                if module.encode() in cmdline.read():
                    found.append(pid)
        except OSError:
            pass
    return found
