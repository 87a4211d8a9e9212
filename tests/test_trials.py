"""`bomi trial` with a stand-in and `bomi replay`: the whole trial path without a person, in CI time.

Two short sessions are run once (a BoMI session of two 8 s trials, a joystick session of one 30 s
trial; dev seeds), then checked: the records have the benchmark's keys, the timing agrees with the
logged ticks, the HDF5 file reads with h5py alone and its frames are the logged bytes, a replay
reproduces the hand path and a tampered log does not, re-scoring with the same model gives the
logged decisions' accuracy, and bad input is one line.
"""
from __future__ import annotations

import json
import re
import shutil
import struct

import h5py
import numpy as np
import pytest

from tasks.cli import main
from tasks.stacking.record import DecisionTrace, EpisodeLog
from tasks.stacking.summary import summarize

BOMI_ARGS = ["trial", "--stand-in", "P1", "--profile", "P1", "--controller", "bomi", "--trials", "2",
             "--seed", "11", "--headless", "--time-limit", "8", "--countdown", "0.5"]
JOYSTICK_ARGS = ["trial", "--stand-in", "P1", "--controller", "joystick", "--trials", "1", "--seed", "12",
                 "--headless", "--time-limit", "30", "--countdown", "0.5"]


# the tests of the two stand-in sessions below run on one xdist worker, which makes each session once
# (but the real-time test, in the real-time group: it makes bomi_dir on its own worker)
SESSIONS = pytest.mark.xdist_group("trial-sessions")


