"""Faults, made and run through the command line: damaged files and bad option values through every
command (``bad-input``), the human-in-the-loop session's faults (``session``: kills, signals, a full
disk, damaged or mixed session files, a stale calibration) and the live loop's safety bars end to
end (``live``: neutral hold, a lost stream, bad sensors, corrupted bytes, a flood, filming). The
README's rows "damaged files and option values", "session faults" and "`bomi live`" come from here.

    python benchmarks/faults.py bad-input [--per-kind 40] [--seed 0]
    python benchmarks/faults.py session [--timeout 300] [--only NAME,NAME]
    python benchmarks/faults.py live --seeds 11000 [--participants P1 P4] [--bars ...]

Every command runs as ``python -m tasks.cli`` in a process of its own (cwd a temporary directory,
never the repository): nothing of the command line is imported here. The frame parser's fuzzing is
in tests/test_frames.py; the live loop's breaks and another sitting in tests/test_live_safety.py and
tests/test_live_breaks.py. What each group does and how an outcome is classified: its section below.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
from tqdm import tqdm

from bomi.chain import OnlineChain, train
from bomi.classifier import NEUTRAL_LABEL
from bomi.emulator import EmulatorConfig, EmulatorStats, PtySink, block_chunks, play
from bomi.model_io import load_model, save_model
from bomi.protocol import Cue
from bomi.serial_source import SerialSource, StreamReader
from sim.env import ArmSim
from tasks.operators.stick import arm_profile, profile_layout
from tasks.participants.participant import calibration_session, load_participant, session_recording
from tasks.participants.wire import participant_blocks, session_heading
from tasks.trials.live import LiveLoop

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"


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


# ============================================================================ bad-input
# A larger corpus of bad inputs, made outside the repository and run through every command.
#
#     python benchmarks/faults.py bad-input [--per-kind 40] [--seed 0]
#
# Base files (in a temporary directory): a 950-row P1 recording cut from day 1, a P1 model trained
# on it (.json and .npz), and copies of the shipped P1 profile, P1 participant, operator and
# simulation TOML files. Each is damaged ``--per-kind`` ways, seeded: truncated, random bytes, byte
# flips, a spliced-in chunk, a line deleted or duplicated, and a number (cell, JSON value, TOML
# value) replaced by one of -1, 0, nan, inf, 1e300, 1e400, a word, an empty value, a huge integer.
# Every damaged file goes through every command that reads that kind of file; and every numeric
# option of every command gets -1, 0, nan, inf, 1e308, a word and an empty string. Each run is its
# own process (``run_bomi``: a fresh interpreter running `python -m tasks.cli`, a few seconds each,
# where the earlier forks of an interpreter that had imported the command line took 0.1 s; nothing
# of the command line is imported here). Its outcome is one of:
#
# - clean error: exit 2, exactly one stderr line starting ``bomi: error:`` (the last line), no traceback;
# - accepted: exit 0 (a damage that leaves a valid file, e.g. a flipped digit, is accepted rightly), or
#   run-task's exit 1 (the episode ran and did not succeed in its --time-limit);
# - traceback: a Python traceback or a ``bomi: internal error`` line;
# - other: any other exit code or stderr shape (listed one by one);
# - input changed: an input file differs afterwards, or a temporary file was left behind.
#
# Writes benchmarks/results/bad_input_corpus.{md,json}; the corpus itself is deleted.
TEMP_MARK = ".partial-"
REFUSED_PORT = "socket://127.0.0.1:1"  # never listening: a command that gets this far fails on the port
BAD_NUMBERS = ["-1", "0", "nan", "inf", "1e300", "1e400", "abc", "", "99999999999999999999999"]
BAD_OPTION_VALUES = ["-1", "0", "nan", "inf", "1e308", "abc", ""]
NUMBER = re.compile(rb"-?\d+(\.\d+)?(e-?\d+)?")


@dataclass
class Run:
    command: str
    kind: str       # what was bad: a file kind or "option"
    what: str       # the damage or the option value
    argv: list[str]


def corpus_bases(work: Path) -> dict[str, Path]:
    """The good files every damage starts from."""
    sys.path.insert(0, str(ROOT))
    from bomi.chain import train
    from bomi.dataset import data_dir
    from bomi.model_io import load_model, save_model
    from bomi.profiles import load_profile
    from bomi.recording import NodeData, Recording, read_recording, write_recording

    day1 = read_recording(data_dir() / "day1_testp.mat")
    tiny = Recording({i: NodeData(**{s: getattr(n, s)[:950] for s in ("acc", "gyro", "mag", "angles")})
                      for i, n in day1.nodes.items()}, day1.labels[:950])
    bases = {"csv": work / "tiny.csv", "json": work / "m.json", "npz": work / "m.npz",
             "profile": work / "profile.toml", "participant": work / "participant.toml",
             "operator": work / "operator.toml", "sim": work / "sim.toml"}
    write_recording(bases["csv"], tiny)
    # the first 950 samples hold some of P1's classes: a small valid model, as before issue 29
    save_model(bases["json"], train([read_recording(bases["csv"])], load_profile("P1"), allow_missing_classes=True))
    save_model(bases["npz"], load_model(bases["json"]))
    shutil.copy(ROOT / "bomi" / "profiles" / "P1.toml", bases["profile"])
    shutil.copy(ROOT / "tasks" / "participants" / "P1.toml", bases["participant"])
    shutil.copy(ROOT / "tasks" / "operators" / "operator.toml", bases["operator"])
    shutil.copy(ROOT / "models" / "sim.toml", bases["sim"])
    return bases


def damages(good: bytes, count: int, rng: np.random.Generator, textual: bool) -> list[tuple[str, bytes]]:
    """``count`` damaged versions of ``good``: (what was done, bytes)."""
    kinds = ["truncated", "random bytes", "byte flips", "spliced chunk"]
    if textual:
        kinds += ["line deleted", "line duplicated", "number replaced", "number replaced"]
    out = []
    for k in range(count):
        kind = kinds[k % len(kinds)]
        data = bytearray(good)
        if kind == "truncated":
            cut = int(rng.integers(0, len(good)))
            out.append((f"truncated at {cut}", bytes(data[:cut])))
        elif kind == "random bytes":
            out.append(("random bytes", rng.bytes(int(rng.integers(1, 4096)))))
        elif kind == "byte flips":
            flips = int(rng.integers(1, 9))
            for i in rng.integers(0, len(data), flips):
                data[i] = int(rng.integers(0, 256))
            out.append((f"{flips} byte(s) flipped", bytes(data)))
        elif kind == "spliced chunk":
            at = int(rng.integers(0, len(data)))
            out.append((f"chunk spliced at {at}", bytes(data[:at]) + rng.bytes(int(rng.integers(1, 64))) + bytes(data[at:])))
        else:
            lines = good.split(b"\n")
            j = int(rng.integers(0, len(lines)))
            if kind == "line deleted":
                out.append((f"line {j + 1} deleted", b"\n".join(lines[:j] + lines[j + 1:])))
            elif kind == "line duplicated":
                out.append((f"line {j + 1} duplicated", b"\n".join(lines[:j + 1] + lines[j:])))
            else:
                numbered = [i for i, line in enumerate(lines) if NUMBER.search(line)]
                j = int(rng.choice(numbered))
                matches = list(NUMBER.finditer(lines[j]))
                m = matches[int(rng.integers(0, len(matches)))]
                value = BAD_NUMBERS[int(rng.integers(0, len(BAD_NUMBERS)))]
                lines[j] = lines[j][:m.start()] + value.encode() + lines[j][m.end():]
                out.append((f"line {j + 1}: a number -> {value or 'empty'}", b"\n".join(lines)))
    return out


def file_commands(kind: str, bad: Path, d: Path) -> dict[str, list[str]]:
    """Every command that reads a file of ``kind``, with ``bad`` in its place."""
    csv, model = d / "tiny.csv", d / "m.json"
    live = ["live", "--port", REFUSED_PORT, "--headless"]
    return {
        "csv": {"train": ["train", str(bad), "--out", str(d / "o.json")],
                "evaluate --test": ["evaluate", "--train", str(model), "--test", str(bad), "--png", str(d / "c.png")],
                "evaluate --train": ["evaluate", "--train", str(bad), "--test", str(csv), "--png", str(d / "c.png")],
                "fuse": ["fuse", str(bad), "--out", str(d / "o.csv")],
                "emulate --recording": ["emulate", "--recording", str(bad), "--to", "/dev/null"],
                "live --neutral-from": [*live, "--profile", "P1", "--model", str(model), "--neutral-from", str(bad)]},
        "json": {"evaluate --train": ["evaluate", "--train", str(bad), "--test", str(csv), "--png", str(d / "c.png")],
                 "live --model": [*live, "--profile", "P1", "--model", str(bad)]},
        "npz": {"evaluate --train": ["evaluate", "--train", str(bad), "--test", str(csv), "--png", str(d / "c.png")],
                "live --model": [*live, "--profile", "P1", "--model", str(bad)]},
        "profile": {"train --profile": ["train", str(csv), "--profile", str(bad), "--out", str(d / "o.json")],
                    "evaluate --profile": ["evaluate", "--train", str(model), "--test", str(csv), "--profile", str(bad),
                                           "--png", str(d / "c.png")],
                    "live --profile": [*live, "--profile", str(bad), "--model", str(model)],
                    "capture --profile": ["capture", "--port", REFUSED_PORT, "--duration", "1", "--nodes", "1",
                                          "--profile", str(bad), "--out", str(d / "o.csv")],
                    "record --profile": ["record", "--port", REFUSED_PORT, "--profile", str(bad), "--out", str(d / "o.csv")]},
        "participant": {"run-task --participant": ["run-task", "--operator", "joystick", "--participant", str(bad),
                                                   "--time-limit", "1"],
                        "emulate --participant": ["emulate", "--participant", str(bad), "--to", "/dev/null"]},
        "operator": {"run-task --operator-file": ["run-task", "--operator", "joystick", "--operator-file", str(bad),
                                                  "--time-limit", "1"]},
        "sim": {"sim-check --config": ["sim-check", "--config", str(bad), "--seconds", "0.6"],
                "render --config": ["render", "--config", str(bad), "--out", str(d / "o.mp4")]},
    }[kind]


def option_runs(d: Path) -> list[Run]:
    """Every numeric option of every command, each bad value; the rest of the command line is good."""
    csv, model = str(d / "tiny.csv"), str(d / "m.json")
    base = {
        "evaluate": (["evaluate", "--train", model, "--test", csv, "--png", str(d / "c.png")], ["--reject", "--vote"]),
        "emulate": (["emulate", "--participant", "P1", "--to", "/dev/null"],
                    ["--rate", "--loss", "--corrupt", "--seed", "--duration", "--hold", "--neutral", "--linger", "--baud"]),
        "capture": (["capture", "--port", REFUSED_PORT, "--out", str(d / "o.csv"), "--duration", "1"],
                    ["--duration", "--baud", "--retries", "--nodes"]),
        "record": (["record", "--port", REFUSED_PORT, "--out", str(d / "o.csv"), "--profile", "P1"],
                   ["--repetitions", "--hold", "--neutral", "--baud", "--retries", "--amplitudes"]),
        "live": (["live", "--port", REFUSED_PORT, "--profile", "P1", "--model", model, "--headless"],
                 ["--duration", "--baud", "--retries"]),
        "run-task": (["run-task", "--operator", "joystick", "--time-limit", "1"], ["--seed", "--time-limit", "--vote"]),
        "benchmark": (["benchmark", "--operators", "joystick", "--seeds", "1", "--time-limit", "1"],
                      ["--seeds", "--first-seed", "--jobs", "--time-limit", "--vote"]),
        "demo": (["demo", "--out", str(d / "demo")], ["--seed"]),
        "sim-check": (["sim-check"], ["--deflection", "--seconds"]),
    }
    runs = []
    for command, (argv, options) in base.items():
        for option in options:
            for value in BAD_OPTION_VALUES:
                args = list(argv)
                if option in args:  # replace the good value already given
                    args[args.index(option) + 1] = value
                else:
                    args += [option, value]
                runs.append(Run(command, "option", f"{option} {value!r}", args))
    return runs


def snapshot(directory: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in directory.iterdir() if p.is_file()}


def classify(code: int, err: str) -> str:
    lines = err.splitlines()
    if "Traceback" in err or any("internal error" in line for line in lines):
        return "traceback"
    if code == 0:
        return "accepted"
    errors = [line for line in lines if line.startswith("bomi: error: ")]
    if code == 2 and len(errors) == 1 and lines[-1] == errors[0]:
        return "clean error"
    return "other"


def execute(run: Run, base_dir: Path, scratch: Path, timeout: float) -> dict:
    """One run in its own copy of the base files, so no run sees another's leftovers."""
    d = Path(tempfile.mkdtemp(dir=scratch))
    for p in base_dir.iterdir():  # the good files and the bad one this run reads
        if not p.name.startswith("bad") or str(p) in run.argv:
            shutil.copy(p, d / p.name)
    argv = [a.replace(str(base_dir), str(d)) for a in run.argv]
    before = snapshot(d)
    start = time.monotonic()
    code, err = forked(argv, d, timeout)
    outcome = "other" if code is None else classify(code, err)
    if outcome == "other" and run.argv[0] == "run-task" and code == 1 and "bomi: error" not in err:
        outcome = "accepted"  # the episode ran (valid input) and did not succeed within its time limit
    seconds = time.monotonic() - start
    after = snapshot(d)
    changed = [name for name, digest in before.items() if after.get(name) != digest]
    leftovers = [p.name for p in d.rglob("*") if TEMP_MARK in p.name]
    if changed or leftovers:
        outcome = "input changed"
    shutil.rmtree(d, ignore_errors=True)
    last = err.strip().splitlines()[-1] if err.strip() else ""
    return {"command": run.command, "kind": run.kind, "what": run.what, "outcome": outcome, "exit": code,
            "seconds": round(seconds, 2), "stderr_last_line": last[:300], "changed": changed, "leftovers": leftovers}


