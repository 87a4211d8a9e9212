"""`bomi live`: watchdog, sanitizer and stick by hand; the loop on an injected clock; emulator -> pty -> live."""
from __future__ import annotations

import io
import json
import subprocess
import sys
import re
from dataclasses import asdict, replace
from functools import cache

import numpy as np
import pytest

from bomi.chain import Decision, OnlineChain
from tasks.cli import main
from bomi.emulator import EmulatorConfig, EmulatorStats, block_chunks
from bomi.frames import FrameParser, ImuFrame, SafetyKey, encode_imu_frame, encode_safety_key_frame
from bomi.profiles import load_profile
from bomi.protocol import calibration_schedule
from sim.env import ArmSim
from sim.joystick import ArmCommand, JoystickInterpreter, JoystickState
from tasks.operators.stick import DecisionStick
from bomi.gate import GateConfig
from tasks.trials.displays import StatusLine, TickLog, display_opens, has_display
from tasks.trials.live import Tick, run_live, status_text
from tasks.trials.person import Watchdog, refusal
from tasks.participants.imu_synth import SensorNoise, synthesize_raw
from tasks.participants.wire import participant_blocks
from tasks.participants.participant import load_participant

CONTROL_DT = 1 / 60
FULL_SPEED = 0.2


def decision(label: int = 1, function: str = "F", nu: float = 0.5, confidence: float = 0.9, index: int = 0) -> Decision:
    return Decision(label=label, name="x", function=function, confidence=confidence, rejected=False, gamma=10.0,
                    nu=nu, sample_index=index)


# ------------------------------------------------------------------------------------ watchdog
def test_watchdog_expires_after_100_ms_of_silence_and_needs_fresh_frames():
    dog = Watchdog(timeout_s=0.1)
    assert dog.expired(0.0)                  # nothing ever arrived
    dog.frames_arrived(1.0)
    assert not dog.expired(1.0)
    assert not dog.expired(1.099)
    assert dog.expired(1.1)
    assert dog.expired(5.0)                  # time alone never resumes
    assert dog.trips == 1
    dog.frames_arrived(5.0)
    assert not dog.expired(5.05)
    assert dog.expired(5.2)
    assert dog.trips == 2


# ----------------------------------------------------------------------------------- sanitizer
FUNCTIONS_P1 = {cls.label: cls.function for cls in load_profile("P1").classes}


@pytest.mark.parametrize("bad, reason", [
    (decision(label=42), "unknown class 42 (F)"),
    (decision(label=1, function="B"), "unknown class 1 (B)"),       # label and function disagree
    (decision(nu=float("nan")), "nu is nan"),
    (decision(confidence=float("nan")), "confidence is nan"),
    (replace(decision(), gamma=float("inf")), "gamma is inf"),
    (decision(nu=1.5), "nu 1.5 outside [0, 1]"),
    (decision(nu=-0.1), "nu -0.1 outside [0, 1]"),
    (decision(confidence=1.2), "confidence 1.2 outside [0, 1]"),
])
def test_sanitizer_refuses_unknown_classes_nan_and_out_of_range(bad, reason):
    assert refusal(bad, FUNCTIONS_P1) == reason


def test_sanitizer_lets_valid_decisions_through():
    assert FUNCTIONS_P1[1] == "F" and FUNCTIONS_P1[0] == "neutral"
    assert refusal(decision(), FUNCTIONS_P1) is None
    assert refusal(decision(label=0, function="neutral", nu=0.0), FUNCTIONS_P1) is None
    assert refusal(decision(nu=1.0, confidence=1.0), FUNCTIONS_P1) is None


