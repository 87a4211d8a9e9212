"""`bomi trial` applies the profile's assistance as `bomi benchmark` does (issue 54 item 4): a profile
with ``[assist] options = ["auto-mode"]`` (what `bomi design` writes) runs its trials with the
automatic mode switching, logs it in each trial record and in the session file, and `bomi replay`
applies it again; ``--assist`` chooses otherwise (same syntax as the benchmark's)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from tasks.cli import main

ARGS = ["trial", "--stand-in", "P1", "--controller", "bomi", "--trials", "1", "--seed", "11", "--headless",
        "--time-limit", "20", "--countdown", "0.2"]


@pytest.fixture(scope="module")
def auto_mode(tmp_path_factory) -> tuple[Path, Path]:
    """P1's profile with the automatic mode switching on (as `bomi design` writes it), and a model trained
    for it on the virtual P1's short calibration session (seed 1)."""
    from bomi.chain import train
    from bomi.model_io import save_model
    from bomi.profiles import PROFILE_DIR, load_profile
    from tasks.participants.participant import calibration_session, load_participant, session_recording

    home = tmp_path_factory.mktemp("auto")
    text = (PROFILE_DIR / "P1.toml").read_text()
    assert "[assist]" not in text and text.count("[[nodes]]") >= 1
    profile_path = home / "P1_auto.toml"
    profile_path.write_text(text.replace("[[nodes]]", '[assist]\noptions = ["auto-mode"]\n\n[[nodes]]', 1))
    profile = load_profile(profile_path)
    assert profile.assist == ("auto-mode",)
    session = calibration_session(load_participant("P1"), profile, 1, repetitions=1, hold_s=2.0, neutral_s=2.0)
    model_path = home / "model.json"
    save_model(model_path, train([session_recording(session, profile)], profile))
    return profile_path, model_path


def run(auto_mode, out: Path, *extra: str) -> dict:
    profile, model = auto_mode
    assert main([*ARGS, "--profile", str(profile), "--model", str(model), *extra, "--out", str(out)]) == 0
    [record] = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    return record


def test_a_trial_of_a_profile_with_auto_mode_uses_it_logs_it_and_replays_it(auto_mode, tmp_path, capsys):
    import h5py
    out = tmp_path / "session"
    record = run(auto_mode, out)
    assert record["assist"] == "auto-mode"   # (the stand-in rests little: its switches are the joystick test's)
    with h5py.File(out / "bomi.h5") as f:
        assert f.attrs["assist"] == "auto-mode"
    assert json.loads((out / "session.json").read_text())["argv"].count("--assist") == 0  # the profile's: not an option
    capsys.readouterr()
    assert main(["replay", str(out), "--trial", "1"]) == 0
    replayed = capsys.readouterr().out
    assert "the same outcome as logged" in replayed and "max hand deviation 0 m" in replayed
    assert "decisions:" in replayed and "the same as logged (labels" in replayed


def test_assist_none_runs_without_it_and_is_kept_for_a_resume(auto_mode, tmp_path):
    out = tmp_path / "session"
    record = run(auto_mode, out, "--assist", "none")
    assert record["assist"] == "none" and record["automatic_switches"] == 0
    argv = json.loads((out / "session.json").read_text())["argv"]
    assert argv[argv.index("--assist") + 1] == "none"


def test_an_unknown_assistance_is_one_line(auto_mode, tmp_path, capsys):
    profile, model = auto_mode
    assert main([*ARGS, "--profile", str(profile), "--model", str(model), "--assist", "teleport",
                 "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1].startswith("bomi: error: ") and "teleport" in err
    assert not (tmp_path / "x").exists()


def test_a_joystick_trial_with_assist_does_what_the_benchmarks_assisted_episode_does(tmp_path, capsys):
    """`--assist auto-mode` on the joystick: the trial moves the hand exactly as `bomi benchmark`'s episode
    of its seed with the same assistance (an independent path: ``run_episode``'s ``Assisted`` wrapper),
    makes the same automatic switches at the same ticks, and replays to the same path."""
    import h5py
    import numpy as np

    from tasks.experiments.jobs import EpisodeJob, run_job
    from tasks.operators.assist import Assist
    from tasks.stacking.summary import summarize
    out = tmp_path / "session"
    assert main(["trial", "--stand-in", "P1", "--controller", "joystick", "--trials", "1", "--seed", "12",
                 "--headless", "--time-limit", "30", "--countdown", "0.5", "--assist", "auto-mode",
                 "--out", str(out)]) == 0
    [record] = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    episode = run_job(EpisodeJob("joystick", "P1", 12, 30.0, assist=frozenset({Assist.AUTO_MODE})))
    expected = summarize(episode)
    with h5py.File(out / "joystick.h5") as f:
        go, end = (int(f[f"trials/{k}"][0]) for k in ("go_tick", "end_tick"))
        np.testing.assert_array_equal(f["ticks/hand_pos"][go:end], episode.hand_pos)
        assert f.attrs["assist"] == "auto-mode"
    assert record["assist"] == expected["assist"] == "auto-mode"
    assert record["automatic_switches"] == expected["automatic_switches"] > 0
    for key in ("mode_switches", "refused_switches", "undone_switches", "wrong_goal_switches"):
        assert record[key] == expected[key], key
    capsys.readouterr()
    assert main(["replay", str(out), "--trial", "1"]) == 0
    replayed = capsys.readouterr().out
    assert "the same outcome as logged" in replayed and "max hand deviation 0 m" in replayed
