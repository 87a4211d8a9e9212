"""A trial session never loses a person's data (issue 40 item 2): each trial written as it finishes,
kill -9 and SIGTERM keep the finished ones replayable, a second session on one directory is refused,
--force keeps the old session until the new one has a trial, a full disk is one line, and an
interrupted session resumes. Short stand-in sessions (2 s trials) with a given model (no calibration)."""
from __future__ import annotations

import errno
import fcntl
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tasks.cli import main
from tasks.experiments.limits import MAX_SEED


def trial_args(model: Path, out: Path, trials: int = 2) -> list[str]:
    return ["trial", "--stand-in", "P1", "--profile", "P1", "--model", str(model), "--controller", "bomi",
            "--trials", str(trials), "--seed", "11", "--headless", "--time-limit", "2", "--countdown", "0.2",
            "--out", str(out)]


def trials_in(out: Path) -> list[int]:
    return [json.loads(line)["trial"] for line in (out / "trials.jsonl").read_text().splitlines()]


@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM], ids=["kill-9", "SIGTERM"])
def test_a_signal_during_trial_2_keeps_trial_1_replayable(p1_model_file, tmp_path, capsys, signum):
    out = tmp_path / "session"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])}
    process = subprocess.Popen([sys.executable, "-m", "tasks.cli", *trial_args(p1_model_file, out, trials=3)],
                               stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, env=env)
    seen = b""
    while b"trial 2: go" not in seen and (byte := process.stderr.read(1)):
        seen += byte
    process.send_signal(signum)
    rest = process.stderr.read().decode()
    code = process.wait(timeout=30)
    assert b"trial 2: go" in seen
    if signum == signal.SIGKILL:
        assert code == -signal.SIGKILL
    else:
        assert code == 130 and rest.strip().splitlines()[-1] == "bomi: interrupted" and "Traceback" not in rest
    assert trials_in(out)[0] == 1 and 2 not in trials_in(out)      # trial 2 never finished
    assert main(["replay", str(out), "--trial", "1"]) == 0
    assert "the same outcome as logged" in capsys.readouterr().out


def test_a_second_session_on_the_directory_is_refused_by_its_lock(p1_model_file, tmp_path, capsys):
    out = tmp_path / "session"
    out.mkdir()
    held = os.open(out / ".lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)                     # another bomi trial at work
    try:
        assert main(trial_args(p1_model_file, out)) == 2
    finally:
        os.close(held)
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"bomi: error: {out}: another bomi trial is writing to this directory (it holds {out / '.lock'})"]
    assert sorted(p.name for p in out.iterdir()) == [".lock"]


def test_force_keeps_the_old_session_until_the_new_one_has_a_finished_trial(p1_model_file, tmp_path, monkeypatch,
                                                                           capsys):
    import tasks.cli.trial as trial
    out = tmp_path / "session"
    out.mkdir()
    (out / "trials.jsonl").write_text('{"trial": 1, "old": true}\n')
    (out / "bomi.h5").write_bytes(b"the old session")
    listed = []
    commit = trial.Committer.commit

    def watched(self):
        listed.append(sorted(p.name for p in out.iterdir() if not p.name.startswith(".")))
        return commit(self)

    monkeypatch.setattr(trial.Committer, "commit", watched)
    assert main([*trial_args(p1_model_file, out, trials=1), "--force"]) == 0
    assert listed[0] == ["bomi.h5", "trials.jsonl"]                    # at the first trial's end: still the old one
    aside = [p for p in tmp_path.iterdir() if p.name.startswith("session.old-")]
    assert len(aside) == 1 and (aside[0] / "bomi.h5").read_bytes() == b"the old session"
    assert trials_in(out) == [1] and "old" not in (out / "trials.jsonl").read_text()
    assert not [p for p in out.iterdir() if p.name.startswith(".new-")]


def test_a_full_disk_is_one_line_keeps_trial_1_and_the_session_resumes(p1_model_file, tmp_path, monkeypatch, capsys):
    import tasks.trials.dataset as dataset
    out = tmp_path / "session"
    writes = []
    real = dataset._write_h5

    def fills_up(path, session, attrs):
        writes.append(path.name)
        if len(writes) == 2:                                            # trial 2's write
            path.write_bytes(b"part of a file")
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, session, attrs)

    monkeypatch.setattr(dataset, "_write_h5", fills_up)
    assert main(trial_args(p1_model_file, out)) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.startswith("bomi:")]
    assert lines == [f"bomi: error: {out / 'bomi.h5'}: cannot write the trial data ([Errno 28] No space left on "
                     f"device); the session stops, trials up to 1 kept"]
    assert trials_in(out) == [1] and not list(out.glob(".*partial*"))   # the partial trial removed
    monkeypatch.setattr(dataset, "_write_h5", real)
    assert main(["replay", str(out), "--trial", "1"]) == 0

    assert main(["trial", "--resume", str(out)]) == 0                   # the disk has room again
    assert trials_in(out) == [1, 2] and (out / "bomi.2.h5").is_file()
    records = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    assert [r["seed"] for r in records] == [11, 12]                    # trial 2 keeps its cube placement
    assert main(["replay", str(out), "--trial", "2"]) == 0
    assert "the same outcome as logged" in capsys.readouterr().out
    assert main(["trial", "--resume", str(out)]) == 2
    assert "nothing to resume" in capsys.readouterr().err


def test_a_seed_out_of_range_is_refused_before_anything_runs(p1_model_file, tmp_path, capsys):
    args = trial_args(p1_model_file, tmp_path / "session")
    args[args.index("--seed") + 1] = "99999999999999999999"
    assert main(args) == 2
    assert capsys.readouterr().err.startswith(f"bomi: error: argument --seed: at most {MAX_SEED}")
    args[args.index("--seed") + 1] = str(MAX_SEED)                  # the second trial's seed would pass it
    assert main(args) == 2
    assert capsys.readouterr().err.startswith(f"bomi: error: --seed: the session's last trial would have seed {MAX_SEED + 1}")
    assert not (tmp_path / "session").exists()
