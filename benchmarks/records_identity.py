"""Did a change alter the task's episodes?  Two commits run the same development episodes on this
machine, each through its own command line, and their stored records are compared field for field.

    python benchmarks/records_identity.py BEFORE [AFTER] [--seeds N]   # AFTER: this working tree
    python benchmarks/records_identity.py --no-jit [COMMIT] [--seeds N]

BEFORE (and AFTER, when given) is checked out into a temporary ``git worktree`` (removed
afterwards, on error and on Ctrl-C too); without AFTER the other side is this working tree as it
is, uncommitted changes included.  Each side runs its own `bomi benchmark` (``python -m tasks.cli
benchmark --participants P1,P4,P5 --operators joystick,bomi --seeds N --first-seed 0 --jobs 1
--json FILE``) in a subprocess whose cwd and PYTHONPATH are its tree, with the same Python
environment and one BLAS thread, one side after the other; nothing of either side is imported
here, so the comparison holds across any change of the code's layout, as long as both commits have
that command.  The episodes: virtual P1, P4 and P5 on the BoMI (calibration, LDA training and
task), and the joystick once per set of controls (P1's; P4's, which P5 shares: what `bomi
benchmark` runs), task seeds 0..N-1 (development seeds; N=5 by default: 25 episodes a side).

What is compared: every field of each stored per-episode record (``tasks.stacking.episode.
summarize``) but the timing ones (wall and CPU time, the real-time factors).  The records of
5eff363 carry no digest of the logged trajectories, so the trajectories themselves are not
compared; what is, is already a fingerprint of the episode to the last bit: the completion and
simulated times, the unintended displacement, the decisions' accuracies, every onset's latency,
the recoveries and the mode switches (JSON floats round-trip exactly).  Writes
benchmarks/results/records_identity.md (the two commits, the machine, "identical: yes/NO" and
every differing field); exits 1 if any differ.

What "identical" means.  The same build on the same machine (same CPU features, the same glibc
libm, the same numpy and BLAS code paths) gives bit-identical records: that is what this script
checks between two commits, and what tests/test_reproducibility.py checks within one.  It does
not hold across machines: glibc's libm, numpy and OpenBLAS choose FMA, AVX2 or AVX-512 code
paths at run time by the CPU, so the last bit of a sin, an exp or a dot product depends on the
CPU; nor between the numba kernels and their Python forms (``BOMI_NO_JIT=1``), whose operations
are rounded in another order.  The stacking task is chaotic (one last bit becomes another
episode), so there only distributions hold: ``--no-jit`` runs COMMIT (default: this working tree)
compiled and with ``BOMI_NO_JIT=1`` and compares, per operator over all its episodes, the success
rate (Fisher's exact test) and the completion time of the successful episodes (Mann-Whitney U),
both two-sided at the 5 % level, with benchmarks/comparisons.py's ``compare``; it writes
benchmarks/results/records_identity_no_jit.md and exits 1 if either test rejects.

Bad input (not a git checkout, an unknown commit, a commit whose command line lacks `bomi
benchmark --json`, --seeds outside 1-1000) is one ``bomi: error:`` line and exit 2, before any
episode runs; a side whose run fails later is one such line too.  Ctrl-C: "bomi: interrupted", exit 130.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from importlib.metadata import version
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
TIMING_FIELDS = ("wall_time", "cpu_time", "realtime_factor", "realtime_factor_cpu")
PARTICIPANTS = ("P1", "P4", "P5")
OPERATORS = ("joystick", "bomi")
DEVELOPMENT_SEEDS = 1000  # task seeds 0-999; the seeds above are held out
ALPHA = 0.05  # the --no-jit tests' level (two-sided)
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


class Failed(Exception):
    """Bad input or a side that cannot run: one ``bomi: error:`` line."""


# ------------------------------------------------------------------------------ the two trees
class Side(NamedTuple):
    """The code one side runs: its name in the tables, what it is, its tree, its environment additions."""

    name: str
    label: str
    path: Path
    env: tuple[tuple[str, str], ...] = ()

    def environment(self) -> dict[str, str]:
        return os.environ | ONE_THREAD | dict(self.env) | {"PYTHONPATH": str(self.path)}


def git(*args: str) -> str:
    done = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise Failed(done.stderr.strip().splitlines()[-1] if done.stderr.strip() else f"git {args[0]} failed")
    return done.stdout.strip()


def check_git_checkout() -> None:
    try:
        git("rev-parse", "--show-toplevel")
    except (Failed, FileNotFoundError) as exc:
        raise Failed(f"{ROOT}: not a git checkout (records_identity checks commits out with git "
                     f"worktree): {exc}") from None


def resolve(name: str, what: str) -> str:
    """The full hash of commit ``name``."""
    try:
        return git("rev-parse", "--verify", "--quiet", f"{name}^{{commit}}")
    except Failed:
        raise Failed(f"{what}: {name!r} is not a commit of {ROOT}") from None


def describe(sha: str) -> str:
    sha_date, subject = git("log", "-1", "--format=%h (%ad)%n%s", "--date=short", sha).split("\n", 1)
    return f"{sha_date} {subject[:90]}{'...' if len(subject) > 90 else ''}"


def working_tree() -> Side:
    changed = ", with uncommitted changes" if git("status", "--porcelain", "--untracked-files=no") else ""
    return Side("after", f"working tree at {describe('HEAD')}{changed}", ROOT)


@contextlib.contextmanager
def checked_out(name: str, sha: str) -> Iterator[Side]:
    """Commit ``sha`` in a temporary detached worktree, removed on the way out whatever happens."""
    with tempfile.TemporaryDirectory(prefix="records_identity_") as tmp:
        path = Path(tmp) / sha[:12]
        git("worktree", "add", "--detach", "--quiet", str(path), sha)
        try:
            yield Side(name, describe(sha), path)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(path)], capture_output=True)


def benchmark_command(seeds: int, out: Path) -> list[str]:
    return [sys.executable, "-m", "tasks.cli", "benchmark", "--participants", ",".join(PARTICIPANTS),
            "--operators", ",".join(OPERATORS), "--seeds", str(seeds), "--first-seed", "0", "--jobs", "1",
            "--json", str(out)]


def check_side(side: Side) -> None:
    """The side's packages import from its tree, and its `bomi benchmark` has the options used (before any episode)."""
    where = subprocess.run([sys.executable, "-c", "import bomi, sim, tasks; print(bomi.__file__, sim.__file__, "
                            "tasks.__file__)"], env=side.environment(), cwd=side.path, capture_output=True, text=True)
    tree = side.path.resolve()
    if where.returncode != 0 or not all(tree in Path(f).resolve().parents for f in where.stdout.split()):
        raise Failed(f"{side.label}: its packages do not import from {tree}: {where.stdout.strip() or where.stderr}")
    usage = subprocess.run([sys.executable, "-m", "tasks.cli", "benchmark", "--help"], env=side.environment(),
                           cwd=side.path, capture_output=True, text=True).stdout
    missing = [o for o in benchmark_command(1, Path("x"))[4:] if o.startswith("--") and o not in usage]
    if missing:
        raise Failed(f"{side.label}: its `bomi benchmark` lacks {', '.join(missing)}")


