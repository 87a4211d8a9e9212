"""Bad input, class by class (issue 10): every case is exit 2 with exactly one stderr line
``bomi: error: ...`` naming the file or option, no traceback, every file in the directory unchanged
byte for byte and no temporary file left behind. How long each takes, and a larger corpus made
outside the repository: `python benchmarks/faults.py bad-input`.

Each case runs in a directory holding a tiny P1 recording (950 rows of day 1: classes 0, 2, 4),
a model trained on the whole of day 1 (a P1 model needs every class of the profile, issue 26), and
whatever bad file the case writes.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from bomi.chain import train
from bomi.files import TEMP_MARK
from bomi.frames import ImuFrame, encode_imu_frame
from bomi.model_io import save_model
from bomi.profiles import load_profile
from bomi.recording import NodeData, Recording, read_recording, write_recording
from tasks.cli import main

TINY_ROWS = 950  # day 1 rows 0..949: neutral, c2, neutral, the start of c4


@pytest.fixture(scope="module")
def base(tmp_path_factory, shared_data) -> dict[str, bytes]:
    """name -> bytes of the files every case starts from."""
    day1 = read_recording(shared_data / "day1_testp.mat")
    tiny = Recording({i: NodeData(*(getattr(n, s)[:TINY_ROWS] for s in ("acc", "gyro", "mag", "angles")))
                      for i, n in day1.nodes.items()}, day1.labels[:TINY_ROWS], source="tiny.csv")
    where = tmp_path_factory.mktemp("base")
    write_recording(where / "tiny.csv", tiny)
    save_model(where / "m.json", train([day1], load_profile("P1")))
    return {name: (where / name).read_bytes() for name in ("tiny.csv", "m.json")}


def tiny_text(base) -> str:
    return base["tiny.csv"].decode()


def edited_csv(base, edit: Callable[[list[list[str]]], None]) -> str:
    rows = [line.split(",") for line in tiny_text(base).splitlines()]
    edit(rows)
    return "\n".join(",".join(r) for r in rows) + "\n"


def set_cell(column: str, row: int, value: str) -> Callable[[list[list[str]]], None]:
    def edit(rows):
        rows[row][rows[0].index(column)] = value
    return edit


def drop_node(node: int) -> Callable[[list[list[str]]], None]:
    def edit(rows):
        keep = [j for j, name in enumerate(rows[0]) if not (name[:-1].endswith(str(node)) or f"{node}Raw" in name)]
        rows[:] = [[r[j] for j in keep] for r in rows]
    return edit


def model_json(base, edit: Callable[[dict], None]) -> str:
    data = json.loads(base["m.json"])
    edit(data)
    return json.dumps(data)


def nested_json(depth: int = 100_000) -> str:
    return "[" * depth + "]" * depth


def constant_mat(base) -> bytes:
    """The tiny recording as a .mat in which every sensor sends one constant value (labels kept)."""
    import io
    import scipy.io
    rows = [line.split(",") for line in tiny_text(base).splitlines()]
    header, values = rows[0], np.array(rows[1:], dtype=float)
    columns = {name: (values[:, j:j + 1] if name == "Etiquette" else np.ones((len(values), 1)))
               for j, name in enumerate(header) if name != "Time"}
    buffer = io.BytesIO()
    scipy.io.savemat(buffer, columns)
    return buffer.getvalue()


def many_classes(count: int) -> str:
    return shipped_text("bomi/profiles/P1.toml") + "".join(
        f'\n[[classes]]\nlabel = {9 + k}\nname = "extra {k}"\nfunction = "F"\nnode = 1\n' for k in range(count))


def shipped_text(relative: str) -> str:
    return (Path(__file__).resolve().parent.parent / relative).read_text()


def identity_of(profile: str) -> dict:
    identity = load_profile(profile).identity
    return {"name": identity.name, "sha256": identity.digest}


@dataclass
class Case:
    id: str
    argv: list[str]                              # {d} is the case directory
    names: str                                   # the error line must contain this (the file or option)
    files: dict[str, Callable] = field(default_factory=dict)  # name -> base -> text or bytes
    directories: tuple[str, ...] = ()


P1_PORT = "socket://127.0.0.1:1"  # never reached: every case fails before opening it

CASES = [
    # 1. nothing overwritten: an input, an existing output (unless --force)
    Case("fuse-out-is-its-input", ["fuse", "{d}/tiny.csv", "--out", "{d}/tiny.csv"], "tiny.csv"),
    Case("fuse-out-is-its-input-even-with-force", ["fuse", "{d}/tiny.csv", "--out", "{d}/tiny.csv", "--force"], "tiny.csv"),
    Case("train-out-exists", ["train", "{d}/tiny.csv", "--out", "{d}/m.json"], "m.json"),
    Case("evaluate-png-exists", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv", "--png", "{d}/c.png"],
         "c.png", {"c.png": lambda b: b"\x89PNG old"}),
    Case("evaluate-json-is-the-test", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv",
                                       "--png", "{d}/c.png", "--json", "{d}/tiny.csv"], "tiny.csv"),
    Case("run-task-json-exists", ["run-task", "--operator", "joystick", "--json", "{d}/m.json"], "m.json"),
    Case("benchmark-json-exists", ["benchmark", "--json", "{d}/m.json"], "m.json"),
    Case("record-train-exists", ["record", "--profile", "P1", "--port", P1_PORT, "--out", "{d}/new.csv",
                                 "--train", "{d}/m.json"], "m.json"),
    Case("capture-out-exists", ["capture", "--port", P1_PORT, "--duration", "1", "--out", "{d}/tiny.csv"], "tiny.csv"),
    Case("live-log-exists", ["live", "--port", P1_PORT, "--profile", "P1", "--model", "{d}/m.json",
                             "--log", "{d}/tiny.csv"], "tiny.csv"),
    # 3. models that could move the arm wrongly
    Case("model-nan-amplitude", ["evaluate", "--train", "{d}/bad.json", "--test", "{d}/tiny.csv"], "bad.json",
         {"bad.json": lambda b: model_json(b, lambda m: m["amplitude"]["2"].update(gamma_max=math.nan))}),
    Case("model-empty-amplitude-range", ["live", "--port", P1_PORT, "--profile", "P1", "--model", "{d}/bad.json"],
         "bad.json", {"bad.json": lambda b: model_json(b, lambda m: m["amplitude"]["2"].update(gamma_min=5, gamma_max=5))}),
    Case("model-of-another-profile-live", ["live", "--port", P1_PORT, "--profile", "P1", "--model", "{d}/p4.json"],
         "p4.json", {"p4.json": lambda b: model_json(b, lambda m: m.update(profile=identity_of("P4")))}),
    Case("model-of-another-profile-evaluate", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv",
                                               "--profile", "P4"], "m.json"),
    Case("model-of-an-edited-profile", ["live", "--port", P1_PORT, "--profile", "P1", "--model", "{d}/edited.json"],
         "edited.json", {"edited.json": lambda b: model_json(b, lambda m: m["profile"].update(sha256="0" * 64))}),
    Case("model-without-profile", ["evaluate", "--train", "{d}/old.json", "--test", "{d}/tiny.csv"], "old.json",
         {"old.json": lambda b: model_json(b, lambda m: m.pop("profile"))}),
    Case("model-amplitude-node-not-the-profiles", ["live", "--port", P1_PORT, "--profile", "P1", "--model", "{d}/n.json"],
         "n.json", {"n.json": lambda b: model_json(b, lambda m: m["amplitude"]["2"].update(node=2))}),
    Case("train-on-constant-signals", ["train", "{d}/flat.csv", "--out", "{d}/new.json"], "flat.csv",
         {"flat.csv": lambda b: edited_csv(b, lambda rows: [r.__setitem__(slice(1, -1), ["1.0"] * (len(r) - 2))
                                                           for r in rows[1:]])}),
    # 4. what used to end in a traceback
    Case("recording-lacks-a-profile-node", ["train", "{d}/two.csv", "--profile", "P1", "--out", "{d}/new.json"], "two.csv",
         {"two.csv": lambda b: edited_csv(b, drop_node(3))}),
    Case("neutral-from-lacks-a-node", ["live", "--port", P1_PORT, "--profile", "P1", "--model", "{d}/m.json",
                                       "--neutral-from", "{d}/two.csv"], "two.csv",
         {"two.csv": lambda b: edited_csv(b, drop_node(3))}),
    Case("value-1e300", ["train", "{d}/huge.csv", "--out", "{d}/new.json"], "huge.csv",
         {"huge.csv": lambda b: edited_csv(b, set_cell("GYRO1X", 5, "1e300"))}),
    Case("test-shorter-than-a-window", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/short.csv"], "short.csv",
         {"short.csv": lambda b: "\n".join(tiny_text(b).splitlines()[:5]) + "\n"}),
    Case("model-nested-json", ["evaluate", "--train", "{d}/deep.json", "--test", "{d}/tiny.csv"], "deep.json",
         {"deep.json": lambda b: nested_json()}),
    Case("model-window-1e12", ["evaluate", "--train", "{d}/w.json", "--test", "{d}/tiny.csv"], "w.json",
         {"w.json": lambda b: model_json(b, lambda m: m["features"].update(window=10**12))}),
    Case("evaluate-reject-5", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv", "--reject", "5"], "--reject"),
    Case("evaluate-reject-nan", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv", "--reject", "nan"], "--reject"),
    Case("evaluate-vote-0", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv", "--vote", "0"], "--vote"),
    Case("evaluate-vote-negative", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv", "--vote", "-3"], "--vote"),
    Case("train-out-is-a-directory", ["train", "{d}/tiny.csv", "--out", "{d}/dir.json"], "dir.json", directories=("dir.json",)),
    Case("fuse-out-is-a-directory", ["fuse", "{d}/tiny.csv", "--out", "{d}/dir.csv"], "dir.csv", directories=("dir.csv",)),
    Case("evaluate-png-is-a-directory", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv",
                                         "--png", "{d}/dir.png"], "dir.png", directories=("dir.png",)),
    Case("evaluate-json-is-a-directory", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv",
                                          "--png", "{d}/c.png", "--json", "{d}/dir.json"], "dir.json",
         directories=("dir.json",)),
    Case("run-task-json-is-a-directory", ["run-task", "--operator", "joystick", "--json", "{d}/dir.json"], "dir.json",
         directories=("dir.json",)),
    Case("train-out-in-a-missing-directory", ["train", "{d}/tiny.csv", "--out", "{d}/no/m.json"], "no/m.json"),
    Case("record-train-in-a-missing-directory", ["record", "--profile", "P1", "--port", P1_PORT, "--out", "{d}/r.csv",
                                                 "--train", "{d}/no/m.json"], "no/m.json"),
    Case("run-task-negative-seed", ["run-task", "--operator", "joystick", "--seed", "-1"], "--seed"),
    Case("benchmark-no-jobs", ["benchmark", "--jobs", "0"], "--jobs"),
    Case("run-task-video-not-mp4", ["run-task", "--operator", "joystick", "--video", "{d}/x.txt"], "x.txt"),
    Case("run-task-plot-not-png", ["run-task", "--operator", "joystick", "--plot", "{d}/x.xyz"], "x.xyz"),
    # 6. labels the model does not know
    Case("evaluate-unknown-label", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/l42.csv"], "l42.csv",
         {"l42.csv": lambda b: edited_csv(b, set_cell("Etiquette", 400, "42"))}),
    # 7. capture options
    Case("capture-negative-duration", ["capture", "--port", P1_PORT, "--duration", "-1", "--out", "{d}/c.csv"], "--duration"),
    Case("capture-nan-duration", ["capture", "--port", P1_PORT, "--duration", "nan", "--out", "{d}/c.csv"], "--duration"),
    Case("capture-negative-retries", ["capture", "--port", P1_PORT, "--duration", "1", "--retries", "-1",
                                      "--out", "{d}/c.csv"], "--retries"),
    Case("capture-out-not-csv", ["capture", "--port", P1_PORT, "--duration", "1", "--out", "{d}/x.txt"], "x.txt"),
    # 8. messages that say what is wrong
    Case("huge-label", ["train", "{d}/big.csv", "--out", "{d}/new.json"], "Etiquette, row 2",
         {"big.csv": lambda b: edited_csv(b, set_cell("Etiquette", 2, "99999999999999999999"))}),
    Case("semicolon-csv", ["train", "{d}/semi.csv", "--out", "{d}/new.json"], "separated by commas",
         {"semi.csv": lambda b: tiny_text(b).replace(",", ";")}),
    Case("pickle-to-evaluate", ["evaluate", "--train", "{d}/m.pkl", "--test", "{d}/tiny.csv"], "pickles are never loaded",
         {"m.pkl": lambda b: b"\x80\x04K\x01."}),
    Case("json-renamed-npz", ["evaluate", "--train", "{d}/m.npz", "--test", "{d}/tiny.csv"], "not an NPZ archive",
         {"m.npz": lambda b: b["m.json"]}),
    Case("recording-is-a-directory", ["train", "{d}/rec.csv", "--out", "{d}/new.json"], "is a directory",
         directories=("rec.csv",)),
    Case("window-longer-than-the-recording", ["train", "{d}/short.csv", "--profile", "P1", "--allow-missing-classes",
                                              "--out", "{d}/new.json"],
         "shorter than one",
         {"short.csv": lambda b: "\n".join(tiny_text(b).splitlines()[:5]) + "\n"}),
    Case("profile-value-beyond-any-setting", ["train", "{d}/tiny.csv", "--profile", "{d}/p.toml", "--out", "{d}/n.json"],
         "[post_processing] vote_length", {"p.toml": lambda b: shipped_text("bomi/profiles/P1.toml").replace(
             "vote_length = 1", "vote_length = 99999999999999999999999")}),
    Case("operator-infinite-speed", ["run-task", "--operator", "joystick", "--operator-file", "{d}/o.toml"],
         "[deflection] full_speed", {"o.toml": lambda b: shipped_text("tasks/operators/operator.toml").replace(
             "full_speed = 0.20", "full_speed = inf")}),
    # 10. nonsense that used to be accepted (issue 29): physical quantities and sizes out of range
    Case("model-coefficient-1e308", ["evaluate", "--train", "{d}/bad.json", "--test", "{d}/tiny.csv"], "LDA parameters",
         {"bad.json": lambda b: model_json(b, lambda m: m["lda_coef"][0].__setitem__(0, 1e308))}),
    Case("model-vote-length-1e12", ["evaluate", "--train", "{d}/bad.json", "--test", "{d}/tiny.csv"], "vote length",
         {"bad.json": lambda b: model_json(b, lambda m: m["post_processing"].update(vote_length=10**12))}),
    Case("model-shrinkage-NaN", ["evaluate", "--train", "{d}/bad.json", "--test", "{d}/tiny.csv"], "shrinkage",
         {"bad.json": lambda b: model_json(b, lambda m: m.update(shrinkage="NaN"))}),
    Case("model-gamma-min-minus-50", ["evaluate", "--train", "{d}/bad.json", "--test", "{d}/tiny.csv"],
         "amplitude range of class 2",  # gamma, the size of an angle change, is never negative
         {"bad.json": lambda b: model_json(b, lambda m: (m["amplitude"]["2"].pop("direction", None),
                                                          m["amplitude"]["2"].update(gamma_min=-50.0)))}),
    Case("model-along-class-min-beyond-any-angle", ["live", "--port", P1_PORT, "--profile", "P1", "--model",
                                                    "{d}/bad.json"], "amplitude range of class 2",
         {"bad.json": lambda b: model_json(b, lambda m: m["amplitude"]["2"].update(gamma_min=-1000.0))}),
    Case("profile-20000-classes", ["train", "{d}/tiny.csv", "--profile", "{d}/p.toml", "--out", "{d}/n.json"], "p.toml",
         {"p.toml": lambda b: many_classes(20_000)}),
    Case("profile-70-classes", ["train", "{d}/tiny.csv", "--profile", "{d}/p.toml", "--out", "{d}/n.json"],
         "need three to 64 classes", {"p.toml": lambda b: many_classes(61)}),
    Case("profile-neutral-samples-1e6", ["train", "{d}/tiny.csv", "--profile", "{d}/p.toml", "--out", "{d}/n.json"],
         "[neutral] samples", {"p.toml": lambda b: shipped_text("bomi/profiles/P1.toml").replace(
             "samples = 100 ", "samples = 1000000 ")}),
    Case("profile-nested-3000-deep", ["train", "{d}/tiny.csv", "--profile", "{d}/p.toml", "--out", "{d}/n.json"],
         "nested deeper", {"p.toml": lambda b: "a = " + "[" * 3000 + "]" * 3000 + "\n"}),
    Case("operator-full-speed-0", ["run-task", "--operator", "joystick", "--operator-file", "{d}/o.toml"],
         "full_speed", {"o.toml": lambda b: shipped_text("tasks/operators/operator.toml").replace(
             "full_speed = 0.20", "full_speed = 0")}),
    Case("run-task-time-limit-1e-300", ["run-task", "--operator", "joystick", "--time-limit", "1e-300"], "--time-limit"),
    Case("demo-time-limit-nan", ["demo", "--time-limit", "nan", "--out", "{d}/demo"], "--time-limit"),
    Case("train-recording-lacks-profile-classes", ["train", "{d}/tiny.csv", "--profile", "P1", "--out", "{d}/n.json"],
         "class c1 (head pitch up (+29 deg)) of profile P1 is missing"),
    Case("train-mat-with-constant-sensors", ["train", "{d}/flat.mat", "--profile", "P1", "--allow-missing-classes",
                                             "--out", "{d}/n.json"], "is constant", {"flat.mat": constant_mat}),
    Case("train-out-name-300-characters", ["train", "{d}/tiny.csv", "--out", "{d}/" + "m" * 295 + ".json"],
         "longer than the 255 bytes"),
    Case("evaluate-png-name-300-characters", ["evaluate", "--train", "{d}/m.json", "--test", "{d}/tiny.csv",
                                              "--png", "{d}/" + "c" * 296 + ".png"], "longer than the 255 bytes"),
    Case("sweep-out-name-300-characters", ["sweep", "{d}/g.toml", "--out", "{d}/" + "s" * 300, "--jobs", "1"],
         "File name too long", {"g.toml": lambda b: 'participants = ["P1"]\noperators = ["joystick"]\nseeds = [0]\n'}),
    Case("benchmark-1e11-seeds", ["benchmark", "--operators", "joystick", "--seeds", "100000000000"], "--seeds"),
    Case("run-task-seed-1e15", ["run-task", "--operator", "joystick", "--seed", "1000000000000000"], "--seed"),
    Case("demo-out-name-300-characters", ["demo", "--out", "{d}/" + "o" * 300], "File name too long"),
    # 9. options
    Case("emulate-zero-hold", ["emulate", "--participant", "P1", "--to", "pty", "--hold", "0"], "--hold"),
    Case("emulate-nan-duration", ["emulate", "--participant", "P1", "--to", "pty", "--duration", "nan"], "--duration"),
    Case("emulate-hold-1e308", ["emulate", "--participant", "P1", "--to", "pty", "--hold", "1e308"], "--hold"),
    Case("emulate-settle-first-of-a-recording", ["emulate", "--recording", "{d}/tiny.csv", "--to", "pty",
                                                 "--settle-first"], "--settle-first"),
    Case("sim-check-seconds-1e308", ["sim-check", "--seconds", "1e308"], "--seconds"),
    Case("record-zero-repetitions", ["record", "--profile", "P1", "--port", P1_PORT, "--out", "{d}/r.csv",
                                     "--repetitions", "0"], "--repetitions"),
    Case("record-negative-hold", ["record", "--profile", "P1", "--port", P1_PORT, "--out", "{d}/r.csv",
                                  "--hold", "-2"], "--hold"),
    Case("run-task-zero-time-limit", ["run-task", "--operator", "joystick", "--time-limit", "0"], "--time-limit"),
    Case("run-task-negative-time-limit", ["run-task", "--operator", "joystick", "--time-limit", "-5"], "--time-limit"),
    Case("run-task-nan-time-limit", ["run-task", "--operator", "joystick", "--time-limit", "nan"], "--time-limit"),
    Case("run-task-joystick-unknown-participant", ["run-task", "--operator", "joystick", "--participant", "P9"], "P9"),
    Case("benchmark-unknown-participant-late-in-the-list", ["benchmark", "--participants", "P1,P4,P9", "--seeds", "1"], "P9"),
]


def snapshot(directory: Path) -> dict[str, str]:
    return {str(p.relative_to(directory)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(directory.rglob("*"))}


def materialize(case: Case, base: dict[str, bytes], directory: Path) -> list[str]:
    for name, data in base.items():
        (directory / name).write_bytes(data)
    for name, make in case.files.items():
        content = make(base)
        (directory / name).write_bytes(content if isinstance(content, bytes) else content.encode())
    for name in case.directories:
        (directory / name).mkdir()
    return [arg.replace("{d}", str(directory)) for arg in case.argv]


def assert_clean_error(code: int, err: str, names: str, before: dict, directory: Path) -> str:
    lines = err.splitlines()
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("bomi: error: "), err
    assert names in lines[0], lines[0]
    assert "Traceback" not in err
    assert snapshot(directory) == before, "files were created, changed or removed"
    assert not [p for p in directory.rglob("*") if TEMP_MARK in p.name]
    return lines[0]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_one_line_exit_2_and_nothing_changes(case, base, tmp_path, capsys):
    argv = materialize(case, base, tmp_path)
    before = snapshot(tmp_path)
    capsys.readouterr()
    code = main(argv)
    assert_clean_error(code, capsys.readouterr().err, case.names, before, tmp_path)


@pytest.mark.parametrize("case", [c for c in CASES if c.id in ("model-nested-json", "evaluate-reject-nan",
                                                               "recording-lacks-a-profile-node")], ids=lambda c: c.id)
def test_the_installed_command_line_process_too(case, base, tmp_path):
    """The same through a real process (what a user runs): stderr is the one line, nothing else."""
    argv = materialize(case, base, tmp_path)
    before = snapshot(tmp_path)
    done = subprocess.run([sys.executable, "-m", "tasks.cli", *argv], capture_output=True, text=True, timeout=120)
    assert_clean_error(done.returncode, done.stderr, case.names, before, tmp_path)


@pytest.mark.parametrize("kind", ["fifo", "device"])
@pytest.mark.parametrize("command", ["train", "evaluate-model", "profile", "operator"])
def test_a_fifo_or_device_where_a_file_is_meant_is_refused_without_reading_it(base, tmp_path, capsys, kind, command):
    """No hang on a FIFO nobody writes, no endless read of /dev/zero: refused by its type, at once."""
    (tmp_path / "tiny.csv").write_bytes(base["tiny.csv"])
    (tmp_path / "m.json").write_bytes(base["m.json"])
    suffix = {"train": ".csv", "evaluate-model": ".json", "profile": ".toml", "operator": ".toml"}[command]
    if kind == "fifo":
        bad = tmp_path / f"bad{suffix}"
        os.mkfifo(bad)
    else:
        bad = tmp_path / f"zero{suffix}"
        bad.symlink_to("/dev/zero")  # a name with the right suffix, that is a device
    argv = {"train": ["train", str(bad), "--out", str(tmp_path / "n.json")],
            "evaluate-model": ["evaluate", "--train", str(bad), "--test", str(tmp_path / "tiny.csv")],
            "profile": ["train", str(tmp_path / "tiny.csv"), "--profile", str(bad), "--out", str(tmp_path / "n.json")],
            "operator": ["run-task", "--operator", "joystick", "--operator-file", str(bad)]}[command]
    before = snapshot(tmp_path)
    start = time.monotonic()
    code = main(argv)
    line = assert_clean_error(code, capsys.readouterr().err, str(bad), before, tmp_path)
    assert "is not a regular file" in line and time.monotonic() - start < 10


def test_an_out_name_of_245_characters_is_written(base, tmp_path, capsys):
    """The temporary sibling is cut to fit NAME_MAX: a long name the file system accepts works."""
    (tmp_path / "tiny.csv").write_bytes(base["tiny.csv"])
    out = tmp_path / ("f" * 241 + ".csv")
    assert len(out.name) == 245
    assert main(["fuse", str(tmp_path / "tiny.csv"), "--out", str(out)]) == 0
    assert len(read_recording(out)) == TINY_ROWS
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([out.name, "tiny.csv"])


def test_a_full_disk_while_writing_is_one_line_and_leaves_nothing(base, tmp_path):
    """The file system refuses more bytes mid-write (a full disk; here a file-size limit, EFBIG):
    one error line, no partial output, no temporary file."""
    import resource
    import signal

    def small_files():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (len(base["tiny.csv"]), len(base["tiny.csv"])))

    (tmp_path / "tiny.csv").write_bytes(base["tiny.csv"])
    before = snapshot(tmp_path)
    done = subprocess.run([sys.executable, "-m", "tasks.cli", "fuse", str(tmp_path / "tiny.csv"), "--out",
                           str(tmp_path / "o.csv")], capture_output=True, text=True, timeout=120, preexec_fn=small_files)
    line = assert_clean_error(done.returncode, done.stderr, "o.csv", before, tmp_path)
    assert "cannot be written (File too large)" in line


def test_an_unwritable_directory_is_one_line(base, tmp_path):
    """A directory the process may not write into: without write bits for a user; for root (whom
    permission bits do not stop: CI runs as root), a read-only file system mounted over it in a mount
    namespace of the command's own (``unshare -m``)."""
    (tmp_path / "tiny.csv").write_bytes(base["tiny.csv"])
    locked = tmp_path / "locked"
    locked.mkdir()
    fuse = [sys.executable, "-m", "tasks.cli", "fuse", str(tmp_path / "tiny.csv"), "--out", str(locked / "o.csv")]
    if os.geteuid() == 0:
        mounted = 'mount -t tmpfs -o ro tmpfs "$1" && shift && exec "$@"'
        command = ["unshare", "-m", "sh", "-c", mounted, "sh", str(locked), *fuse]
    else:
        locked.chmod(0o500)
        command = fuse
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr == f"bomi: error: {locked / 'o.csv'}: directory {locked} is not writable\n"
    assert list(locked.iterdir()) == []