# --------------------------------------------------------------------------------------- stick
def test_stick_deflects_by_nu_and_presses_a_button_held_long_enough_on_its_rising_edge():
    profile = load_profile("P1")   # button_hold_s 0.35 s: 22 decisions at 62.5 Hz (21 are 0.336 s)
    buttons = {cls.function: cls.label for cls in profile.classes}
    b1 = decision(label=buttons["B1"], function="B1", nu=0.0)
    pressed = JoystickState(pressed=frozenset({"B1"}))
    stick = DecisionStick(profile)
    assert stick.update([decision(nu=0.25)]) == JoystickState({"F": 0.25})
    assert stick.update([]) == JoystickState({"F": 0.25})                 # held until the next decision
    assert stick.update([b1] * 21) == JoystickState()                     # not yet: the stick centred meanwhile
    assert stick.update([b1]) == pressed                                  # the 22nd in a row
    assert stick.update([b1] * 30) == JoystickState()                     # one press per hold
    assert stick.update([decision(), *[b1] * 21]) == JoystickState()      # a break starts the count anew
    assert stick.update([b1]) == pressed
    stick.update([decision(nu=0.7), *[b1] * 12])
    stick.release()                                                       # forgets the evidence too
    assert stick.update([b1] * 12) == JoystickState() and stick.update([]) == JoystickState()
    # without a hold (0 s) every button decision counts: a press on each rising edge
    quick = DecisionStick(replace(profile, button_hold_s=0.0))
    assert quick.update([b1, b1]) == pressed and quick.update([decision(), b1]) == pressed


# ------------------------------------------------------------------------------ status, display
class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("stream, expected", [(io.StringIO(), "0\n0.5\n1\n"), (Terminal(), "\r0\r0.5\r1\n")])
def test_status_line_about_twice_a_second_in_place_on_a_terminal(stream, expected):
    status = StatusLine(stream, period_s=0.5)
    for k in range(61):
        t = k / 60
        status.show(t, lambda: f"{t:.2g}")
    status.close()
    assert stream.getvalue().replace(" ", "") == expected


def test_status_text_by_hand():
    parser = FrameParser(confirm_frames=1)  # two frames: no phantom-frame guard (tested in test_frames)
    parser.feed(encode_imu_frame(ImuFrame(10, 16, 0, (0, 0, 0), (0, 0, 0), (0, 0, 0))), now=0.0)
    parser.feed(encode_imu_frame(ImuFrame(10, 16, 4, (0, 0, 0), (0, 0, 0), (0, 0, 0))), now=0.5)  # 3 lost
    command = ArmCommand(np.array([0.0, -0.12, 0.0]), np.zeros(3), 0.0)
    tick = Tick(30, 0.5, 1, 3, False, False, False, [], [], JoystickState({"F": 0.6}), "translation", command)
    tick = replace(tick, loop_hz=59.0, overruns=2)
    assert status_text(tick, parser, decision(nu=0.6, confidence=0.875)) == \
        "   0.5 s | loop 59.0 Hz, 2 overruns | stream   2.0 Hz | lost 3 (60.0 %) | c1 F conf 0.88 | translation | " \
        "12.0 cm/s | ok"
    stale = replace(tick, stale=True, calibrating=True, mode="wrist",
                    command=ArmCommand(np.zeros(3), np.array([0.0, 0.0, np.radians(30)]), 0.0))
    assert status_text(stale, parser, None).endswith(
        "| calibrating neutral, hold still | wrist | 30 deg/s | STOPPED: no frames")
    warming = replace(tick, hold="warming up (node 2)")
    assert status_text(warming, parser, None).endswith("| no decision yet | translation | 12.0 cm/s | HELD: warming up (node 2)")


def test_display_is_looked_for_in_the_environment():
    assert not has_display({})
    assert not has_display({"DISPLAY": ""})
    assert has_display({"DISPLAY": ":0"}) and has_display({"WAYLAND_DISPLAY": "wayland-0"})


