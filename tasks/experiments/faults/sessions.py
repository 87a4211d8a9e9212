"""The human-in-the-loop session's faults (`python benchmarks/faults.py session`): kills, signals, a full
disk, damaged or mixed session files, a stale calibration."""
from __future__ import annotations

import json
import os
import shutil
import signal
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np


from tasks.experiments.faults.runs import ROOT, Ran, run_bomi


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


def run_sessions(timeout: float, only: str | None, results_dir: Path) -> None:
    """The session fault corpus: every case made and run."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    cases = corpus()
    if only:
        wanted = set(only.split(","))
        cases = [c for c in cases if c.name in wanted]
    start = time.monotonic()
    results = []
    with tempfile.TemporaryDirectory(prefix="bomi-session-faults-") as tmp:
        bases = make_bases(Path(tmp), timeout)
        for case in cases:
            work = Path(tempfile.mkdtemp(dir=tmp))
            try:
                result = case.run(work, bases, timeout)
            except Exception as exc:  # the corpus's own fault: said, never counted as ok
                result = {"outcome": "corpus error", "exit": None, "last_line": f"{type(exc).__name__}: {exc}",
                          "seconds": 0}
            results.append({"case": case.name, "group": case.group, **result})
            print(f"{result['outcome']:>17}  {case.name}: {result['last_line'][:140]}", flush=True)
            shutil.rmtree(work, ignore_errors=True)
    write_results(results, time.monotonic() - start, only, results_dir)


OUTCOMES = ("ok", "traceback", "hang", "nonsense accepted", "trials lost", "other", "corpus error")


def write_results(results: list[dict], wall_s: float, only: str | None, results_dir: Path) -> None:
    total = Counter(r["outcome"] for r in results)
    lines = ["# Session fault corpus (issue 40)", "",
             f"`python benchmarks/faults.py session{' --only ' + only if only else ''}`: {len(results)} "
             f"cases, {wall_s / 60:.1f} min on this machine; each command is `python -m tasks.cli` in its own process "
             "on files made in a temporary directory (outcome classes in tasks/experiments/faults/sessions.py).", "",
             "| cases | " + " | ".join(OUTCOMES) + " |", "|---|" + "---:|" * len(OUTCOMES),
             "| all | " + " | ".join(str(total[o]) for o in OUTCOMES) + " |",
             "",
             "| case | group | outcome | exit | s | last stderr line (or what was wrong) |",
             "|---|---|---|---:|---:|---|"]
    for r in results:
        line = r["last_line"].replace("|", "\\|")
        lines.append(f"| {r['case']} | {r['group']} | {r['outcome']} | "
                     f"{r['exit']} | {r['seconds']} | `{line}` |")
    results_dir.mkdir(exist_ok=True)
    (results_dir / "session_faults.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:8]))
