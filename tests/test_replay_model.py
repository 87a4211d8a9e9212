"""`bomi replay` and the model a trial ran with (issue 55 item 3): each BoMI trial record keeps the
SHA-256 of the session's model.json and profile.toml; replay refuses other files (one line, exit 2)
and compares the replayed decisions with the logged ones (labels, gamma and nu to the bit) as well
as the hand. A session from before the digests is judged by its decisions. Short stand-in sessions
(2 s trials) with given models (no calibration): the session's, and another day's."""
from __future__ import annotations

import hashlib
import json
import re
import shutil
from pathlib import Path

import pytest

from tasks.cli import main


SESSION = pytest.mark.xdist_group("replay-session")   # session_dir's tests: one worker makes it once


@pytest.fixture(scope="module")
def session_dir(p1_model_file, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("replay") / "session"
    assert main(["trial", "--stand-in", "P1", "--profile", "P1", "--model", str(p1_model_file), "--controller",
                 "bomi,joystick", "--trials", "1", "--seed", "11", "--headless", "--time-limit", "2", "--countdown",
                 "0.2", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def other_day_model(tmp_path_factory) -> Path:
    """A model for the same profile trained on another day of the virtual P1 (calibration seed 2)."""
    from bomi.chain import train
    from bomi.model_io import save_model
    from bomi.profiles import load_profile
    from tasks.participants.participant import calibration_session, load_participant, session_recording

    params, profile = load_participant("P1"), load_profile("P1")
    session = calibration_session(params, profile, 2, repetitions=1, hold_s=2.0, neutral_s=2.0)
    path = tmp_path_factory.mktemp("model") / "other_day.json"
    save_model(path, train([session_recording(session, profile)], profile))
    return path


def records(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def copy_of(session: Path, tmp_path: Path) -> Path:
    out = tmp_path / "copy"
    shutil.copytree(session, out, ignore=shutil.ignore_patterns(".lock"))
    return out


@SESSION
def test_a_bomi_trial_record_keeps_the_digests_of_its_model_and_profile(session_dir):
    bomi, joystick = records(session_dir)
    assert bomi["operator"] == "bomi" and joystick["operator"] == "joystick"
    assert bomi["model_sha256"] == sha256(session_dir / "model.json")
    assert bomi["profile_sha256"] == sha256(session_dir / "profile.toml")
    assert "model_sha256" not in joystick


@SESSION
def test_a_logged_trial_replays_to_the_same_decisions(session_dir, capsys):
    assert main(["replay", str(session_dir), "--trial", "1"]) == 0
    out = capsys.readouterr().out
    assert f"sha256 {sha256(session_dir / 'model.json')} as logged" in out
    replayed, logged = map(int, re.search(r"decisions: (\d+) replayed, (\d+) logged, the same as logged "
                                          r"\(labels, gamma and nu to the bit\)", out).groups())
    assert replayed == logged > 20


@SESSION
def test_another_days_model_is_refused_in_one_line(session_dir, other_day_model, tmp_path, capsys):
    out = copy_of(session_dir, tmp_path)
    logged = sha256(out / "model.json")
    shutil.copyfile(other_day_model, out / "model.json")
    assert main(["replay", str(out), "--trial", "1"]) == 2
    err = capsys.readouterr().err
    assert err == (f"bomi: error: {out / 'model.json'}: not the model the trials were run with "
                   f"(sha256 {logged} logged, {sha256(other_day_model)} now)\n")


@SESSION
def test_an_edited_profile_is_refused_in_one_line(session_dir, tmp_path, capsys):
    out = copy_of(session_dir, tmp_path)
    with (out / "profile.toml").open("a") as f:
        f.write("\n# edited\n")
    assert main(["replay", str(out), "--trial", "1"]) == 2
    assert "profile.toml: not the profile the trials were run with" in capsys.readouterr().err


@SESSION
def test_a_session_without_digests_is_judged_by_its_decisions(session_dir, other_day_model, tmp_path, capsys):
    """Records from before the digests: replay says the model cannot be checked; with the session's own
    model the decisions are the logged ones, with another day's they are not (and replay says so)."""
    out = copy_of(session_dir, tmp_path)
    old = [{k: v for k, v in r.items() if not k.endswith("_sha256")} for r in records(out)]
    (out / "trials.jsonl").write_text("".join(json.dumps(r) + "\n" for r in old))
    assert main(["replay", str(out), "--trial", "1"]) == 0
    same = capsys.readouterr().out
    assert "keeps no model hash" in same and "the same as logged (labels" in same
    shutil.copyfile(other_day_model, out / "model.json")
    assert main(["replay", str(out), "--trial", "1"]) == 0
    other = capsys.readouterr().out
    assert "keeps no model hash" in other and "decisions:" in other and "NOT the same as logged" in other


@SESSION
def test_a_digest_that_is_not_one_is_one_line(session_dir, tmp_path, capsys):
    out = copy_of(session_dir, tmp_path)
    edited = records(out)
    edited[0]["model_sha256"] = "abc"
    (out / "trials.jsonl").write_text("".join(json.dumps(r) + "\n" for r in edited))
    assert main(["replay", str(out), "--trial", "1"]) == 2
    assert capsys.readouterr().err == (f"bomi: error: {out / 'trials.jsonl'}: line 1: model_sha256: 'abc' is not a "
                                       f"SHA-256 digest (64 hexadecimal digits)\n")


def test_a_resumed_session_keeps_its_model_and_profile_files_byte_for_byte(p1_model_file, tmp_path, monkeypatch,
                                                                          capsys):
    """A session interrupted in trial 2 and resumed: its model.json and profile.toml are not rewritten (a
    profile saved again from its loaded copy differs in its bytes), so every record's digests are the
    files' and trial 1 still replays."""
    import signal

    from tasks.trials.standin import BomiStandIn
    heard, calls = BomiStandIn.heard, []

    def heard_then_signal(self, decisions):
        calls.append(1)
        if len(calls) == 1500:                       # trial 2 (each trial: 12 + 120 ticks after the warm-up)
            signal.raise_signal(signal.SIGTERM)
        return heard(self, decisions)

    monkeypatch.setattr(BomiStandIn, "heard", heard_then_signal)
    out = tmp_path / "session"
    assert main(["trial", "--stand-in", "P1", "--profile", "P1", "--model", str(p1_model_file), "--controller", "bomi",
                 "--trials", "3", "--seed", "11", "--headless", "--time-limit", "4", "--countdown", "0.2",
                 "--out", str(out)]) == 130
    before = [r["trial"] for r in records(out)]
    monkeypatch.setattr(BomiStandIn, "heard", heard)
    assert main(["trial", "--resume", str(out)]) == 0
    assert before and [r["trial"] for r in records(out)] == [1, 2, 3]
    assert {(r["model_sha256"], r["profile_sha256"]) for r in records(out)} == \
        {(sha256(out / "model.json"), sha256(out / "profile.toml"))}
    assert main(["replay", str(out), "--trial", "1"]) == 0
    assert "decisions:" in capsys.readouterr().out