def test_an_unreachable_display_means_headless(tmp_path, p1_model_file, monkeypatch, capsys):
    monkeypatch.setenv("DISPLAY", ":4242")
    assert not display_opens()
    assert main(["live", "--port", "loop://", "--profile", "P1", "--model", str(p1_model_file),
                 "--duration", "0.2"]) == 0
    assert "live: cannot open the display :4242: running headless" in capsys.readouterr().err


def test_the_port_opens_once_the_scene_is_built_and_no_file_before_it(tmp_path, p1_model_file, monkeypatch):
    """A sender that starts with its reader (the emulator, its cues from its first frame) must not run
    while the scene is built: on a slow machine that took seconds, the frames were dropped and the
    cues came early. And a port that cannot open leaves no log behind."""
    import tasks.cli.live as live_cli
    from bomi.serial_source import SerialSource

    order: list[str] = []
    monkeypatch.setattr(live_cli, "ArmSim", lambda *a, **k: order.append("scene") or ArmSim(*a, **k))
    real_open = SerialSource.open
    monkeypatch.setattr(SerialSource, "open", lambda self: order.append("port") or real_open(self))
    assert main(["live", "--port", "loop://", "--profile", "P1", "--model", str(p1_model_file), "--headless",
                 "--duration", "0.1", "--log", str(tmp_path / "live.jsonl")]) == 0
    assert order[0] == "scene" and set(order[1:]) == {"port"} and (tmp_path / "live.jsonl").exists()
    assert main(["live", "--port", "socket://127.0.0.1:1", "--profile", "P1", "--model", str(p1_model_file),
                 "--headless", "--log", str(tmp_path / "never.jsonl")]) == 2
    assert not (tmp_path / "never.jsonl").exists()


# ------------------------------------------------------------------------ the loop, injected clock
class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


class ClockedSource:
    """Timed chunks sent by a clock's time, through one parser (as the pty delivers them)."""
    error, reconnections = None, 0

    def __init__(self, chunks: list[tuple[float, bytes]], clock):
        self.chunks, self.clock, self.parser, self._next = chunks, clock, FrameParser(), 0

    def poll(self):
        data = b""
        while self._next < len(self.chunks) and self.chunks[self._next][0] <= self.clock():
            data += self.chunks[self._next][1]
            self._next += 1
        seen = len(self.parser.safety_events)
        return self.parser.feed(data, self.clock()), self.parser.safety_events[seen:]


def still_frame(counter: int, node: int = 1) -> ImuFrame:
    """A frame of P1's node sitting still at fusion angles (0, 0, 0), noise-free: from its zero state the
    filter reads exactly 0, so the gate settles on its first full window."""
    mag, gyro, acc = _still_raw(node)
    return ImuFrame(9 + node, 16, counter % 256, mag, gyro, acc)


@cache
def _still_raw(node: int) -> tuple[tuple, tuple, tuple]:
    """(mag, gyro, acc) of ``still_frame``: the same for every counter, so synthesised once per node (the
    scripted loops ask for thousands of frames; loading the profile and synthesising took ~5 ms each)."""
    cal = load_profile("P1").nodes[node - 1].calibration
    raw = synthesize_raw(np.zeros((1, 3)), cal, np.random.default_rng(0), SensorNoise(0.0, 0.0, 0.0))
    return tuple(raw.mag[0].tolist()), tuple(raw.gyro[0].tolist()), tuple(raw.acc[0].tolist())


SETTLE = 4                                   # a short settle window for the scripted loops
QUICK_GATE = GateConfig(settle_samples=SETTLE, filter_age_samples=0)  # no start-up floor


class ScriptedSource:
    """Per tick a number of still frames of node 1 (counters in order) and the bytes of safety-key
    frames, which go through the parser with its guard."""

    def __init__(self, frames_per_tick: list[int], key_bytes: dict[int, bytes] | None = None):
        self.parser = FrameParser()
        self.error = None
        self.reconnections = 0
        self._script = iter(enumerate(frames_per_tick))
        self._keys = key_bytes or {}
        self._counter = 0

    def poll(self):
        t, n = next(self._script, (None, 0))
        seen = len(self.parser.safety_events)
        self.parser.feed(self._keys.get(t, b""))
        frames = [still_frame(self._counter + k) for k in range(n)]
        self._counter += n
        return frames, self.parser.safety_events[seen:]