# ------------------------------------------------------------------------------------- outputs
def test_outputs_get_normal_permissions_and_force_replaces(base, tmp_path, capsys):
    (tmp_path / "tiny.csv").write_bytes(base["tiny.csv"])
    out = tmp_path / "fused.csv"
    old = os.umask(0o022)
    try:
        assert main(["fuse", str(tmp_path / "tiny.csv"), "--out", str(out)]) == 0
        assert out.stat().st_mode & 0o777 == 0o644
        out.write_text("old")
        assert main(["fuse", str(tmp_path / "tiny.csv"), "--out", str(out), "--force"]) == 0
    finally:
        os.umask(old)
    assert read_recording(out).nodes.keys() == {1, 2, 3}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fused.csv", "tiny.csv"]


def test_a_trailing_blank_line_is_accepted(base, tmp_path, capsys):
    path = tmp_path / "blank.csv"
    path.write_text(tiny_text(base) + "\n\n")
    assert len(read_recording(path)) == TINY_ROWS


def test_ctrl_c_inside_a_compiled_call_is_an_interruption_not_a_bug(tmp_path, capsys, monkeypatch):
    """A signal's KeyboardInterrupt raised while a numba kernel runs comes back as the SystemError
    "returned a result with an exception set" (its cause the KeyboardInterrupt; seen in the session
    fault corpus's SIGINT case): "bomi: interrupted", exit 130, as a plain Ctrl-C; any other
    SystemError stays a bug."""
    import tasks.cli.chain as chain_cli

    def interrupted_in_a_kernel(args):
        raise SystemError("CPUDispatcher(<function kernel>) returned a result with an exception set") \
            from KeyboardInterrupt("SIGTERM")

    def plain_system_error(args):
        raise SystemError("a bug")

    (tmp_path / "r.csv").write_text("x")
    argv = ["fuse", str(tmp_path / "r.csv"), "--out", str(tmp_path / "o.csv")]
    monkeypatch.setattr(chain_cli, "fuse_command", interrupted_in_a_kernel)
    assert main(argv) == 130 and capsys.readouterr().err == "bomi: interrupted\n"
    monkeypatch.setattr(chain_cli, "fuse_command", plain_system_error)
    assert main(argv) == 1 and capsys.readouterr().err.startswith("bomi: internal error: SystemError: a bug")