def bad_input_main(args: argparse.Namespace) -> None:
    """Every command on damaged files and bad option values (the `bad-input` corpus)."""
    rng = np.random.default_rng(args.seed)
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="bomi-corpus-") as tmp:
        work = Path(tmp)
        base_dir = work / "base"
        base_dir.mkdir()
        bases = corpus_bases(base_dir)
        corpus = work / "corpus"
        corpus.mkdir()
        runs = []
        for kind, path in bases.items():
            for k, (what, data) in enumerate(damages(path.read_bytes(), args.per_kind, rng, kind != "npz")):
                bad = base_dir / f"bad{k}_{kind}{path.suffix}"  # beside the good files, copied with them per run
                (corpus / bad.name).write_bytes(data)
                runs += [Run(command, kind, what, argv) for command, argv in file_commands(kind, bad, base_dir).items()]
        runs += option_runs(base_dir)
        for p in corpus.iterdir():
            shutil.move(str(p), base_dir / p.name)
        scratch = work / "runs"
        scratch.mkdir()
        results = [execute(r, base_dir, scratch, args.timeout) for r in tqdm(runs, desc="bad inputs", unit="run")]
    outcomes = ["clean error", "accepted", "traceback", "other", "input changed"]
    by_kind: dict[str, Counter] = {}
    for r in results:
        by_kind.setdefault(r["kind"], Counter())[r["outcome"]] += 1
    total = Counter(r["outcome"] for r in results)
    record = {"benchmark": "bad_input_corpus", "seed": args.seed, "per_kind": args.per_kind,
              "python": platform.python_version(), "runs": len(results), "outcomes": dict(total),
              "wall_s": time.monotonic() - start, "results": results}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "bad_input_corpus.json").write_text(json.dumps(record, indent=1) + "\n")
    slow = sorted(results, key=lambda r: -r["seconds"])[:5]
    lines = ["# Bad-input corpus: every command on damaged files and bad option values", "",
             f"`python benchmarks/faults.py bad-input --per-kind {args.per_kind} --seed {args.seed}`: "
             f"{len(results)} runs of the command line (`python -m tasks.cli`, each in its own process) on a corpus made in a temporary directory (not in the "
             f"repository), {record['wall_s'] / 60:.1f} min on this machine. Outcome classes in the script's "
             "docstring.", "",
             "| bad input | runs | " + " | ".join(outcomes) + " |", "|---|---:|" + "---:|" * len(outcomes)]
    for kind, counts in by_kind.items():
        lines.append(f"| {kind} | {sum(counts.values())} | " + " | ".join(str(counts[o]) for o in outcomes) + " |")
    lines.append(f"| **all** | {len(results)} | " + " | ".join(f"**{total[o]}**" for o in outcomes) + " |")
    lines += ["", f"Slowest runs: " + "; ".join(f"{r['command']} ({r['what']}) {r['seconds']:.1f} s" for r in slow)]
    for outcome in ("traceback", "other", "input changed"):
        bad = [r for r in results if r["outcome"] == outcome]
        if bad:
            lines += ["", f"## {outcome} ({len(bad)})", ""]
            lines += [f"- {r['command']}, {r['kind']} {r['what']}: exit {r['exit']}: `{r['stderr_last_line']}`"
                      for r in bad]
    accepted = [r for r in results if r["outcome"] == "accepted"]
    if accepted:
        lines += ["", f"## accepted ({len(accepted)}): damage that left a valid input", ""]
        lines += [f"- {r['command']}, {r['kind']} {r['what']}" for r in accepted]
    (RESULTS / "bad_input_corpus.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:len(by_kind) + 8]))


# ============================================================================== session
# The fault corpus of human-in-the-loop sessions (issue 40): every fault the issue lists, made and run.
#
#     python benchmarks/faults.py session [--timeout 300] [--only NAME,NAME]
#
# Made once, in a temporary directory (never in the repository): a small real session (`bomi trial
# --stand-in P1`, one BoMI and one joystick trial of 8 s, seed 11), a P4 session (another person's
# model and profile), P1's and P4's synthesised calibration recordings (`bomi synth`), and a
# participant file. Each case damages a copy of what it needs and runs the commands the issue ran
# (``run_bomi``, as the bad-input corpus does; kill and signal
# cases send the signal once the session says "trial 2: go"). A case is counted as:
#
# - traceback: a Python traceback or ``bomi: internal error`` on stderr of any of its commands;
# - hang: a command still running at --timeout (killed);
# - nonsense accepted: exit 0 (or a wrong result: a sweep that reruns what it should not) where the
#   input should be refused, or a refusal that is not one ``bomi: error:`` line with exit 2;
# - trials lost: a finished trial that is not replayable afterwards (the kill cases);
# - ok otherwise.
#
# The trial cases exercise the session writer of issue 40 items 1-2 (`bomi trial --resume DIR`, a
# lock on --out, SIGTERM/SIGHUP like SIGINT, trials written as they finish). Writes
# benchmarks/results/session_faults.md.
SESSION = ["trial", "--stand-in", "P1", "--profile", "P1", "--controller", "bomi,joystick", "--trials", "1",
           "--seed", "11", "--headless", "--time-limit", "8", "--countdown", "0.5"]
P4_SESSION = ["trial", "--stand-in", "P4", "--profile", "P4", "--controller", "bomi", "--trials", "1",
              "--seed", "12", "--headless", "--time-limit", "2", "--countdown", "0.5"]
THREE_TRIALS = ["trial", "--stand-in", "P1", "--profile", "P1", "--controller", "bomi", "--trials", "3",
                "--seed", "13", "--headless", "--time-limit", "6", "--countdown", "0.5"]
GO_2 = "trial 2: go"
LOCK_WITHIN_S = 15.0  # a second session on a locked --out is refused before its calibration (~20 s here)


def clean_refusal(ran: Ran) -> bool:
    lines = ran.err.strip().splitlines()
    errors = [line for line in lines if line.startswith("bomi: error: ")]
    return ran.code == 2 and len(errors) == 1 and lines[-1] == errors[0]


def has_traceback(ran: Ran) -> bool:
    return "Traceback" in ran.err or "internal error" in ran.err


@dataclass
class Case:
    name: str
    group: str
    run: Callable[[Path, "Bases", float], dict]  # -> {"outcome": ..., "detail": ...}


@dataclass
class Bases:
    session: Path   # P1: trial 1 bomi, trial 2 joystick
    p4: Path        # a P4 BoMI session (its model and profile)
    p1_csv: Path    # P1's synthesised calibration (3 nodes, 9 classes)
    p4_csv: Path    # P4's (2 nodes, 6 classes)
    extra: dict = field(default_factory=dict)


def outcome_of(runs: list[Ran], want: str, lost: bool = False, wrong: str = "") -> dict:
    """The case's outcome from its commands' runs; ``want``: "refuse" or "accept" for the last run."""
    last = runs[-1]
    if any(has_traceback(r) for r in runs):
        outcome = "traceback"
    elif any(r.code is None for r in runs):
        outcome = "hang"
    elif lost:
        outcome = "trials lost"
    elif wrong or (want == "refuse" and not clean_refusal(last)) or (want == "accept" and last.code != 0):
        outcome = "nonsense accepted" if want == "refuse" or wrong else "other"
    else:
        outcome = "ok"
    shown = next((r for r in runs if has_traceback(r)), last)  # a traceback: its exception's line
    tail = shown.err.strip().splitlines()[-1] if shown.err.strip() else ""
    return {"outcome": outcome, "exit": last.code, "last_line": (wrong or tail)[:240],
            "seconds": round(sum(r.seconds for r in runs), 1)}


# ------------------------------------------------------------------------------------ replay cases
def copy_session(bases: Bases, work: Path) -> Path:
    d = work / "s"
    shutil.copytree(bases.session, d)
    return d


def jsonl_case(edit: Callable[[list[dict]], list[str]], trial: int = 1) -> Callable:
    def run(work: Path, bases: Bases, timeout: float) -> dict:
        d = copy_session(bases, work)
        records = [json.loads(line) for line in (d / "trials.jsonl").read_text().splitlines()]
        (d / "trials.jsonl").write_text("\n".join(edit(records)) + "\n")
        return outcome_of([run_bomi(["replay", str(d), "--trial", str(trial)], work, timeout)], "refuse")
    return run


def h5_case(edit: Callable[[h5py.File], None], trial: int = 1, file: str = "bomi.h5") -> Callable:
    def run(work: Path, bases: Bases, timeout: float) -> dict:
        d = copy_session(bases, work)
        with h5py.File(d / file, "r+") as f:
            edit(f)
        return outcome_of([run_bomi(["replay", str(d), "--trial", str(trial)], work, timeout)], "refuse")
    return run


def set_attr(key: str, value) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        f.attrs[key] = value
    return edit


def edit_plan(f: h5py.File) -> None:
    plan = json.loads(f.attrs["plan"])
    plan["colour"] = "red"
    f.attrs["plan"] = json.dumps(plan)


def replace_column(name: str, change: Callable[[np.ndarray], np.ndarray]) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        values = change(f[name][()])
        del f[name]
        f.create_dataset(name, data=values)
    return edit


def files_case(change: Callable[[Path, Bases], None], argv_extra: tuple[str, ...] = (), trial: int = 1) -> Callable:
    def run(work: Path, bases: Bases, timeout: float) -> dict:
        d = copy_session(bases, work)
        change(d, bases)
        return outcome_of([run_bomi(["replay", str(d), "--trial", str(trial), *argv_extra], work, timeout)], "refuse")
    return run


def swap_f_b(d: Path, bases: Bases) -> None:
    text = (d / "profile.toml").read_text()
    text = text.replace('function = "F"', 'function = "@"').replace('function = "B"', 'function = "F"')
    (d / "profile.toml").write_text(text.replace('function = "@"', 'function = "B"'))


def drop_class_8(d: Path, bases: Bases) -> None:
    lines = (d / "profile.toml").read_text().splitlines(keepends=True)
    (d / "profile.toml").write_text("".join(line for line in lines if "label = 8," not in line))


def outside_link(name: str) -> Callable[[Path, Bases], None]:
    def change(d: Path, bases: Bases) -> None:
        outside = d.parent / f"outside_{name}"
        shutil.copy(d / name, outside)
        (d / name).unlink()
        (d / name).symlink_to(outside)
    return change


def mixed(d: Path, bases: Bases) -> None:
    """trials.jsonl of another session (P4's, seed 12) beside this one's bomi.h5 (two sessions interleaved)."""
    shutil.copy(bases.p4 / "trials.jsonl", d / "trials.jsonl")


def other_person(d: Path, bases: Bases) -> None:
    for name in ("model.json", "profile.toml"):
        shutil.copy(bases.p4 / name, d / name)


def rescore_other(work: Path, bases: Bases, timeout: float) -> dict:
    d = copy_session(bases, work)
    return outcome_of([run_bomi(["replay", str(d), "--trial", "1", "--model", str(bases.p4 / "model.json")], work,
                            timeout)], "refuse")


def good_replay(work: Path, bases: Bases, timeout: float) -> dict:
    d = copy_session(bases, work)
    runs = [run_bomi(["replay", str(d), "--trial", str(k)], work, timeout) for k in (1, 2)]
    return outcome_of(runs, "accept")


def huge_seed(work: Path, bases: Bases, timeout: float) -> dict:
    argv = [*SESSION[:SESSION.index("--seed")], "--seed", "99999999999999999999", "--out", str(work / "o")]
    ran = run_bomi(argv, work, timeout)
    return outcome_of([ran], "refuse", wrong="" if not (work / "o").exists() else "wrote --out before refusing")


# ------------------------------------------------------------------------------------ twin cases
def write_variant(source: Path, target: Path, change: Callable) -> Path:
    from bomi.recording import read_recording, write_recording
    rec = read_recording(source)
    write_recording(target, change(rec))
    return target


def dead(kind: str) -> Callable:
    def change(rec):
        node = rec.nodes[1]
        if kind == "constant":
            node.angles[:] = node.angles[0]
            for s in ("acc", "gyro", "mag"):
                getattr(node, s)[:] = getattr(node, s)[0]
        elif kind == "zero":
            for s in ("angles", "acc", "gyro", "mag"):
                getattr(node, s)[:] = 0
        else:  # saturated: the accelerometer clipped at the int16 limits
            node.acc[:] = np.clip(node.acc * 50, -32768, 32767)
        return rec
    return change


def labels_1e9(rec):
    rec.labels[rec.labels == 8] = 1_000_000_000
    return rec


def time_reversed(rec):
    rec.time[:] = rec.time[::-1].copy()
    return rec


def twin_then_synth(change: Callable | None, profile: tuple[str, ...] = ("--profile", "P1")) -> Callable:
    """`bomi twin` of the changed P1 recording; it must refuse, or else its twin must pass `bomi synth`."""
    def run(work: Path, bases: Bases, timeout: float) -> dict:
        rec = bases.p1_csv if change is None else write_variant(bases.p1_csv, work / "rec.csv", change)
        twin = run_bomi(["twin", str(rec), *profile, "--out", str(work / "t.toml")], work, timeout)
        if twin.code != 0 or change is None:
            runs = [twin]
            if twin.code == 0:
                runs.append(run_bomi(["synth", "--participant", str(work / "t.toml"), "--seed", "1", "--out",
                                  str(work / "t.csv")], work, timeout))
            return outcome_of(runs, "accept" if change is None else "refuse")
        synth = run_bomi(["synth", "--participant", str(work / "t.toml"), "--seed", "1", "--out", str(work / "t.csv")],
                     work, timeout)
        wrong = (f"twin accepted it (exit 0); synth then "
                 f"{'accepted its twin' if synth.code == 0 else 'refused its twin: ' + synth.err.strip()[-120:]}")
        return outcome_of([twin, synth], "refuse", wrong=wrong)
    return run


def two_people(work: Path, bases: Bases, timeout: float) -> dict:
    return outcome_of([run_bomi(["twin", str(bases.p1_csv), str(bases.p4_csv), "--out", str(work / "t.toml")], work,
                            timeout)], "refuse")


def huge_posture(command: str) -> Callable:
    def run(work: Path, bases: Bases, timeout: float) -> dict:
        text = (ROOT / "tasks" / "participants" / "P1.toml").read_text()
        start = text.index("posture_deg = [[") + len("posture_deg = [[")
        end = text.index(",", start)
        (work / "p.toml").write_text(text[:start] + "1e5" + text[end:])
        argv = (["synth", "--participant", str(work / "p.toml"), "--seed", "0", "--out", str(work / "x.csv")]
                if command == "synth" else ["run-task", "--operator", "bomi", "--participant", str(work / "p.toml"),
                                            "--time-limit", "1"])
        return outcome_of([run_bomi(argv, work, timeout)], "refuse")
    return run


# ------------------------------------------------------------------------------------ config and sweep cases
def operator_human_beside(work: Path, bases: Bases, timeout: float) -> dict:
    """[human] model = "h.toml" beside the operator file, run from another directory: read from beside
    the file (exit 0 or 1: the episode ran); the copy in the working directory is a broken file."""
    (work / "conf").mkdir()
    (work / "cwd").mkdir()
    text = (ROOT / "tasks" / "operators" / "operator.toml").read_text()
    head, _, _ = text.partition("[human]")
    (work / "conf" / "op.toml").write_text(head + '[human]\nmodel = "h.toml"\n')
    shutil.copy(ROOT / "tasks" / "operators" / "human.toml", work / "conf" / "h.toml")
    (work / "cwd" / "h.toml").write_text("not = [valid\n")
    ran = run_bomi(["run-task", "--operator", "joystick", "--operator-file", str(work / "conf" / "op.toml"),
                "--time-limit", "1"], work / "cwd", timeout)
    wrong = "read the working directory's h.toml" if "cwd/h.toml" in ran.err else ""
    result = outcome_of([ran], "accept", wrong=wrong)
    if result["outcome"] == "other" and ran.code == 1 and "bomi: error" not in ran.err:
        result["outcome"] = "ok"  # the episode ran and did not succeed in 1 s
    return result


def grid_text(participant: str, seeds: str = "[0]") -> str:
    return (f'participants = ["{participant}"]\noperators = ["joystick"]\nseeds = {seeds}\n'
            '[vary]\ntime_limit = [2.0]\n')


def grid_outside(work: Path, bases: Bases, timeout: float) -> dict:
    (work / "g").mkdir()
    (work / "g" / "grid.toml").write_text(grid_text("../../../tmp/x"))
    return outcome_of([run_bomi(["sweep", str(work / "g" / "grid.toml"), "--out", str(work / "o"), "--jobs", "1"], work,
                            timeout)], "refuse")


def jobs_unbounded(work: Path, bases: Bases, timeout: float) -> dict:
    (work / "grid.toml").write_text(grid_text("P1"))
    return outcome_of([run_bomi(["sweep", str(work / "grid.toml"), "--out", str(work / "o"), "--jobs", "10000"], work,
                            timeout)], "refuse")


def ray_dead_address(work: Path, bases: Bases, timeout: float) -> dict:
    (work / "grid.toml").write_text(grid_text("P1"))
    ran = run_bomi(["sweep", str(work / "grid.toml"), "--out", str(work / "o"), "--engine", "ray", "--address",
                "127.0.0.1:1", "--jobs", "1"], work, min(timeout, 60))
    return outcome_of([ran], "refuse", wrong="" if ran.seconds < 15 or ran.code is None else
                      f"refused after {ran.seconds:.0f} s, not within 10 s")


def episodes(out: Path) -> int:
    path = out / "episodes.jsonl"
    return len(path.read_text().splitlines()) if path.exists() else 0


def edited_twin_reruns(work: Path, bases: Bases, timeout: float) -> dict:
    """A sweep of a twin; the twin edited: its rows run again; resumed from another directory
    (the grid named by another path): nothing runs."""
    (work / "g").mkdir()
    (work / "elsewhere").mkdir()
    shutil.copy(ROOT / "tasks" / "participants" / "P1.toml", work / "g" / "twin.toml")
    (work / "g" / "grid.toml").write_text(grid_text("twin.toml"))
    argv = ["sweep", "g/grid.toml", "--out", "o", "--jobs", "1"]
    runs = [run_bomi(argv, work, timeout)]
    first = episodes(work / "o")
    text = (work / "g" / "twin.toml").read_text()
    (work / "g" / "twin.toml").write_text(text.replace("reaction_s = ", "reaction_s = 0.05 + 0 * ", 0) + "\n# edited\n")
    runs.append(run_bomi(argv, work, timeout))
    edited = episodes(work / "o")
    runs.append(run_bomi(["sweep", "../g/grid.toml", "--out", "../o", "--jobs", "1"], work / "elsewhere", timeout))
    moved = episodes(work / "o")
    wrong = ""
    if edited != first + 1:
        wrong = f"the edited twin ran {edited - first} episodes again, not 1"
    elif moved != edited:
        wrong = f"resumed from another directory: {moved - edited} episodes ran again, not 0"
    return outcome_of(runs, "accept", wrong=wrong)


def sweep_full_disk(work: Path, bases: Bases, timeout: float) -> dict:
    (work / "grid.toml").write_text(grid_text("P1", "[0, 1, 2]"))
    ran = run_bomi(["sweep", str(work / "grid.toml"), "--out", str(work / "o"), "--jobs", "2"], work, timeout,
               fsize=64)
    return outcome_of([ran], "refuse")


# ------------------------------------------------------------------------------------ session writer cases
def replayable(out: Path, trial: int, work: Path, timeout: float) -> Ran:
    return run_bomi(["replay", str(out), "--trial", str(trial)], work, timeout)


def killed_in_trial_2(sig: int) -> Callable:
    def run(work: Path, bases: Bases, timeout: float) -> dict:
        out = work / "o"
        ran = run_bomi([*THREE_TRIALS, "--out", str(out)], work, timeout, signal_at=(GO_2, sig))
        again = replayable(out, 1, work, timeout)
        lost = again.code != 0
        runs = [again] if sig == signal.SIGKILL else [ran, again]  # kill -9 leaves no stderr to judge
        return outcome_of(runs, "accept", lost=lost)
    return run


def force_over_finished(work: Path, bases: Bases, timeout: float) -> dict:
    out = work / "o"
    shutil.copytree(bases.session, out)
    run_bomi([*THREE_TRIALS, "--out", str(out), "--force"], work, timeout, signal_at=("trial 1: go", signal.SIGKILL))
    again = replayable(out, 1, work, timeout)
    return outcome_of([again], "accept", lost=again.code != 0)


def resume_after_kill(work: Path, bases: Bases, timeout: float) -> dict:
    out = work / "o"
    run_bomi([*THREE_TRIALS, "--out", str(out)], work, timeout, signal_at=(GO_2, signal.SIGKILL))
    resumed = run_bomi(["trial", "--resume", str(out)], work, timeout)
    records = (out / "trials.jsonl").read_text().splitlines() if (out / "trials.jsonl").exists() else []
    wrong = "" if resumed.code != 0 or len(records) == 3 else f"resumed, {len(records)} trials recorded, not 3"
    return outcome_of([resumed], "accept", wrong=wrong, lost=replayable(out, 1, work, timeout).code != 0)


def second_session_same_out(work: Path, bases: Bases, timeout: float) -> dict:
    """A second session into the same new --out 2 s after the first: refused (the first's lock), and
    the first then finishes whole (every trial replayable)."""
    out = work / "o"
    pid = os.fork()
    if pid == 0:  # the first session
        os._exit(run_bomi([*THREE_TRIALS, "--out", str(out)], work, timeout).code or 0)
    time.sleep(2.0)
    second = run_bomi([*THREE_TRIALS, "--out", str(out)], work, timeout)
    _, status = os.waitpid(pid, 0)
    replays = [replayable(out, k, work, timeout) for k in (1, 2, 3)]
    first_ok = os.waitstatus_to_exitcode(status) == 0 and all(r.code == 0 for r in replays)
    late = (f"refused only after {second.seconds:.0f} s (its session ran; no lock taken before calibration)"
            if second.code != 0 and second.seconds > LOCK_WITHIN_S else "")
    return outcome_of([*replays, second], "refuse", lost=not first_ok, wrong=late)


def trial_full_disk(work: Path, bases: Bases, timeout: float) -> dict:
    out = work / "o"
    ran = run_bomi([*THREE_TRIALS, "--out", str(out)], work, timeout, fsize=200_000)
    return outcome_of([ran], "refuse")


# ------------------------------------------------------------------------------------ the corpus
def corpus() -> list[Case]:
    def keep(records):
        return [json.dumps(r) for r in records]
    replay = [
        Case("trials.jsonl line a JSON list", "replay", jsonl_case(lambda rs: ["[1, 2]", *keep(rs)[1:]])),
        Case("trials.jsonl line not JSON", "replay", jsonl_case(lambda rs: ["{trial: 1", *keep(rs)[1:]])),
        Case("record without operator", "replay",
             jsonl_case(lambda rs: [json.dumps({k: v for k, v in rs[0].items() if k != "operator"}), *keep(rs)[1:]])),
        Case("operator ../outside/evil", "replay",
             jsonl_case(lambda rs: [json.dumps(rs[0] | {"operator": "../outside/evil"}), *keep(rs)[1:]])),
        Case("trial number as text", "replay",
             jsonl_case(lambda rs: [json.dumps(rs[0] | {"trial": "1"}), *keep(rs)[1:]])),
        Case("a trial recorded twice", "replay", jsonl_case(lambda rs: [*keep(rs), keep(rs)[0]])),
        Case("trials.jsonl not UTF-8", "replay", files_case(lambda d, b: (d / "trials.jsonl").write_bytes(b"\xff\xfe\x00"))),
        Case("trials.jsonl a link outside", "replay", files_case(outside_link("trials.jsonl"))),
        Case("bomi.h5 a link outside", "replay", files_case(outside_link("bomi.h5"))),
        Case("plan with an extra key", "replay", h5_case(edit_plan)),
        Case("unknown layout", "replay", h5_case(set_attr("layout", "9-axis"))),
        Case("unknown controller", "replay", h5_case(set_attr("controller", "telepathy"))),
        Case("neutral not JSON", "replay", h5_case(set_attr("neutral", "{oops"))),
        Case("neutral a list", "replay", h5_case(set_attr("neutral", "[1, 2, 3]"))),
        Case("neutral of other nodes", "replay",
             h5_case(set_attr("neutral", json.dumps({"7": [0, 0, 0]}))), ),
        Case("dt another rate", "replay", h5_case(set_attr("dt", 0.01))),
        Case("stick_columns reordered", "replay",
             h5_case(set_attr("stick_columns", json.dumps(["B", "F", "R", "L", "Rr", "Lr"])), trial=2,
                     file="joystick.h5")),
        Case("ticks/t cut short", "replay", h5_case(replace_column("ticks/t", lambda v: v[:10]))),
        Case("ticks/t going back", "replay", h5_case(replace_column("ticks/t", lambda v: v[::-1].copy()))),
        Case("go_tick 1e9", "replay", h5_case(replace_column("trials/go_tick", lambda v: v * 0 + 10 ** 9))),
        Case("end_tick before go_tick", "replay",
             h5_case(replace_column("trials/end_tick", lambda v: v * 0 + 1))),
        Case("frames/tick beyond the ticks", "replay",
             h5_case(replace_column("frames/tick", lambda v: v + 10 ** 6))),
        Case("decisions/frame_row beyond the frames", "replay",
             h5_case(replace_column("decisions/frame_row", lambda v: v + 10 ** 6)), ),
        Case("byte_end beyond the stream", "replay",
             h5_case(replace_column("ticks/byte_end", lambda v: v * 2))),
        Case("stick NaN", "replay", h5_case(replace_column("ticks/stick", lambda v: v * np.nan), trial=2,
                                            file="joystick.h5")),
        Case("stick as text", "replay", h5_case(replace_column("ticks/stick", lambda v: np.full(len(v), "x", "S1")),
                                                trial=2, file="joystick.h5")),
        Case("trials group missing", "replay", h5_case(lambda f: f.__delitem__("trials"))),
        Case("bomi.h5 truncated (a full disk)", "replay",
             files_case(lambda d, b: (d / "bomi.h5").write_bytes((d / "bomi.h5").read_bytes()[:100_000]))),
        Case("bomi.h5 empty", "replay", files_case(lambda d, b: (d / "bomi.h5").write_bytes(b""))),
        Case("profile without class 8 (the model's)", "replay", files_case(drop_class_8)),
        Case("profile with F and B swapped", "replay", files_case(swap_f_b)),
        Case("another person's model and profile", "replay", files_case(other_person)),
        Case("another person's model, re-scoring", "replay", rescore_other),
        Case("two sessions mixed (trials.jsonl of another)", "replay", files_case(mixed)),
        Case("--seed 99999999999999999999", "trial", huge_seed),
        Case("a good session replays (control)", "replay", good_replay),
    ]
    twin = [
        Case("two people in one twin call", "twin", two_people),
        Case("a constant sensor", "twin", twin_then_synth(dead("constant"))),
        Case("a zero sensor", "twin", twin_then_synth(dead("zero"))),
        Case("a saturated sensor", "twin", twin_then_synth(dead("saturated"))),
        Case("labels 1e9 (profile derived)", "twin", twin_then_synth(labels_1e9, ())),
        Case("time reversed (profile derived)", "twin", twin_then_synth(time_reversed, ())),
        Case("a good twin passes synth (control)", "twin", twin_then_synth(None)),
        Case("posture 1e5 deg, synth", "twin", huge_posture("synth")),
        Case("posture 1e5 deg, run-task", "twin", huge_posture("run-task")),
    ]
    config = [
        Case("[human] model relative to the operator file", "config", operator_human_beside),
        Case("grid participant ../../../tmp/x", "sweep", grid_outside),
        Case("--jobs 10000", "sweep", jobs_unbounded),
        Case("--address 127.0.0.1:1 (no Ray there)", "sweep", ray_dead_address),
        Case("edited twin reruns, resumed elsewhere does not", "sweep", edited_twin_reruns),
        Case("a full disk during a sweep", "sweep", sweep_full_disk),
    ]
    writer = [
        Case("kill -9 during trial 2 keeps trial 1", "trial", killed_in_trial_2(signal.SIGKILL)),
        Case("SIGTERM during trial 2 keeps trial 1", "trial", killed_in_trial_2(signal.SIGTERM)),
        Case("SIGHUP during trial 2 keeps trial 1", "trial", killed_in_trial_2(signal.SIGHUP)),
        Case("SIGINT during trial 2 keeps trial 1", "trial", killed_in_trial_2(signal.SIGINT)),
        Case("--force over a session, killed in trial 1", "trial", force_over_finished),
        Case("--resume after kill -9", "trial", resume_after_kill),
        Case("a second session on the same --out", "trial", second_session_same_out),
        Case("a full disk during a session", "trial", trial_full_disk),
    ]
    return replay + twin + config + writer


def make_bases(work: Path, timeout: float) -> Bases:
    bases = Bases(work / "session", work / "p4", work / "p1.csv", work / "p4.csv")
    for argv in ([*SESSION, "--out", str(bases.session)], [*P4_SESSION, "--out", str(bases.p4)],
                 ["synth", "--participant", "P1", "--seed", "0", "--out", str(bases.p1_csv)],
                 ["synth", "--participant", "P4", "--seed", "0", "--out", str(bases.p4_csv)]):
        ran = run_bomi(argv, work, timeout)
        if ran.code != 0:
            raise SystemExit(f"base {' '.join(argv)} failed: {ran.err.strip()[-500:]}")
    return bases


def session_main(args: argparse.Namespace) -> None:
    """The session fault corpus: every case made and run."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    cases = corpus()
    if args.only:
        wanted = set(args.only.split(","))
        cases = [c for c in cases if c.name in wanted]
    start = time.monotonic()
    results = []
    with tempfile.TemporaryDirectory(prefix="bomi-session-faults-") as tmp:
        bases = make_bases(Path(tmp), args.timeout)
        for case in cases:
            work = Path(tempfile.mkdtemp(dir=tmp))
            try:
                result = case.run(work, bases, args.timeout)
            except Exception as exc:  # the corpus's own fault: said, never counted as ok
                result = {"outcome": "corpus error", "exit": None, "last_line": f"{type(exc).__name__}: {exc}",
                          "seconds": 0}
            results.append({"case": case.name, "group": case.group, **result})
            print(f"{result['outcome']:>17}  {case.name}: {result['last_line'][:140]}", flush=True)
            shutil.rmtree(work, ignore_errors=True)
    write_results(results, time.monotonic() - start, args)


OUTCOMES = ("ok", "traceback", "hang", "nonsense accepted", "trials lost", "other", "corpus error")


def write_results(results: list[dict], wall_s: float, args) -> None:
    total = Counter(r["outcome"] for r in results)
    lines = ["# Session fault corpus (issue 40)", "",
             f"`python benchmarks/faults.py session{' --only ' + args.only if args.only else ''}`: {len(results)} "
             f"cases, {wall_s / 60:.1f} min on this machine; each command is `python -m tasks.cli` in its own process "
             "on files made in a temporary directory (outcome classes in the script's docstring).", "",
             "| cases | " + " | ".join(OUTCOMES) + " |", "|---|" + "---:|" * len(OUTCOMES),
             "| all | " + " | ".join(str(total[o]) for o in OUTCOMES) + " |",
             "",
             "| case | group | outcome | exit | s | last stderr line (or what was wrong) |",
             "|---|---|---|---:|---:|---|"]
    for r in results:
        line = r["last_line"].replace("|", "\\|")
        lines.append(f"| {r['case']} | {r['group']} | {r['outcome']} | "
                     f"{r['exit']} | {r['seconds']} | `{line}` |")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "session_faults.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:8]))


# ================================================================================= live
# The live loop's safety bars (issue 27), measured end to end: a virtual participant's raw samples as
# base-station frames on a pseudo-terminal -> StreamReader -> LiveLoop -> the simulated arm.
#
#     python benchmarks/faults.py live --seeds 11000 [--participants P1 P4] [--out benchmarks/results/live_safety.md]
#
# Per seed and participant: the participant is calibrated (a model trained on their own calibration
# session of that seed, as `bomi record --train` would give), then sits facing the seed's heading:
# - neutral: holds the neutral posture 40 s; share of ticks with the arm at rest after warm-up and calibration;
# - lost: holds F (the arm moving) when the emulator process (`bomi emulate`) is killed; ticks after the
#   last frame, time to rest, and the loop's wall time (start to the reader's end) against its duration;
# - zero / saturated: node 1's frames turn all-zero (or +32767, -32768, a saturated gyroscope) while F is
#   held; time from the tick that read the first such frame to the arm at rest;
# - corrupt: the calibration protocol (every class, B1/B2 included) played clean and with
#   `bomi emulate --corrupt 0.002`, same seed; mode switches of each run (the corrupted run's must all be
#   in the clean one: the same mode within 1.5 s);
# - flood: from 6 s into the F hold the samples come as fast as the pty takes them: the loop's rate,
#   what the status says, and the arm (at rest on every tick of the flood, after its first second);
# - video: `bomi live --video` on the neutral hold: the loop's rate (ticks per second after the first 2 s;
#   the bar: >= 59.5 Hz) and missed periods, beside the same run without --video.
WARM_S = 14.0        # neutral hold before the first motion: the filter settles, then the neutral is taken


def cues_neutral_then(label: int, until_s: float, at_s: float = WARM_S) -> list[Cue]:
    cues = [Cue(NEUTRAL_LABEL, "neutral", 0.0, at_s)]
    if label != NEUTRAL_LABEL:
        cues.append(Cue(label, "motion", at_s, until_s))
    return cues


def class_of(profile, function: str) -> int:
    return next(cls.label for cls in profile.classes if cls.function == function)


def model_for(name: str, seed: int, work: Path) -> Path:
    """The participant's own model: trained on their calibration session of ``seed`` (`bomi record --amplitudes 1 0.5`)."""
    path = work / f"{name}-{seed}.json"
    if not path.exists():
        params, profile = load_participant(name), arm_profile(name)
        session = calibration_session(params, profile, seed, repetitions=1, hold_s=2.0, neutral_s=2.0,
                                      amplitudes=(1.0, 0.5))   # full and half motions: nu spans the range
        save_model(path, train([session_recording(session, profile)], profile))
    return path


def at_rest(record: dict) -> bool:
    return not any(record["linear"]) and not any(record["angular"]) and record["finger"] == 0


def run_in_process(name: str, seed: int, model: Path, blocks, duration_s: float,
                   flood_from_s: float | None = None) -> list[dict]:
    """Play ``blocks`` on a pty and run the live loop on it; every tick's record with its frames' raw values.
    ``flood_from_s``: from then on the samples are sent as fast as the pty takes them."""
    sink = PtySink(linger_s=1.0)
    chunks = block_chunks(blocks, EmulatorConfig(seed=seed), EmulatorStats())
    if flood_from_s is not None:
        chunks = ((min(t, flood_from_s), data) for t, data in chunks)
    thread = threading.Thread(target=lambda: (sink.wait_for_reader(), play(chunks, sink), sink.finish()), daemon=True)
    thread.start()
    records, _ = live_on(sink.description, name, model, duration_s)
    thread.join(timeout=5)
    return records


def live_on(port: str, name: str, model: Path, duration_s: float) -> tuple[list[dict], float]:
    """The live loop on ``port`` for ``duration_s``: every tick's record (with its frames' raw values),
    and the wall time from the loop's start to the reader's end."""
    profile = arm_profile(name)
    sim = ArmSim(layout=profile_layout(profile))
    records: list[dict] = []

    def observe(tick) -> None:
        record = tick.record()
        record["raw"] = [list(frame.mag + frame.gyro + frame.acc) for frame in tick.imu]
        records.append(record)

    loop = LiveLoop(OnlineChain(load_model(model), profile), sim, observers=[observe])
    reader = StreamReader(SerialSource(port, log=lambda message: None))
    with reader:
        start = time.monotonic()
        loop.run(reader, duration_s=duration_s)
    wall = time.monotonic() - start
    sim.close()
    return records, wall


def live_cli(port: str, name: str, model: Path, log: Path, duration_s: float, *extra: str) -> float:
    """`bomi live` in a subprocess; its wall time."""
    start = time.monotonic()
    subprocess.run([sys.executable, "-m", "tasks.cli", "live", "--port", port, "--profile", name, "--model",
                    str(model), "--headless", "--duration", f"{duration_s:g}", "--log", str(log), *extra],
                   check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.monotonic() - start


def emulator(name: str, seed: int, *extra: str) -> tuple[subprocess.Popen, str]:
    process = subprocess.Popen([sys.executable, "-m", "tasks.cli", "emulate", "--participant", name, "--to", "pty",
                                "--seed", str(seed), *extra], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               text=True)
    return process, process.stdout.readline().strip()


def read_log(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


# ------------------------------------------------------------------------------------------ bars
def neutral_bar(name: str, seed: int, model: Path) -> dict:
    params, profile = load_participant(name), arm_profile(name)
    blocks = participant_blocks(params, profile, seed, cues_neutral_then(NEUTRAL_LABEL, 0.0, 40.0), 40.0)
    records = run_in_process(name, seed, model, blocks, 38.0)
    calibrated = next(k for k, r in enumerate(records) if "neutral" in r)
    after = records[calibrated + 1:]
    return {"ticks": len(after), "rest": float(np.mean([at_rest(r) for r in after])),
            "warm_s": max(r["t"] for r in records if (r["hold"] or "").startswith("warming")),
            "neutral_s": records[calibrated]["t"]}


def bad_values_bar(name: str, seed: int, model: Path, bad: str, inject_s: float = WARM_S + 6.0) -> dict:
    """Node 1's frames replaced by ``bad`` values from ``inject_s`` (emulator time) while F is held."""
    params, profile = load_participant(name), arm_profile(name)
    values = {"zero": [0] * 9, "+32767": [32767] * 9, "-32768": [-32768] * 9}
    blocks = participant_blocks(params, profile, seed, cues_neutral_then(class_of(profile, "F"), 40.0), 30.0)

    def spoiled():
        t = 0
        for block in blocks:
            rows = len(next(iter(block.values())))
            times = (t + np.arange(rows)) * 0.016
            node1 = block[1].copy()
            hit = times >= inject_s
            if bad == "gyro saturated":
                node1[hit, 3:6] = 32767
            else:
                node1[hit] = values[bad]
            block = {**block, 1: node1}
            t += rows
            yield block

    records = run_in_process(name, seed, model, spoiled(), 27.0)
    first = next(k for k, r in enumerate(records) if any(
        (raw[3:6] == [32767] * 3) if bad == "gyro saturated" else raw == values[bad] for raw in r["raw"]))
    moving = not at_rest(records[first - 1])
    rest = next(k for k in range(first, len(records)) if at_rest(records[k]))
    still = all(at_rest(r) for r in records[rest:])
    return {"moving_before": moving, "rest_after_s": records[rest]["t"] - records[first]["t"],
            "held_to_end": still, "hold": records[rest]["hold"]}


def lost_bar(name: str, seed: int, model: Path, duration_s: float = 26.0) -> dict:
    process, port = emulator(name, seed, "--neutral", f"{WARM_S:g}", "--hold", "30")   # F from WARM_S on
    killer = threading.Timer(WARM_S + 8.0, process.kill)
    killer.start()
    ticks, wall = live_on(port, name, model, duration_s)
    killer.cancel()
    process.kill()
    last = max(k for k, r in enumerate(ticks) if r["frames"])
    moving = not at_rest(ticks[last])
    rest = next(k for k in range(last, len(ticks)) if at_rest(ticks[k]))
    gaps = np.diff([r["t"] for r in ticks[last:]])
    return {"moving_at_loss": moving, "rest_after_s": ticks[rest]["t"] - ticks[last]["t"],
            "ticks_after": len(ticks) - last - 1, "max_tick_gap_s": float(gaps.max()) if len(gaps) else 0.0,
            "all_rest_after": all(at_rest(r) for r in ticks[rest:]), "wall_s": wall, "duration_s": duration_s}


def flood_bar(name: str, seed: int, model: Path, flood_s: float = WARM_S + 6.0) -> dict:
    """From ``flood_s`` on (F held) the participant's samples arrive as fast as the pty takes them."""
    params, profile = load_participant(name), arm_profile(name)
    blocks = participant_blocks(params, profile, seed, cues_neutral_then(class_of(profile, "F"), 3000.0), 3000.0)
    records = run_in_process(name, seed, model, blocks, flood_s + 6.0, flood_from_s=flood_s)
    before = [r for r in records if flood_s - 3 < r["t"] < flood_s]
    during = [r for r in records if r["t"] > flood_s + 1.0]
    rate = (len(during) - 1) / (during[-1]["t"] - during[0]["t"])
    per_node = sum(r["frames"] for r in during) / (during[-1]["t"] - during[0]["t"]) / len(profile.nodes)
    return {"moving_before": any(not at_rest(r) for r in before), "rate_hz": rate, "frames_hz": per_node,
            "rest": float(np.mean([at_rest(r) for r in during])),
            "holds": sorted({r["hold"] for r in during if r["hold"]})[:2],
            "status_rate_hz": min(r["loop_hz"] for r in during)}


def switches(ticks: list[dict]) -> list[tuple[float, str]]:
    return [(b["t"], b["mode"]) for a, b in zip(ticks, ticks[1:]) if a["mode"] != b["mode"]]


def corrupt_bar(name: str, seed: int, model: Path, work: Path, duration_s: float = 75.0) -> dict:
    runs = {}
    for corrupt in ("0", "0.002"):
        process, port = emulator(name, seed, "--neutral", "3", "--hold", "3", "--corrupt", corrupt)
        log = work / f"corrupt-{corrupt}-{name}-{seed}.jsonl"
        log.unlink(missing_ok=True)
        live_cli(port, name, model, log, duration_s)
        process.kill()
        ticks = read_log(log)
        runs[corrupt] = {"switches": switches(ticks), "held": float(np.mean([r["hold"] is not None for r in ticks]))}
    clean = runs["0"]["switches"]
    extra = [(t, mode) for t, mode in runs["0.002"]["switches"]
             if not any(m == mode and abs(t - u) <= 1.5 for u, m in clean)]
    return {"clean": len(clean), "corrupt": len(runs["0.002"]["switches"]), "extra": len(extra),
            "held_clean": runs["0"]["held"], "held_corrupt": runs["0.002"]["held"]}


def loop_rate(ticks: list[dict], after_s: float = 2.0) -> tuple[float, int, float]:
    """Ticks per second after the first ``after_s``, periods missed, lowest 1-s rate."""
    t = np.array([r["t"] for r in ticks])
    steady = t > after_s
    return (float((steady.sum() - 1) / (t[steady][-1] - t[steady][0])), ticks[-1]["overruns"],
            min(r["loop_hz"] for r in ticks if r["t"] > after_s))


def video_bar(name: str, seed: int, model: Path, work: Path, duration_s: float = 25.0) -> dict:
    """The loop's rate with --video, and without it on the same stream (the machine's own share)."""
    out = {}
    for filmed in (False, True):
        process, port = emulator(name, seed, "--neutral", "30", "--hold", "2")
        log, video = work / f"video-{filmed}-{name}-{seed}.jsonl", work / f"video-{name}-{seed}.mp4"
        log.unlink(missing_ok=True)
        video.unlink(missing_ok=True)
        live_cli(port, name, model, log, duration_s, *(("--video", str(video)) if filmed else ()))
        process.kill()
        out[filmed] = loop_rate(read_log(log))
    return {"rate_hz": out[True][0], "overruns": out[True][1], "min_loop_hz": out[True][2],
            "plain_rate_hz": out[False][0], "plain_overruns": out[False][1],
            "film_bytes": video.stat().st_size if video.exists() else 0}


Row = tuple[str, str, bool]   # bar, measured, met


def neutral_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = neutral_bar(name, seed, model)
    return [("neutral hold: arm at rest after calibration", f"{100 * r['rest']:.1f} % of {r['ticks']} ticks "
             f"(settled at {r['warm_s']:.1f} s, neutral at {r['neutral_s']:.1f} s)", r["rest"] >= 0.95)]


def bad_rows(name: str, seed: int, model: Path) -> list[Row]:
    rows = []
    for bad in ("zero", "+32767", "-32768", "gyro saturated"):
        r = bad_values_bar(name, seed, model, bad)
        rows.append((f"node 1 {bad}: arm at rest after the first such frame",
                     f"{1000 * r['rest_after_s']:.0f} ms (moving before: {r['moving_before']}, held to the end: "
                     f"{r['held_to_end']}, status: {r['hold']})",
                     r["rest_after_s"] <= 0.1 and r["moving_before"] and r["held_to_end"]))
    return rows


def flood_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = flood_bar(name, seed, model)
    return [("flood (samples as fast as the pty takes them): not silent, arm at rest",
             f"{r['frames_hz']:.0f} frames/s per node; loop {r['rate_hz']:.1f} Hz (status and log say "
             f"{r['status_rate_hz']:.0f} Hz at the lowest), arm at rest {100 * r['rest']:.0f} % of the "
             f"flood's ticks (moving before: {r['moving_before']}), status: {'; '.join(r['holds'])}",
             r["rest"] == 1.0 and r["moving_before"])]


def lost_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = lost_bar(name, seed, model)
    return [("emulator killed: ticks go on, rest, --duration kept",
             f"rest {1000 * r['rest_after_s']:.0f} ms after the last frame (moving: {r['moving_at_loss']}), "
             f"{r['ticks_after']} ticks after it (largest gap {1000 * r['max_tick_gap_s']:.0f} ms), "
             f"wall {r['wall_s']:.1f} s for --duration {r['duration_s']:g}",
             r["rest_after_s"] <= 0.1 and r["moving_at_loss"] and r["all_rest_after"]
             and r["max_tick_gap_s"] < 0.1 and abs(r["wall_s"] - r["duration_s"]) <= 1.0)]


def corrupt_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = corrupt_bar(name, seed, model, model.parent)
    return [("--corrupt 0.002: mode switches the clean stream does not have",
             f"{r['extra']} (clean {r['clean']} switches, corrupted {r['corrupt']}; arm held "
             f"{100 * r['held_clean']:.0f} % / {100 * r['held_corrupt']:.0f} % of ticks)", r["extra"] == 0)]


def video_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = video_bar(name, seed, model, model.parent)
    return [("live --video: control rate",
             f"{r['rate_hz']:.2f} Hz, {r['overruns']} periods missed, lowest 1-s rate {r['min_loop_hz']:.0f} Hz "
             f"(film {r['film_bytes']} bytes; without --video: {r['plain_rate_hz']:.2f} Hz, "
             f"{r['plain_overruns']} missed)", r["rate_hz"] >= 59.5)]


# bar -> (rows, for every participant or the first only)
BARS = {"neutral": (neutral_rows, True), "bad": (bad_rows, True), "flood": (flood_rows, False),
        "lost": (lost_rows, False), "corrupt": (corrupt_rows, False), "video": (video_rows, False)}


def live_main(args: argparse.Namespace) -> None:
    """The live loop's safety bars, end to end."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for seed in args.seeds:
            for name in args.participants:
                model = model_for(name, seed, work)
                heading = session_heading(seed)
                print(f"{name} seed {seed} (heading {heading:.0f} deg)", file=sys.stderr, flush=True)
                for bar in args.bars:
                    function, everyone = BARS[bar]
                    if everyone or name == args.participants[0]:
                        for row in function(name, seed, model):
                            rows.append((name, seed, *row))
                            print(rows[-1], file=sys.stderr, flush=True)
    lines = [f"# Live loop safety (`python benchmarks/faults.py live --seeds {' '.join(map(str, args.seeds))} "
             f"--participants {' '.join(args.participants)}`)", "",
             f"Machine: {os.cpu_count()} cores, shared. Every run is real time (62.5 Hz frames on a pty, 60 Hz ticks).", "",
             "| participant | seed | bar | measured | met |", "|---|---|---|---|---|"]
    lines += [f"| {n} | {s} | {bar} | {value} | {'yes' if ok else 'NO'} |" for n, s, bar, value, ok in rows]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    groups = parser.add_subparsers(dest="group", required=True)
    bad = groups.add_parser("bad-input", help="damaged files and bad option values through every command")
    bad.add_argument("--per-kind", type=int, default=40, help="damaged files per kind of file (default 40)")
    bad.add_argument("--seed", type=int, default=0)
    bad.add_argument("--timeout", type=float, default=180.0)
    bad.set_defaults(run=bad_input_main)
    session = groups.add_parser("session", help="the session fault corpus")
    session.add_argument("--timeout", type=float, default=300.0, help="seconds a command may run (default 300)")
    session.add_argument("--only", help="comma-separated case names (default: every case)")
    session.set_defaults(run=session_main)
    live = groups.add_parser("live", help="the live loop's safety bars, end to end")
    live.add_argument("--seeds", type=int, nargs="+", required=True)
    live.add_argument("--participants", nargs="+", default=["P1", "P4"])
    live.add_argument("--bars", nargs="+", choices=sorted(BARS), default=list(BARS))
    live.add_argument("--out", type=Path, default=RESULTS / "live_safety.md")
    live.set_defaults(run=live_main)
    args = parser.parse_args()
    args.run(args)


if __name__ == "__main__":
    main()
