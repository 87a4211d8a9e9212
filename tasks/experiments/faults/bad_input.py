"""Damaged files and bad option values through every command (`python benchmarks/faults.py bad-input`)."""
from __future__ import annotations

import hashlib
import json
import platform
import re
import shutil
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tasks.experiments.faults.runs import ROOT, forked


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


def run_bad_input(per_kind: int, seed: int, timeout: float, results_dir: Path) -> None:
    """Every command on damaged files and bad option values (the `bad-input` corpus)."""
    rng = np.random.default_rng(seed)
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
            for k, (what, data) in enumerate(damages(path.read_bytes(), per_kind, rng, kind != "npz")):
                bad = base_dir / f"bad{k}_{kind}{path.suffix}"  # beside the good files, copied with them per run
                (corpus / bad.name).write_bytes(data)
                runs += [Run(command, kind, what, argv) for command, argv in file_commands(kind, bad, base_dir).items()]
        runs += option_runs(base_dir)
        for p in corpus.iterdir():
            shutil.move(str(p), base_dir / p.name)
        scratch = work / "runs"
        scratch.mkdir()
        results = [execute(r, base_dir, scratch, timeout) for r in tqdm(runs, desc="bad inputs", unit="run")]
    outcomes = ["clean error", "accepted", "traceback", "other", "input changed"]
    by_kind: dict[str, Counter] = {}
    for r in results:
        by_kind.setdefault(r["kind"], Counter())[r["outcome"]] += 1
    total = Counter(r["outcome"] for r in results)
    record = {"benchmark": "bad_input_corpus", "seed": seed, "per_kind": per_kind,
              "python": platform.python_version(), "runs": len(results), "outcomes": dict(total),
              "wall_s": time.monotonic() - start, "results": results}
    results_dir.mkdir(exist_ok=True)
    (results_dir / "bad_input_corpus.json").write_text(json.dumps(record, indent=1) + "\n")
    slow = sorted(results, key=lambda r: -r["seconds"])[:5]
    lines = ["# Bad-input corpus: every command on damaged files and bad option values", "",
             f"`python benchmarks/faults.py bad-input --per-kind {per_kind} --seed {seed}`: "
             f"{len(results)} runs of the command line (`python -m tasks.cli`, each in its own process) on a corpus made in a temporary directory (not in the "
             f"repository), {record['wall_s'] / 60:.1f} min on this machine. Outcome classes in "
             "tasks/experiments/faults/bad_input.py.", "",
             "| bad input | runs | " + " | ".join(outcomes) + " |", "|---|---:|" + "---:|" * len(outcomes)]
    for kind, counts in by_kind.items():
        lines.append(f"| {kind} | {sum(counts.values())} | " + " | ".join(str(counts[o]) for o in outcomes) + " |")
    lines.append(f"| **all** | {len(results)} | " + " | ".join(f"**{total[o]}**" for o in outcomes) + " |")
    lines += ["", "Slowest runs: " + "; ".join(f"{r['command']} ({r['what']}) {r['seconds']:.1f} s" for r in slow)]
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
    (results_dir / "bad_input_corpus.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:len(by_kind) + 8]))
