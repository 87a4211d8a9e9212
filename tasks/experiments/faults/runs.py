"""The command line run as a user runs it, for the fault corpora: ``python -m tasks.cli`` (this tree's) in a
process of its own, with a timeout, a file-size limit (a full disk) or a signal sent at a given line."""
from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]   # the tree whose command line runs


# ------------------------------------------------------------------------- the command line, run
@dataclass
class Ran:
    code: int | None  # None: killed at the timeout
    err: str
    seconds: float


def run_bomi(argv: list[str], cwd: Path, timeout: float, *, fsize: int | None = None,
             signal_at: tuple[str, int] | None = None) -> Ran:
    """``python -m tasks.cli ARGV`` (this tree's) in ``cwd``, in a process group of its own, its stderr
    through a pipe (no file-size limit applies to it); ``fsize``: its file-size limit in bytes (a full
    disk); ``signal_at``: (text, signal) sends the signal to its group once stderr shows the text."""
    start = time.monotonic()

    def limited() -> None:
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "tasks.cli", *argv], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
                            preexec_fn=limited)
    chunks: list[bytes] = []
    reader = threading.Thread(target=lambda: chunks.extend(iter(lambda: proc.stderr.read1(65536), b"")), daemon=True)
    reader.start()
    sent, code = signal_at is None, None
    while True:
        if proc.poll() is not None:
            code = proc.returncode
            break
        if not sent and signal_at[0].encode() in b"".join(chunks):
            os.killpg(proc.pid, signal_at[1])
            sent = True
        if time.monotonic() - start > timeout:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            break
        time.sleep(0.02)
    reader.join(timeout=5)
    return Ran(code, b"".join(chunks).decode(errors="replace"), time.monotonic() - start)


def forked(argv: list[str], cwd: Path, timeout: float) -> tuple[int | None, str]:
    """(exit code or None on timeout, stderr) of ``run_bomi``."""
    ran = run_bomi(argv, cwd, timeout)
    return (ran.code, ran.err) if ran.code is not None else (None, f"timeout after {timeout:g} s")