class ScriptedChain:
    """Returns the scripted decisions, one per pushed sample of node 1."""

    def __init__(self, decisions: list[Decision | None]):
        self.profile = load_profile("P1")
        self.nodes = (1,)
        self.model = type("M", (), {"spec": type("S", (), {"window": 8})()})()
        self._decisions = iter(decisions)
        self.calibrating = False
        self.neutral = {1: (0.0, 0.0, 0.0)}
        self.pushed = 0

    def set_neutral(self, offsets) -> None:
        pass

    def forget_decisions(self) -> None:
        """The real chain empties its window and vote; the script has neither."""

    def push_angles(self, node, angles, gyro) -> Decision | None:
        self.pushed += 1
        return next(self._decisions)


class StickArm:
    """The arm's joystick logic alone: records what reaches it."""

    dt = CONTROL_DT

    def __init__(self):
        self.joystick = JoystickInterpreter(FULL_SPEED, 1.0)
        self.states: list[JoystickState] = []

    def step(self, state: JoystickState):
        self.states.append(state)
        return self.joystick.update(state)

    @property
    def mode(self):
        return self.joystick.mode


def test_loop_stops_the_arm_within_one_tick_of_silence_and_resumes_on_fresh_decisions():
    # ticks 0-2 warm-up (the 4th frame settles the gate and is the first to reach the chain), then
    # ticks 3-32 a frame each, 33-52 silence, 53-62 frames again
    script = [1] * (SETTLE - 1) + [1] * 30 + [0] * 20 + [1] * 10
    b = next(cls.label for cls in load_profile("P1").classes if cls.function == "B")
    decisions = ([decision(nu=0.5)] * 10 + [decision(label=b, function="B", nu=float("nan")), decision(label=99)]
                 + [decision(nu=0.5)] * 18 + [None] + [decision(nu=0.75)] * 9)
    clock, arm, log = FakeClock(), StickArm(), io.StringIO()
    summary = run_live(ScriptedSource(script), ScriptedChain(decisions), arm, duration_s=63 * CONTROL_DT,
                       neutral={1: (0.0, 0.0, 0.0)}, log=TickLog(log), clock=clock, sleep=clock.sleep, gate=QUICK_GATE)
    ticks = [json.loads(line) for line in log.getvalue().splitlines()]
    assert summary.ticks == len(ticks) == 63
    assert [tick["hold"] for tick in ticks[:SETTLE - 1]] == ["warming up (node 1)"] * (SETTLE - 1)
    assert [np.linalg.norm(tick["linear"]) for tick in ticks[:SETTLE - 1]] == [0.0] * (SETTLE - 1)
    ticks = ticks[SETTLE - 1:]
    speed = [np.linalg.norm(tick["linear"]) for tick in ticks]
    # before the silence: F at nu 0.5; the NaN B and the unknown class never reach the arm
    assert speed[:30] == pytest.approx([0.5 * FULL_SPEED] * 30)
    assert [d["reason"] for d in ticks[10]["dropped"] + ticks[11]["dropped"]] == ["nu is nan", "unknown class 99 (F)"]
    assert ticks[10]["deflection"] == ticks[11]["deflection"] == {"F": 0.5}
    assert summary.dropped == 2
    # silence: moving while the frame age 1.5 ticks ahead is < 100 ms, zero from the last tick before that
    last_frame_t = ticks[29]["t"]
    for tick, v in zip(ticks[30:50], speed[30:50]):
        age = tick["t"] - last_frame_t
        assert tick["stale"] == (age + 1.5 * CONTROL_DT >= 0.1 - 1e-9)
        assert (v == 0) == tick["stale"]
    first_stale = next(tick for tick in ticks if tick["stale"])
    assert 0.1 - 1.5 * CONTROL_DT - 1e-9 <= first_stale["t"] - last_frame_t <= 0.1 - 0.5 * CONTROL_DT + 1e-9
    assert all(state == JoystickState() for state in arm.states[first_stale["tick"]:53])
    assert all(tick["hold"] == "no frames" for tick in ticks if tick["stale"])
    # fresh frames without a decision do not restart the old motion; the next decision does
    assert not ticks[50]["stale"] and speed[50] == 0
    assert speed[51:] == pytest.approx([0.75 * FULL_SPEED] * 9)
    assert summary.watchdog_trips == 1