def episode_key(record: dict) -> str:
    return f"{record['participant']} {record['operator']} seed {record['seed']}"


def stored_records(episodes: list[dict]) -> dict[str, dict]:
    """The records of a `bomi benchmark --json` file by episode, without their timing fields."""
    return {episode_key(r): {k: v for k, v in r.items() if k not in TIMING_FIELDS} for r in episodes}


def run_side(side: Side, seeds: int) -> dict[str, dict]:
    """The records of one side, from its own `bomi benchmark` run."""
    with tempfile.TemporaryDirectory(prefix="records_identity_out_") as tmp:
        out = Path(tmp) / "benchmark.json"
        print(f"{side.name}: {' '.join(benchmark_command(seeds, out)[1:])} in {side.path}", file=sys.stderr)
        with tempfile.TemporaryFile("w+") as errors:
            done = subprocess.run(benchmark_command(seeds, out), env=side.environment(), cwd=side.path,
                                  stdout=subprocess.DEVNULL, stderr=errors, text=True)
            if done.returncode != 0 or not out.exists():
                errors.seek(0)
                last = [line for line in errors.read().splitlines() if line.strip()]
                raise Failed(f"{side.label}: its benchmark failed (exit {done.returncode}): {(last or [''])[-1]}")
        return stored_records(json.loads(out.read_text())["episodes"])


# -------------------------------------------------------------------------------- comparing
def canonical(value) -> str:
    """A field as its JSON text (NaN equals NaN; 1 and 1.0 differ, as they would in a results file)."""
    return json.dumps(value, sort_keys=True)


