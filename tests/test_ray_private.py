"""A local Ray reachable from this machine only: during a `bomi sweep --engine ray`, no process of
the sweep or of its Ray listens (TCP) or receives (UDP) on anything but the loopback, as each
process's own network namespace sees it (read from /proc, as `ss -lptn` would)."""
import ipaddress
import os
import socket
import subprocess
import sys
import time

import pytest

from tasks.experiments.sweep import RESULTS_FILE

GRID = """
participants = ["P1"]
operators = ["joystick"]
seeds = {first = 0, count = 4}
[vary]
time_limit = [2.0]
"""
TCP_LISTEN = "0A"  # include/net/tcp_states.h


def _address(hex_address: str) -> tuple[str, int]:
    """/proc/net/{tcp,udp}{,6}'s local address: little-endian 32-bit words, then the port."""
    hex_ip, hex_port = hex_address.split(":")
    raw = bytes.fromhex(hex_ip)
    words = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
    family = socket.AF_INET if len(raw) == 4 else socket.AF_INET6
    return socket.inet_ntop(family, words), int(hex_port, 16)


def served_sockets(pid: int) -> list[tuple[str, str, int]]:
    """(protocol, address, port) of every TCP socket listening and UDP socket bound to a port that
    process ``pid`` holds, in the tables of its own network namespace."""
    try:
        inodes = {os.readlink(f"/proc/{pid}/fd/{fd}") for fd in os.listdir(f"/proc/{pid}/fd")}
    except OSError:  # ended meanwhile
        return []
    found = []
    for protocol in ("tcp", "tcp6", "udp", "udp6"):
        try:
            with open(f"/proc/{pid}/net/{protocol}") as table:
                lines = table.read().splitlines()[1:]
        except OSError:
            return []
        for line in lines:
            fields = line.split()
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


@pytest.mark.xdist_group("ray")  # one Ray at a time (see tests/test_engine.py)
def test_a_local_ray_sweep_listens_on_the_loopback_only(tmp_path):
    pytest.importorskip("ray", reason="Ray is the optional extra: pip install -e \".[ray]\"")
    grid, out = tmp_path / "grid.toml", tmp_path / "out"
    grid.write_text(GRID)
    sweep = subprocess.Popen([sys.executable, "-m", "tasks.cli", "sweep", str(grid), "--out", str(out),
                              "--engine", "ray", "--jobs", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    seen: dict[tuple[int, str, str, int], str] = {}  # (pid, protocol, address, port) -> the process's command
    try:
        while sweep.poll() is None:  # the whole run: start-up, episodes, idle workers, shut-down
            for pid in [sweep.pid, *descendants(sweep.pid)]:
                for served in served_sockets(pid):
                    try:
                        with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
                            seen[(pid, *served)] = cmdline.read().replace(b"\0", b" ")[:100].decode()
                    except OSError:
                        pass
            time.sleep(0.3)
        _, err = sweep.communicate()
    finally:
        if sweep.poll() is None:
            sweep.kill()
    assert sweep.returncode == 0, err
    assert (out / RESULTS_FILE).read_text().count("\n") == 4
    commands = " ".join(seen.values())
    assert "gcs_server" in commands and "raylet" in commands  # Ray's servers were seen, listening
    beyond = {key: command for key, command in seen.items() if not is_loopback(key[2])}
    assert not beyond, f"listening beyond the loopback: {beyond}"