def test_an_internal_error_is_one_line_and_debug_shows_the_traceback(tmp_path, capsys, monkeypatch):
    import tasks.cli.chain as chain_cli

    def bug(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(chain_cli, "fuse_command", bug)
    (tmp_path / "r.csv").write_text("x")
    argv = ["fuse", str(tmp_path / "r.csv"), "--out", str(tmp_path / "o.csv")]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("bomi: internal error: ZeroDivisionError: a bug")
    assert main(["--debug", *argv]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "ZeroDivisionError" in err


def test_a_command_module_that_fails_to_load_is_one_line_too(capsys, monkeypatch):
    """A broken install (a module half written, a library missing) is one internal-error line."""
    import tasks.cli as cli

    def broken(name, *args):
        raise ImportError(f"cannot import {name}")

    monkeypatch.setattr(cli.importlib, "import_module", broken)
    assert main(["train", "x.csv", "--out", "m.json"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("bomi: internal error: ImportError: cannot import tasks.cli.chain")


# ------------------------------------------------------------------------------------- streams
def serve(payloads: Callable[[socket.socket], None]) -> tuple[str, threading.Thread]:
    server = socket.create_server(("127.0.0.1", 0))
    url = f"socket://127.0.0.1:{server.getsockname()[1]}"

    def run():
        client, _ = server.accept()
        server.close()  # one client only: a reconnection finds nobody
        try:
            payloads(client)
        except OSError:
            pass
        client.close()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return url, thread


def test_a_socket_read_takes_everything_that_has_arrived():
    """pyserial's socket:// says 1 byte is waiting whatever is there; one read must drain it all."""
    from bomi.serial_source import SerialSource

    frames = b"".join(encode_imu_frame(ImuFrame(10 + k % 3, 16, k // 3 % 256, (k, 0, 0), (0, 0, 0), (0, 0, 0)))
                      for k in range(900))
    url, thread = serve(lambda client: (time.sleep(0.4), client.sendall(frames), time.sleep(2)))
    with SerialSource(url, poll_s=0.0) as source:
        assert source.port.in_waiting <= 1
        time.sleep(0.8)  # everything has arrived
        chunks = source.chunks()
        first = next(chunks)
    assert len(first) == len(frames)


def random_bytes_for(seconds: float) -> Callable[[socket.socket], None]:
    def send(client):
        rng = np.random.default_rng(0)
        end = time.monotonic() + seconds
        time.sleep(0.35)
        while time.monotonic() < end:
            client.sendall(rng.bytes(40_000))
            time.sleep(0.01)
    return send


@pytest.mark.parametrize("nodes", [None, "1,2,3"])
def test_garbage_on_a_socket_is_not_a_recording(tmp_path, capsys, nodes):
    url, thread = serve(random_bytes_for(2.0))
    out = tmp_path / "c.csv"
    argv = ["capture", "--port", url, "--duration", "1.2", "--out", str(out), "--retries", "0"]
    assert main(argv + (["--nodes", nodes] if nodes else [])) == 2
    err = capsys.readouterr().err.splitlines()
    assert [line for line in err if line.startswith("bomi: error: ")] == err[-1:]
    assert "nothing recorded" in err[-1] and not out.exists()


@pytest.mark.real_time
def test_capture_ends_within_its_duration_when_the_stream_is_lost_and_says_the_file_is_partial(tmp_path, capsys):
    def stream_then_vanish(client):
        # 40 rows of 3 nodes, sent as 4 bursts of 0.16 s of stream: on a loaded machine a sender that slept
        # 16 ms per row took longer than the capture's duration to send them (CI: 33 rows in 2.5 s)
        time.sleep(0.35)
        for burst in range(4):
            client.sendall(b"".join(encode_imu_frame(ImuFrame(10 + n, 16, k, (k, 1, 2), (0, 0, 0), (0, 0, 16000)))
                                    for k in range(10 * burst, 10 * burst + 10) for n in range(3)))
            time.sleep(0.16)

    url, thread = serve(stream_then_vanish)
    out = tmp_path / "c.csv"
    start = time.monotonic()
    assert main(["capture", "--port", url, "--duration", "4", "--out", str(out)]) == 2
    assert time.monotonic() - start < 5.5  # 6 retries would take 31.5 s: the duration bounds them
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("bomi: error: ")]
    assert len(err) == 1 and f"{out} is partial: it keeps the" in err[0]
    assert 10 < len(read_recording(out)) <= 40


# ------------------------------------------------------------------------------------- property
GOOD = {"csv": "tiny.csv", "json": "m.json"}


def npz_model(base) -> bytes:
    import io
    import tempfile
    from bomi.model_io import load_model
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "m.json").write_bytes(base["m.json"])
        save_model(Path(d) / "m.npz", load_model(Path(d) / "m.json"))
        return (Path(d) / "m.npz").read_bytes()


def profile_toml() -> bytes:
    return (Path(load_profile("P1").source)).read_bytes()


@st.composite
def damaged(draw, good: bytes) -> bytes:
    kind = draw(st.sampled_from(["random", "truncated", "flipped", "spliced"]))
    if kind == "random":
        return draw(st.binary(max_size=2000))
    if kind == "truncated":
        return good[:draw(st.integers(0, len(good) - 1))]
    data = bytearray(good)
    if kind == "flipped":
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, len(data) - 1))
            data[i] = draw(st.integers(0, 255))
        return bytes(data)
    i = draw(st.integers(0, len(data)))
    return bytes(data[:i]) + draw(st.binary(min_size=1, max_size=64)) + bytes(data[i:])


# (command builder, which file is damaged: suffix). Each command either succeeds (exit 0) or fails in one line.
def commands(d: Path, bad: Path) -> dict[str, list[str]]:
    return {
        "csv": [["train", str(bad), "--out", str(d / "o.json")],
                ["evaluate", "--train", str(d / "m.json"), "--test", str(bad), "--png", str(d / "c.png")],
                ["fuse", str(bad), "--out", str(d / "o.csv")],
                ["live", "--port", P1_PORT, "--profile", "P1", "--model", str(d / "m.json"), "--neutral-from", str(bad)],
                ["emulate", "--recording", str(bad), "--to", "/dev/null"]],
        "json": [["evaluate", "--train", str(bad), "--test", str(d / "tiny.csv"), "--png", str(d / "c.png")],
                 ["live", "--port", P1_PORT, "--profile", "P1", "--model", str(bad)]],
        "npz": [["evaluate", "--train", str(bad), "--test", str(d / "tiny.csv"), "--png", str(d / "c.png")],
                ["live", "--port", P1_PORT, "--profile", "P1", "--model", str(bad)]],
        "toml": [["train", str(d / "tiny.csv"), "--profile", str(bad), "--out", str(d / "o.json")],
                 ["live", "--port", P1_PORT, "--profile", str(bad), "--model", str(d / "m.json")],
                 ["capture", "--port", P1_PORT, "--duration", "1", "--profile", str(bad), "--nodes", "1",
                  "--out", str(d / "o.csv")],
                 ["record", "--port", P1_PORT, "--profile", str(bad), "--out", str(d / "o.csv")]],
    }


@pytest.fixture(scope="module")
def goods(base) -> dict[str, bytes]:
    return {"csv": base["tiny.csv"], "json": base["m.json"], "npz": npz_model(base), "toml": profile_toml()}


@pytest.mark.parametrize("suffix", ["csv", "json", "npz", "toml"])
def test_damaged_files_never_crash_any_command(suffix, base, goods, tmp_path_factory):
    @given(data=st.data())
    @settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
    def check(data):
        d = tmp_path_factory.mktemp(f"prop-{suffix}")
        for name, content in base.items():
            (d / name).write_bytes(content)
        bad = d / f"bad.{suffix}"
        bad.write_bytes(data.draw(damaged(goods[suffix])))
        argv = data.draw(st.sampled_from(commands(d, bad)[suffix]))
        before = {p.name: p.read_bytes() for p in d.iterdir()}
        import contextlib
        import io
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(argv)
        lines = err.getvalue().splitlines()
        errors = [line for line in lines if line.startswith("bomi: error: ")]
        assert code in (0, 2), err.getvalue()
        assert not [line for line in lines if "internal error" in line or "Traceback" in line]
        if code == 2:
            assert len(errors) == 1 and errors == lines[-1:], err.getvalue()
        after = {p.name: p.read_bytes() for p in d.iterdir() if p.name in before}
        assert after == before
        assert not [p for p in d.iterdir() if TEMP_MARK in p.name]

    check()