def test_safety_key_standby_holds_the_arm_until_control_and_calibration_restarts_the_neutral():
    # a key that sends one frame per press, its counter counting the ticks
    w = SETTLE - 1   # warm-up ticks before the script
    keys = {w + t: encode_safety_key_frame(event, t)
            for t, event in {5: SafetyKey.STANDBY, 10: SafetyKey.CONTROL, 15: SafetyKey.CALIBRATION}.items()}
    chain = ScriptedChain([decision(nu=0.5)] * 21)
    calibrations = []
    chain.begin_neutral_calibration = lambda: calibrations.append(True)
    clock, log = FakeClock(), io.StringIO()
    summary = run_live(ScriptedSource([1] * (w + 20), keys), chain, StickArm(), duration_s=(w + 20) * CONTROL_DT,
                       neutral={1: (0.0, 0.0, 0.0)}, log=TickLog(log), clock=clock, sleep=clock.sleep, gate=QUICK_GATE)
    ticks = [json.loads(line) for line in log.getvalue().splitlines()][w:]
    assert [tick["standby"] for tick in ticks] == [False] * 5 + [True] * 5 + [False] * 10
    speed = [np.linalg.norm(tick["linear"]) for tick in ticks]
    assert speed == pytest.approx([0.1] * 5 + [0.0] * 5 + [0.1] * 10)
    assert calibrations == [True] and summary.standby_ticks == 5
    assert [tick["tick"] - w for tick in ticks if "neutral" in tick] == [0, 15]  # the offsets are announced


def test_a_phantom_control_frame_does_not_end_a_standby_and_the_real_key_still_does():
    """A key streaming a frame per tick (event 0 between presses). A phantom CONTROL (id 40, event 3,
    a counter that does not follow the key's) lands in tick 10: the arm stays held; the real CONTROL at
    tick 15 follows the key's frame of tick 14 and ends the standby on its own tick."""
    w = SETTLE - 1
    events = {5: SafetyKey.STANDBY, 15: SafetyKey.CONTROL}
    keys = {w + t: encode_safety_key_frame(events.get(t, SafetyKey.NONE), t) for t in range(20)}
    keys[w + 10] += encode_safety_key_frame(SafetyKey.CONTROL, 200)
    clock, log = FakeClock(), io.StringIO()
    source = ScriptedSource([1] * (w + 20), keys)
    summary = run_live(source, ScriptedChain([decision(nu=0.5)] * 21), StickArm(), duration_s=(w + 20) * CONTROL_DT,
                       neutral={1: (0.0, 0.0, 0.0)}, log=TickLog(log), clock=clock, sleep=clock.sleep, gate=QUICK_GATE)
    ticks = [json.loads(line) for line in log.getvalue().splitlines()][w:]
    assert [tick["standby"] for tick in ticks] == [False] * 5 + [True] * 10 + [False] * 5
    speed = [np.linalg.norm(tick["linear"]) for tick in ticks]
    assert speed == pytest.approx([0.1] * 5 + [0.0] * 10 + [0.1] * 5)
    assert summary.standby_ticks == 10
    assert source.parser.key_events_unconfirmed == 1
    assert "1 safety-key events dropped by the guard" in source.parser.summary()