@pytest.fixture(scope="module")
def bomi_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("trial") / "bomi"
    assert main([*BOMI_ARGS, "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def joystick_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("trial") / "joystick"
    assert main([*JOYSTICK_ARGS, "--out", str(out)]) == 0
    return out


def _records(out):
    return [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]


def _summary_keys(with_decisions: bool) -> set[str]:
    """The keys `bomi benchmark --json` gives an episode (``summarize``, its record builder), of a tiny log."""
    n = 3
    trace = DecisionTrace(np.arange(n) * 0.016, np.array([0, 1, 1]), np.array([0, 0, 1]), np.zeros(n), np.zeros(n))
    log = EpisodeLog("bomi", "P1", 0, "x", np.arange(n) / 60, np.zeros((n, 3)), np.zeros((n, 3)), ["translation"] * n,
                     0, np.zeros((n, 2, 3)), np.zeros((n, 2), bool), np.zeros(3), False, None, "t", 1.0, 1.0,
                     decisions=trace if with_decisions else None)
    return set(summarize(log))


@SESSIONS
def test_a_stand_in_session_writes_the_benchmark_records(bomi_dir, joystick_dir):
    bomi, joystick = _records(bomi_dir), _records(joystick_dir)
    assert [r["trial"] for r in bomi] == [1, 2] and [r["trial"] for r in joystick] == [1]
    for r in bomi:
        # and the model and profile files it ran with (tests/test_replay_model.py)
        assert set(r) - {"trial", "model_sha256", "profile_sha256"} == _summary_keys(with_decisions=True)
        assert r["operator"] == "bomi" and r["participant"] == "P1" and r["decisions"] > 100
        assert 0.0 <= r["accuracy_all_decisions"] <= 1.0
    assert set(joystick[0]) - {"trial"} == _summary_keys(with_decisions=False)
    for name in ("bomi.h5", "model.json", "profile.toml", "report.md"):
        assert (bomi_dir / name).is_file()
    report = (joystick_dir / "report.md").read_text()
    assert "| 1 | joystick | P1 |" in report and (joystick_dir / "timeline_joystick.png").stat().st_size > 10_000


@SESSIONS
def test_a_trial_is_timed_from_the_first_command_to_the_stack_standing_still(joystick_dir):
    record = _records(joystick_dir)[0]
    assert record["success"], record["failure"]
    with h5py.File(joystick_dir / "joystick.h5") as f:
        go, end = int(f["trials/go_tick"][0]), int(f["trials/end_tick"][0])
        stick, pressed, task_t = f["ticks/stick"][go:end], f["ticks/pressed"][go:end], f["ticks/task_t"][go:end]
        cubes = f["ticks/cube_pos"][go:end]
    first = np.flatnonzero((stick > 0).any(axis=1) | pressed.any(axis=1))[0]
    # the task ends 1 s (its still_time) after the stack became still, one tick after the last row
    still_from = task_t[-1] + 1 / 60 - 1.0
    assert record["completion_time"] == pytest.approx(still_from - task_t[first], abs=1.5 / 60)
    # and the cubes do stand one on the other at the end, the top one a cube's height higher
    bottom, top = np.sort(cubes[-1][:, 2])
    assert top - bottom == pytest.approx(0.05, abs=0.005)


@SESSIONS
def test_the_dataset_reads_without_this_package_and_holds_the_bytes_the_loop_read(bomi_dir):
    with h5py.File(bomi_dir / "bomi.h5") as f:
        assert f.attrs["format"] == "bomi-trials" and f.attrs["version"] == 1
        stream = f["stream/bytes"][()].tobytes()
        node_id, counter, acc = f["frames/node_id"][()], f["frames/counter"][()], f["frames/acc"][()]
        tick, byte_end, frames_per_tick = f["frames/tick"][()], f["ticks/byte_end"][()], f["ticks/frames"][()]
    # a naive decoder of the 32-byte frames (docs: start 0x33, node, period, counter, mag, gyro, acc, end 0x34)
    assert len(stream) % 32 == 0
    decoded = [struct.unpack(">BBBBx9h8xB", stream[k:k + 32]) for k in range(0, len(stream), 32)]
    assert all(d[0] == 0x33 and d[-1] == 0x34 for d in decoded)
    np.testing.assert_array_equal([d[1] for d in decoded], node_id)
    np.testing.assert_array_equal([d[3] for d in decoded], counter)
    np.testing.assert_array_equal([d[10:13] for d in decoded], acc)
    # the frames reached the loop at their ticks, never before their bytes did (the parser holds the
    # first frames until it is in step with the stream), and every byte made a frame
    np.testing.assert_array_equal(np.bincount(tick, minlength=len(frames_per_tick)), frames_per_tick)
    bytes_frames = np.cumsum(np.diff(np.r_[0, byte_end]) // 32)
    assert np.all(np.cumsum(frames_per_tick) <= bytes_frames) and frames_per_tick.sum() == bytes_frames[-1]


def _deviation(text: str) -> float:
    return float(re.search(r"^replay: max hand deviation (\S+) m$", text, re.M).group(1))


@SESSIONS
def test_replay_reproduces_the_hand_path_and_a_tampered_log_does_not(bomi_dir, tmp_path, capsys):
    assert main(["replay", str(bomi_dir), "--trial", "2"]) == 0
    assert _deviation(capsys.readouterr().out) <= 1e-6
    tampered = tmp_path / "tampered"
    shutil.copytree(bomi_dir, tampered)
    with h5py.File(tampered / "bomi.h5", "r+") as f:  # node 1's acc x during trial 2: leaning, not neutral
        go = int(f["trials/go_tick"][1])
        byte_end = f["ticks/byte_end"][()]
        data = f["stream/bytes"][()]
        start = int(byte_end[go])
        for k in range(start, int(byte_end[go + 240]), 32):
            if data[k + 1] == f["frames/node_id"][0]:
                data[k + 17:k + 19] = np.frombuffer(struct.pack(">h", 4000), np.uint8)
        f["stream/bytes"][...] = data
    assert main(["replay", str(tampered), "--trial", "2"]) == 0
    assert _deviation(capsys.readouterr().out) > 1e-3


@SESSIONS
def test_rescoring_with_the_logged_model_gives_the_logged_accuracy(bomi_dir, capsys):
    assert main(["replay", str(bomi_dir), "--trial", "1", "--model", str(bomi_dir / "model.json")]) == 0
    out = capsys.readouterr().out
    logged, again = re.findall(r"(\d+) (?:logged )?decisions, accuracy ([\d.]+) %", out)
    assert logged == again and "100.00 % of the logged decisions decided alike" in out and "would have differed" in out


@SESSIONS
def test_bad_input_is_one_line(bomi_dir, tmp_path, capsys):
    other = tmp_path / "p4_model.json"
    text = (bomi_dir / "model.json").read_text()
    other.write_text(text.replace('"name": "P1"', '"name": "P4"', 1))
    cases = [
        ([*BOMI_ARGS, "--out", str(bomi_dir)], "directory holds a session"),
        ([*BOMI_ARGS, "--model", str(other), "--out", str(tmp_path / "x")], "model trained for profile P4"),
        (["trial", "--port", str(tmp_path / "no-such-port"), "--profile", "P1", "--model",
          str(bomi_dir / "model.json"), "--controller", "bomi", "--headless", "--out", str(tmp_path / "y")],
         "cannot open the port"),
        (["trial", "--controller", "joystick", "--gamepad", "3", "--headless",
          "--out", str(tmp_path / "z")], "--gamepad"),
        (["trial", "--profile", "P1", "--controller", "bomi", "--out", str(tmp_path / "w")], "--port"),
        (["replay", str(bomi_dir), "--trial", "9"], "no trial 9"),
        (["replay", str(tmp_path), "--trial", "1"], "trials.jsonl"),
        (["replay", str(bomi_dir), "--trial", "1", "--model", str(other)], "model trained for profile P4"),
    ]
    for argv, fault in cases:
        capsys.readouterr()
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("bomi: error: ") and fault in err and err.count("\n") == 1, err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists() and not (tmp_path / "z").exists()


@pytest.fixture
def virtual_pads(monkeypatch):
    """SDL's virtual joysticks (the SDL pygame ships): a full gamepad (6 axes, 4 buttons) and a
    1-axis device that is no gamepad; (sdl, index of each)."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    pygame = pytest.importorskip("pygame")
    import ctypes
    import glob
    import os
    pygame.display.init()
    pygame.joystick.init()
    found = glob.glob(os.path.join(os.path.dirname(pygame.__file__), "..", "pygame.libs", "libSDL2-2*"))
    if not found:
        pytest.skip("pygame without its own SDL library")
    sdl = ctypes.CDLL(found[0])
    sdl.SDL_JoystickFromInstanceID.restype = ctypes.c_void_p
    sdl.SDL_JoystickSetVirtualAxis.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int16]
    sdl.SDL_JoystickSetVirtualButton.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_uint8]
    pad, other = sdl.SDL_JoystickAttachVirtual(1, 6, 4, 0), sdl.SDL_JoystickAttachVirtual(1, 1, 0, 0)
    yield sdl, pad, other
    pygame.quit()


def test_a_gamepad_drives_the_stick_and_unplugging_it_is_one_line(virtual_pads, tmp_path, capsys):
    from bomi.errors import BomiError
    from tasks.trials.devices import DeviceLost, Gamepad
    sdl, index, other = virtual_pads
    pad = Gamepad(index)
    handle = sdl.SDL_JoystickFromInstanceID(pad._pad.get_instance_id())
    sdl.SDL_JoystickSetVirtualAxis(handle, 0, 16384)   # left stick right, half way
    sdl.SDL_JoystickSetVirtualAxis(handle, 1, -32768)  # left stick fully up
    sdl.SDL_JoystickSetVirtualAxis(handle, 2, 3000)    # right stick inside the dead zone
    sdl.SDL_JoystickSetVirtualButton(handle, 0, 1)
    first, held = pad.read(0.0), pad.read(0.016)
    # SDL's axis 16384 is 0.5 (pygame divides by 32768), outside the 0.15 dead zone: (0.5 - 0.15) / 0.85
    assert first.deflection == pytest.approx({"R": (0.5 - 0.15) / 0.85, "F": 1.0})
    assert first.pressed == {"B1"} and held.pressed == frozenset()  # a button counts on its way down
    with pytest.raises(BomiError, match="has 1 axes and 0 buttons"):
        Gamepad(other)
    assert main(["trial", "--controller", "joystick", "--gamepad", str(other), "--headless",
                 "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bomi: error: --gamepad") and "a gamepad for the JACO stick needs" in err
    assert not (tmp_path / "t").exists()
    sdl.SDL_JoystickDetachVirtual(index)
    with pytest.raises(DeviceLost, match="unplugged"):
        pad.read(0.032)


def test_the_viewer_keys_hold_a_function_for_a_moment_and_press_a_button_once():
    from tasks.trials.devices import KEY_HOLD_S, ViewerKeys
    now = [10.0]
    keys = ViewerKeys(lambda: now[0])
    keys.key(265)  # up arrow: F
    keys.key(49)   # 1: B1
    first, second = keys.read(10.0), keys.read(10.0)
    assert first.deflection == second.deflection == {"F": 1.0}
    assert first.pressed == {"B1"} and second.pressed == frozenset()
    now[0] = 10.0 + 0.9 * KEY_HOLD_S
    keys.key(265)  # the key's auto-repeat: held on
    assert keys.read(10.0 + 1.5 * KEY_HOLD_S).deflection == {"F": 1.0}
    assert keys.read(10.0 + 2.0 * KEY_HOLD_S).deflection == {}


@SESSIONS
def test_the_joystick_stand_in_does_what_the_simulated_episode_of_its_seed_does(joystick_dir):
    """An independent path to the same trial: `bomi run-task`'s episode (tasks.stacking.episode.run_episode)
    with the trial's seed moves the hand exactly as the trial did; only the clock differs (the trial
    is timed from the first command, the episode from its start)."""
    from tasks.experiments.jobs import EpisodeJob, run_job
    episode = run_job(EpisodeJob("joystick", "P1", 12, 30.0))
    record = _records(joystick_dir)[0]
    with h5py.File(joystick_dir / "joystick.h5") as f:
        go, end, first = (int(f[f"trials/{k}"][0]) for k in ("go_tick", "end_tick", "first_command_tick"))
        hand, task_t = f["ticks/hand_pos"][go:end], f["ticks/task_t"][()]
    np.testing.assert_array_equal(hand, episode.hand_pos)
    assert record["completion_time"] == pytest.approx(episode.completion_time - task_t[first], abs=1e-9)
    assert record["mode_switches"] == summarize(episode)["mode_switches"]


def test_a_controller_never_ready_ends_the_session_without_a_trial():
    from sim.env import ArmSim
    from sim.joystick import JoystickState
    from tasks.trials.session import TrialArm, TrialPlan
    sim = ArmSim()
    arm = TrialArm(sim, TrialPlan(ready_within_s=0.5))
    home = sim.tool_position
    ticks = 0
    while not arm.finished and ticks < 100:
        arm.step(JoystickState({"F": 1.0}))  # whatever the controller says, nothing moves while waiting
        ticks += 1
    assert arm.finished and ticks == 31 and "not ready within 0.5 s" in arm.not_ready and arm.results == []
    assert np.linalg.norm(sim.tool_position - home) < 1e-3


@pytest.mark.real_time
def test_a_stream_that_goes_away_mid_trial_fails_that_trial_and_keeps_the_session(bomi_dir, tmp_path, capsys):
    """A person's session on a pty (`bomi emulate`'s virtual participant, real time, in its own
    process) whose base station goes away 20 s in: the trial running then fails ("stream lost"), the
    session is written, the command ends with one error line, and the cut-short trial replays exactly."""
    import subprocess
    import sys
    emulator = subprocess.Popen(
        [sys.executable, "-m", "tasks.cli", "emulate", "--participant", "P1", "--to", "pty", "--neutral", "28",
         "--duration", "20", "--linger", "0.5", "--seed", "3"],  # neutral throughout the 20 s (12 s of warm-up)
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = emulator.stdout.readline().strip()
        assert port.startswith("/dev/")
        out = tmp_path / "person"
        code = main(["trial", "--port", port, "--profile", "P1", "--model", str(bomi_dir / "model.json"),
                     "--controller", "bomi", "--trials", "2", "--countdown", "0.5", "--time-limit", "30",
                     "--retries", "0", "--headless", "--out", str(out)])
        emulator.wait(timeout=30)
    finally:
        emulator.kill()
    err = capsys.readouterr().err
    assert code == 2 and err.strip().splitlines()[-1].startswith("bomi: error: ") and "stream lost" in err
    records = _records(out)
    assert len(records) == 1 and records[0]["failure"] == "stream lost" and records[0]["participant"] == "person"
    assert records[0]["accuracy_all_decisions"] is None  # nobody knows what a person intended
    assert records[0]["wall_time"] > 0 and records[0]["cpu_time"] > 0 and (out / "report.md").is_file()
    with h5py.File(out / "bomi.h5") as f:
        go, end = int(f["trials/go_tick"][0]), int(f["trials/end_tick"][0])
        t, stale = f["ticks/t"][()], f["ticks/stale"][()]
        linear = f["ticks/linear"][()]
    assert 0 < go < end
    # the last ticks ran without frames: held, no command (the watchdog)
    assert stale[-1] and np.all(linear[stale] == 0) and t[-1] - t[go] < 12.0
    capsys.readouterr()
    assert main(["replay", str(out), "--trial", "1"]) == 0
    assert _deviation(capsys.readouterr().out) <= 1e-6


def test_a_trials_recoveries_are_its_free_calibrating_runs_and_its_recalibrations():
    """The trial record's recoveries: each run of ticks calibrating the neutral with the arm otherwise
    free (the person's gesture, the safety key) is a re-zero from its first tick's task time to its
    last; a retake held after a break in the stream (its ticks carry the hold) is not; each run of
    recalibrating ticks is a recalibration, in order of their start."""
    from tasks.operators.recovery import RecoveryAction
    from tasks.trials.session import person_recoveries

    untrusted = "node 1 untrusted after reconnect: retaking warm-up and neutral"
    recalibrating = "recalibrating (relax: rest, 4 s left)"
    flags = [(False, "", False), (True, "", False), (True, "", False), (False, "", False), (True, untrusted, False),
             (True, untrusted, False), (False, "", False), (False, recalibrating, True), (False, recalibrating, True),
             (True, "", False)]
    ticks = [{"calibrating": c, "hold": h, "recalibrating": r} for c, h, r in flags]
    task_t = [0.5 * k for k in range(len(ticks))]
    events = person_recoveries(ticks, task_t)
    assert [(e.action, e.start_s, e.end_s) for e in events] == [(RecoveryAction.REZERO, 0.5, 1.0),
                                                                (RecoveryAction.RECALIBRATE, 3.5, 4.0),
                                                                (RecoveryAction.REZERO, 4.5, 4.5)]