def differences(before: dict[str, dict], after: dict[str, dict]) -> list[str]:
    """``episode: field: before -> after`` for every field that differs or is on one side only."""
    lines = []
    for key in sorted(before.keys() | after.keys()):
        if key not in before or key not in after:
            lines.append(f"{key}: run {'before' if key in before else 'after'} only")
            continue
        a, b = before[key], after[key]
        for field in sorted(a.keys() | b.keys()):
            if field not in a or field not in b or canonical(a[field]) != canonical(b[field]):
                lines.append(f"{key}: {field}: {a.get(field, '(absent)')!r} -> {b.get(field, '(absent)')!r}")
    return lines


def same_episode(key: str, records: list[dict[str, dict]]) -> bool:
    return not differences(*({key: r[key]} if key in r else {} for r in records))


def machine() -> str:
    """The CPU and the run-time code paths that decide the last bits: libm, numpy SIMD, BLAS kernel."""
    import numpy as np
    from numpy._core._multiarray_umath import __cpu_baseline__, __cpu_dispatch__, __cpu_features__
    from threadpoolctl import threadpool_info

    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        cpu = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                   if line.startswith("model name"))
    found = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    flags = ", ".join(f"{f} {'yes' if __cpu_features__.get(f) else 'no'}" for f in ("FMA3", "AVX2", "AVX512F"))
    blas = "; ".join(f"{lib['internal_api']} {lib['version']} (kernel {lib.get('architecture', '?')})"
                     for lib in threadpool_info() if lib["user_api"] == "blas")
    return (f"{cpu} ({platform.machine()}, {os.cpu_count()} CPUs), {platform.system()} {platform.release()}, "
            f"libc {' '.join(platform.libc_ver()) or '?'}; numpy {np.__version__} SIMD baseline "
            f"{' '.join(__cpu_baseline__)}, dispatch found {' '.join(found) or 'none'} ({flags}); BLAS {blas}; "
            f"numba {version('numba')}, mujoco {version('mujoco')}, Python {platform.python_version()}")


def episode_table(sides: list[Side], records: list[dict[str, dict]]) -> list[str]:
    lines = [f"| episode | success ({sides[0].name} / {sides[1].name}) | completion time s | decisions | same |",
             "|---|---|---|---|---|"]
    for key in records[0]:
        a, b = records[0][key], records[1].get(key, {})
        times = " / ".join(f"{r['completion_time']:.2f}" if r.get("completion_time") is not None else "-"
                           for r in (a, b))
        decisions = " / ".join(str(r.get("decisions", "-")) for r in (a, b))
        same = "yes" if same_episode(key, records) else "NO"
        lines.append(f"| {key} | {a.get('success')} / {b.get('success')} | {times} | {decisions} | {same} |")
    return lines


def scope(records: dict[str, dict], seeds: int) -> str:
    return (f"{len(records)} episodes a side: {', '.join(PARTICIPANTS)} on the BoMI, the joystick once per set of "
            f"controls, task seeds 0-{seeds - 1}, each side through its own `bomi benchmark`; every stored field "
            f"of each record but the timing ones ({', '.join(TIMING_FIELDS)}).")


def identity_report(sides: list[Side], records: list[dict[str, dict]], seeds: int, command: str,
                    minutes: float) -> tuple[str, bool]:
    diff = differences(*records)
    text = "\n".join([
        "# Records of two commits, run on one machine", "", f"`{command}` ({minutes:.1f} min)", "",
        f"- before: {sides[0].label}", f"- after: {sides[1].label}", f"- machine: {machine()}",
        f"- {scope(records[0], seeds)}", "",
        f"**Identical: {'yes' if not diff else 'NO'}** ({len(diff)} differing fields).", "",
        *(f"- {d}" for d in diff), *([""] if diff else []),
        *episode_table(sides, records), "",
        "Identical means bit-identical on this machine with this build (see the script's docstring): on "
        "another CPU both commits may give other episodes, identical or not between themselves."]) + "\n"
    return text, not diff