# -------------------------------------------------------------------- emulator -> pty -> bomi live
SEED = 0


def offline_decisions(model_path, hold_s: float, neutral_s: float, end_s: float, neutral: dict) -> list[dict]:
    """The same participant's raw samples straight into an OnlineChain (its own fusion from the first
    sample), with the neutral offsets live took: every decision, without its sample index."""
    from bomi.model_io import load_model
    params, profile = load_participant("P1"), load_profile("P1")
    blocks = participant_blocks(params, profile, SEED, calibration_schedule(profile, hold_s=hold_s,
                                                                            neutral_s=neutral_s), end_s)
    chain = OnlineChain(load_model(model_path), profile)
    chain.set_neutral({int(k): v for k, v in neutral.items()})
    out = []
    for block in blocks:
        for rows in zip(*(values.tolist() for values in block.values())):
            for node, row in zip(block, rows):
                made = chain.push(node, tuple(row[6:9]), tuple(row[3:6]), tuple(row[0:3]))
                if made is not None:
                    out.append({k: v for k, v in asdict(made).items() if k != "sample_index"})
    return out


def read_log_text(text: str) -> list[dict]:
    return [json.loads(line) for line in text.splitlines()]


def read_log(path) -> list[dict]:
    return read_log_text(path.read_text())


