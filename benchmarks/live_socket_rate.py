"""Does `bomi live` keep up with a 3-node stream on every kind of port?

    python benchmarks/live_socket_rate.py [--seconds 30]

Trains P1's model on day 1 (in a temporary directory), then for each port kind (socket://, pty)
starts `bomi emulate --participant P1 --to PORT` (3 nodes at 62.5 Hz) and `bomi live --port PORT
--headless --log L` and reads the log: frames handled per second per node (slope of the cumulative
frame count over the run, first and last second left out), the largest number of frames one tick
read, and how far the live loop fell behind (frames the emulator had sent by the end of live that
live never read, from the emulator's count). Before the fix the socket:// reader took one frame per
tick: 20 Hz per node (issue 10). Writes benchmarks/results/live_socket_rate.{md,json}.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = Path(__file__).resolve().parent.parent
NODES = 3
NOMINAL_HZ = 62.5


def bomi(*args: str, **kwargs) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT), MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    return subprocess.Popen([sys.executable, "-m", "tasks.cli", *args], env=env, **kwargs)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_one(kind: str, model: Path, seconds: float, work: Path) -> dict:
    log = work / f"live_{kind}.jsonl"
    to = f"socket://127.0.0.1:{free_port()}" if kind == "socket" else "pty"
    emulator = bomi("emulate", "--participant", "P1", "--to", to, "--duration", str(seconds + 20),
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    port = emulator.stdout.readline().strip() if kind == "pty" else to
    if kind == "socket":
        time.sleep(2.0)  # the emulator builds the participant, then listens
    live = bomi("live", "--port", port, "--profile", "P1", "--model", str(model), "--headless",
                "--duration", str(seconds), "--log", str(log), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = live.communicate(timeout=seconds + 120)
    emulator.terminate()
    emulator.communicate(timeout=30)
    if live.returncode != 0:
        raise SystemExit(f"live failed ({live.returncode}): {err.strip().splitlines()[-1:]}")
    ticks = [json.loads(line) for line in log.read_text().splitlines()]
    t = np.array([tick["t"] for tick in ticks])
    frames = np.cumsum([tick["frames"] for tick in ticks])
    first = int(np.argmax(frames > 0))
    steady = (t > t[first] + 1.0) & (t < t[-1] - 1.0)
    slope = float(np.polyfit(t[steady], frames[steady], 1)[0])
    # frames sent by the emulator from live's first frame on, at its real rate, minus frames read
    expected = NOMINAL_HZ * NODES * (t[-1] - t[first])
    return {"port": kind, "seconds": float(t[-1]), "ticks": len(ticks), "frames": int(frames[-1]),
            "per_node_hz": slope / NODES, "max_frames_in_one_tick": int(max(tick["frames"] for tick in ticks)),
            "frames_behind_at_end": float(expected - (frames[-1] - ticks[first]["frames"])),
            "summary": out.strip().splitlines()[-1]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    args = parser.parse_args()
    start = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        model = work / "p1_day1.json"
        data = Path(os.environ.get("BOMI_DATA_DIR", ROOT.parent / "shared" / "data" / "flexible_bomi_p1_5days"))
        trained = bomi("train", str(data / "day1_testp.mat"), "--profile", "P1", "--out", str(model),
                       stdout=subprocess.DEVNULL)
        if trained.wait() != 0:
            raise SystemExit("training the P1 model failed")
        rows = [run_one(kind, model, args.seconds, work) for kind in ("socket", "pty")]
    record = {"benchmark": "live_socket_rate", "python": platform.python_version(), "machine": platform.machine(),
              "nominal_hz_per_node": NOMINAL_HZ, "nodes": NODES, "runs": rows,
              "wall_s": time.monotonic() - start}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "live_socket_rate.json").write_text(json.dumps(record, indent=2) + "\n")
    lines = ["# bomi live: frames handled per node on each kind of port", "",
             f"`python benchmarks/live_socket_rate.py --seconds {args.seconds:g}`: `bomi emulate --participant P1` "
             f"(3 nodes at {NOMINAL_HZ:g} Hz) into `bomi live --headless` with P1's day-1 model; "
             f"Python {record['python']} on {record['machine']}.", "",
             "| port | live seconds | frames | frames/s per node | most frames in one tick | frames behind at the end |",
             "|---|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['port']} | {r['seconds']:.1f} | {r['frames']} | {r['per_node_hz']:.2f} "
              f"| {r['max_frames_in_one_tick']} | {r['frames_behind_at_end']:.0f} |" for r in rows]
    lines += ["", "Frames behind: what the emulator sent at its real rate since live's first frame, minus what live "
              "read; a few frames is one tick's worth (60 Hz ticks, 187.5 frames/s). Before the fix (issue 10) the "
              "socket:// reader took one 32-byte frame per tick: 20 Hz per node, a backlog growing by 127.5 "
              "frames every second."]
    (RESULTS / "live_socket_rate.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