def no_jit_report(sides: list[Side], records: list[dict[str, dict]], seeds: int, command: str,
                  minutes: float) -> tuple[str, bool]:
    from comparisons import compare  # beside this script; imports scipy

    rows, held = [], True
    for operator in OPERATORS:
        keys = [k for k in records[0] if records[0][k]["operator"] == operator]
        compiled, interpreted = ({i: r[k] for i, k in enumerate(keys)} for r in records)
        if not all(any(e["success"] for e in side.values()) for side in (compiled, interpreted)):
            rows.append(f"| {operator} | {len(keys)} | no success on one side: not compared | | | | |")
            held = False
            continue
        r = compare(compiled, interpreted)
        ok = r["success_p_fisher"] >= ALPHA and r["time_p_mannwhitney"] >= ALPHA
        held &= ok
        rows.append(f"| {operator} | {r['n']} | {r['successes'][0]} / {r['successes'][1]} | "
                    f"{r['success_p_fisher']:.2f} | {r['time_median'][0]:.2f} / {r['time_median'][1]:.2f} | "
                    f"{r['time_p_mannwhitney']:.2f} | {'same distribution not rejected' if ok else 'REJECTED'} |")
    same = sum(same_episode(key, records) for key in records[0])
    text = "\n".join([
        "# Compiled kernels against BOMI_NO_JIT=1, as distributions", "", f"`{command}` ({minutes:.1f} min)", "",
        f"- code: {sides[0].label}", f"- machine: {machine()}", f"- {scope(records[0], seeds)}", "",
        f"Per operator over its episodes (participants pooled, paired by participant and seed): success rate by "
        f"Fisher's exact test, completion time of the successful episodes by Mann-Whitney U, both two-sided at "
        f"the {ALPHA:.0%} level (benchmarks/comparisons.py's `compare`). Bit-identical episodes: "
        f"{same} of {len(records[0])} (not required: the two forms round in another order).", "",
        "| operator | episodes | successes (compiled / no JIT) | Fisher p | completion time median s | "
        "Mann-Whitney p | verdict |", "|---|---|---|---|---|---|---|", *rows, "",
        f"**Same distributions: {'yes' if held else 'NO'}** (a test with this few episodes detects only large "
        f"differences).", "", *episode_table(sides, records)]) + "\n"
    return text, held


# ------------------------------------------------------------------------------------- main
def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("commits", nargs="*", metavar="COMMIT",
                        help="BEFORE [AFTER] (AFTER: this working tree); with --no-jit, [COMMIT]")
    parser.add_argument("--seeds", type=int, default=5, help="task seeds 0..N-1 per cell (default 5; at most 1000)")
    parser.add_argument("--no-jit", action="store_true",
                        help="compare compiled and BOMI_NO_JIT=1 episodes of one commit, as distributions")
    args = parser.parse_args(argv)
    if not 1 <= args.seeds <= DEVELOPMENT_SEEDS:
        raise Failed(f"--seeds: {args.seeds}: give 1-{DEVELOPMENT_SEEDS} (development task seeds 0-999)")
    if not (0 if args.no_jit else 1) <= len(args.commits) <= (1 if args.no_jit else 2):
        raise Failed(f"COMMIT: {' '.join(args.commits) or 'none'}: give "
                     f"{'at most one commit with --no-jit' if args.no_jit else 'BEFORE [AFTER]'}")
    return args


def compare_commits(args: argparse.Namespace, command: str) -> int:
    check_git_checkout()
    names = ("COMMIT",) if args.no_jit else ("BEFORE", "AFTER")
    shas = [resolve(commit, name) for commit, name in zip(args.commits, names)]
    start = time.monotonic()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # the worktrees are removed on kill too
    with contextlib.ExitStack() as stack:
        trees = [stack.enter_context(checked_out(name.lower(), sha)) for name, sha in zip(names, shas)]
        if args.no_jit:
            tree = trees[0] if trees else working_tree()
            sides = [Side("compiled", tree.label, tree.path), Side("no JIT", tree.label, tree.path,
                                                                   (("BOMI_NO_JIT", "1"),))]
        else:
            sides = trees if len(trees) == 2 else [trees[0], working_tree()]
        for side in sides:
            check_side(side)
        records = [run_side(side, args.seeds) for side in sides]
    report = no_jit_report if args.no_jit else identity_report
    text, held = report(sides, records, args.seeds, command, (time.monotonic() - start) / 60)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"records_identity{'_no_jit' if args.no_jit else ''}.md").write_text(text, encoding="utf-8")
    print(text)
    return 0 if held else 1


def main(argv: list[str] | None = None) -> int:
    command = "python benchmarks/records_identity.py " + " ".join(sys.argv[1:] if argv is None else argv)
    try:
        return compare_commits(parse(argv), command)
    except Failed as exc:
        print(f"bomi: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # the worktrees are removed by then
        print("bomi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