@pytest.mark.real_time
def test_emulate_participant_to_pty_then_live_decides_as_the_offline_chain(tmp_path, p1_model_file, capsys):
    """Seed 0 faces 18 deg: nothing is decided until the filter has settled (status: warming up); then the
    neutral is taken and live decides as the chain fed the same samples offline."""
    emulator = subprocess.Popen(
        [sys.executable, "-m", "tasks.cli", "emulate", "--participant", "P1", "--to", "pty", "--loss", "0",
         "--hold", "2", "--neutral", "17", "--duration", "28", "--seed", str(SEED)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        path = emulator.stdout.readline().strip()
        assert path.startswith("/dev/pts/")
        log = tmp_path / "live.jsonl"
        assert main(["live", "--port", path, "--profile", "P1", "--model", str(p1_model_file), "--headless",
                     "--duration", "21", "--log", str(log), "--retries", "0"]) == 0
        emulator.wait(timeout=30)
    finally:
        emulator.kill()
    out = capsys.readouterr()
    assert "live: neutral offsets" in out.err
    assert "HELD: warming up (node " in out.err and " Hz | lost 0 (0.0 %) | " in out.err   # status lines
    ticks = read_log(log)
    assert 0.8 * 21 * 60 < len(ticks) <= 21 * 60 + 1                      # 60 Hz (late ticks are skipped)
    warm = [tick for tick in ticks if (tick["hold"] or "").startswith("warming up")]
    # the filter's 12 s floor (750 samples from the first frame fused), then the signal, while still; the
    # floor runs on the samples' clock, which leads the loop's by the frames the first tick finds (those
    # that arrived while the loop started): up to a few ticks
    assert 12.0 - 0.05 <= warm[-1]["t"] < 16.0
    neutral_tick = next(tick for tick in ticks if "neutral" in tick)
    assert neutral_tick["t"] > warm[-1]["t"]
    assert all(np.linalg.norm(tick["linear"]) == 0 for tick in ticks if tick["t"] <= neutral_tick["t"])
    live = [{k: v for k, v in d.items() if k != "sample_index"} for tick in ticks for d in tick["decisions"]]
    assert len(live) > 150
    offline = offline_decisions(p1_model_file, 2.0, 17.0, 28.0, neutral_tick["neutral"])
    # live's filter starts at the first frame it polls (what arrived while it got ready is dropped), the
    # offline one at the first sample: after the warm-up they agree to far below the decisions' resolution
    start = next(k for k in range(len(offline) - len(live) + 1)
                 if [d["function"] for d in offline[k:k + len(live)]] == [d["function"] for d in live])
    for mine, theirs in zip(live, offline[start:start + len(live)]):
        assert mine["label"] == theirs["label"] and mine["rejected"] == theirs["rejected"]
        assert mine["confidence"] == pytest.approx(theirs["confidence"], abs=1e-3)
        assert mine["gamma"] == pytest.approx(theirs["gamma"], abs=0.05)
        assert mine["nu"] == pytest.approx(theirs["nu"], abs=0.01)
    # the F cue at 17 s: recognised once the head is up, and the arm is driven by it
    first_f = next(tick for tick in ticks if any(d["function"] == "F" for d in tick["decisions"]))
    assert 17.0 < first_f["t"] < 19.5
    assert max(np.linalg.norm(tick["linear"]) for tick in ticks) > 0.5 * FULL_SPEED


def test_watchdog_zeroes_the_arm_when_the_emulator_pauses(tmp_path, p1_model_file, capsys, monkeypatch):
    """The emulator's stream of P1 (warm-up, neutral, F from 17 s) pausing 0.5 s at 19.5 s, read by the
    loop `bomi live` runs, on a simulated clock: each chunk reaches the parser when the loop's clock
    reaches its time, so the pause, and nothing else, trips the watchdog: exactly once."""
    from bomi.model_io import load_model

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    params, profile = load_participant("P1"), load_profile("P1")
    cues = calibration_schedule(profile, hold_s=4.0, neutral_s=17.0)   # warm-up, neutral; F from 17 s (held ~18.2-21.4 s)
    chunks = block_chunks(participant_blocks(params, profile, SEED, cues, 23.0), EmulatorConfig(), EmulatorStats())
    paused = [(t + 0.5 if t >= 19.5 else t, data) for t, data in chunks]   # 0.5 s of silence at 19.5 s
    clock = FakeClock()

    log = io.StringIO()
    summary = run_live(ClockedSource(paused, clock), OnlineChain(load_model(p1_model_file), profile), StickArm(), duration_s=21.5,
                       log=TickLog(log), clock=clock, sleep=clock.sleep)
    ticks = [json.loads(line) for line in log.getvalue().splitlines()]
    arrived = [tick for tick in ticks if tick["frames"]]
    gaps = [(b["t"] - a["t"], a, b) for a, b in zip(arrived, arrived[1:])]
    _, before, after = max(gaps, key=lambda gap: gap[0])
    assert after["t"] - before["t"] > 0.4
    speed = {tick["tick"]: np.linalg.norm(tick["linear"]) for tick in ticks}
    assert speed[before["tick"]] > 0                                   # moving (F) when the stream stopped
    silent = [tick for tick in ticks if before["t"] < tick["t"] < after["t"]]
    dt = 1.5 / 60      # the loop judges 1.5 periods ahead
    for tick in silent:
        age = tick["t"] - before["t"]
        if abs(age + dt - 0.1) > 1e-6:
            assert tick["stale"] == (age + dt > 0.1)
        if tick["stale"]:
            assert speed[tick["tick"]] == 0 and tick["angular"] == [0, 0, 0] and tick["finger"] == 0
    # the zero command comes on the last control tick before 100 ms of silence have passed
    first_stale = next(tick for tick in silent if tick["stale"])
    previous = ticks[first_stale["tick"] - 1]
    assert first_stale["t"] - before["t"] <= 0.1 + 1e-6                # the simulated clock: no tick is late
    assert previous["t"] - before["t"] + dt < 0.1 + 1e-6
    assert any(speed[tick["tick"]] > 0 for tick in ticks if tick["t"] > after["t"])   # resumes with the stream
    assert summary.watchdog_trips == 1                                 # the pause, once
    # the command says the count, headless when there is no display
    assert main(["live", "--port", "loop://", "--profile", "P1", "--model", str(p1_model_file),
                 "--duration", "0.2"]) == 0
    out = capsys.readouterr()
    assert "live: no display (DISPLAY and WAYLAND_DISPLAY are unset): running headless" in out.err
    assert re.search(r"watchdog stopped the arm \d+ time\(s\)", out.out)



def test_a_stalled_loop_fuses_and_decides_the_backlog_whole_as_the_offline_chain(p1_model_file):
    """The loop stalls 0.6 s while P1 holds F (its clock jumps; the frames wait in the port): the next tick
    fuses every frame of the backlog, so each decision is the offline chain's for the same samples, to the
    bit, before and after the stall (a filter that skipped the backlog would lag it); only the newest
    decision of that tick reaches the stick, and the stick, not a hold, drives the arm on."""
    from bomi.model_io import load_model

    params, profile = load_participant("P1"), load_profile("P1")
    cues = calibration_schedule(profile, hold_s=2.0, neutral_s=17.0)
    chunks = list(block_chunks(participant_blocks(params, profile, SEED, cues, 21.0), EmulatorConfig(),
                               EmulatorStats()))

    class StallingClock(FakeClock):
        def sleep(self, seconds: float) -> None:
            self.now += seconds + (0.6 if self.now <= 18.5 < self.now + seconds else 0.0)

    log = io.StringIO()
    clock = StallingClock()
    run_live(ClockedSource(chunks, clock), OnlineChain(load_model(p1_model_file), profile), StickArm(),
             duration_s=20.5, log=TickLog(log), clock=clock, sleep=clock.sleep)
    ticks = read_log_text(log.getvalue())
    stalled = next(tick for tick in ticks if tick["t"] > 18.5)
    assert 0.6 <= stalled["t"] - ticks[stalled["tick"] - 1]["t"] < 0.65 and stalled["frames"] >= 3 * 37
    assert len(stalled["decisions"]) >= 37 and stalled["skipped"] == len(stalled["decisions"]) - 1
    assert stalled["hold"] is None and any(d["function"] == "F" for d in stalled["decisions"])
    assert np.linalg.norm(stalled["linear"]) > 0
    live = [{k: v for k, v in d.items() if k != "sample_index"} for tick in ticks for d in tick["decisions"]]
    neutral = next(tick for tick in ticks if "neutral" in tick)["neutral"]
    offline = offline_decisions(p1_model_file, 2.0, 17.0, 21.0, neutral)
    start = next(k for k in range(len(offline) - len(live) + 1)
                 if [d["function"] for d in offline[k:k + len(live)]] == [d["function"] for d in live])
    assert live == offline[start:start + len(live)]

# ------------------------------------------------------------------------------------- bad input
def test_live_refuses_bad_files_in_one_line_and_overwrites_nothing(tmp_path, p1_model_file, capsys):
    bad_model = tmp_path / "bad.json"
    bad_model.write_text("{not json")
    assert main(["live", "--port", "loop://", "--profile", "P1", "--model", str(bad_model), "--headless"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"bomi: error: {bad_model}") and err.count("\n") == 1
    log = tmp_path / "old.jsonl"
    log.write_text("keep me\n")
    assert main(["live", "--port", "loop://", "--profile", "P1", "--model", str(p1_model_file), "--headless",
                 "--log", str(log)]) == 2
    assert capsys.readouterr().err == f"bomi: error: {log}: file exists, not overwriting it\n"
    assert log.read_text() == "keep me\n"
    assert main(["live", "--port", "loop://", "--profile", "P1", "--model", str(p1_model_file), "--headless",
                 "--neutral-from", str(tmp_path / "none.csv")]) == 2
    assert capsys.readouterr().err.startswith(f"bomi: error: {tmp_path / 'none.csv'}")
    assert main(["emulate", "--participant", "P9", "--to", "pty"]) == 2
    assert "no such participant file" in capsys.readouterr().err
