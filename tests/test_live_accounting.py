"""What a live session counts and keeps (issue 55 item 4): the samples lost are those the packet
counters show lost within a stream, not counter arithmetic across a restart (a reconnection, another
sitting), and a trial cut short by a lost input keeps its wall and CPU times and its report."""
from __future__ import annotations

import json

import numpy as np
import pytest

from bomi.errors import BomiError
from bomi.frames import FrameParser, ImuFrame, encode_imu_frame
from sim.joystick import JoystickState
from tasks.trials.live import LiveLoop
from tests.test_live import QUICK_GATE, StickArm, decision, still_frame
from tests.test_live_breaks import CalibratingChain


def _bytes(node_id: int, counters) -> bytes:
    return b"".join(encode_imu_frame(ImuFrame(node_id, 16, c % 256, (1, 2, 3), (4, 5, 6), (7, 8, 9)))
                    for c in counters)


# ------------------------------------------------------------------------------ the lost count
@pytest.mark.parametrize("restart_at", [0, 1, 100])
def test_a_stream_whose_counters_restart_is_a_new_stream_not_229_samples_lost(restart_at):
    """28 frames (counters 0..27, 2 lost within: 10 and 11), then the stream back with its counters restarted
    at ``restart_at``: every frame delivered, 2 lost, one restart, whatever the restart's counter (the old
    arithmetic: (restart_at - 27 - 1) % 256 more, 228 for a restart at 0, 229 at 1)."""
    parser = FrameParser()
    first = [c for c in range(28) if c not in (10, 11)]
    frames = parser.feed(_bytes(11, first)) + parser.feed(_bytes(11, range(restart_at, restart_at + 20)))
    stats = parser.nodes[11]
    assert len(frames) == len(first) + 20 and stats.frames == len(frames)
    assert (stats.lost, stats.restarts) == (2, 1) and parser.total_lost == 2
    assert ", 2 lost (" in parser.summary() and "1 counter restart(s)" in parser.summary()


def test_a_loss_within_the_guards_reach_is_counted_and_a_repeat_is_a_restart():
    """A step of 16 (the phantom guard's reach) loses 15 samples; a repeated counter (delivered: the guards
    off) is a restart, not a full wrap of 255 samples lost."""
    parser = FrameParser()
    parser.feed(_bytes(12, [0, 1, 2, 18, 19]))           # 2 -> 18: 15 lost
    assert (parser.nodes[12].lost, parser.nodes[12].restarts) == (15, 0)
    unguarded = FrameParser(confirm_frames=1)
    assert len(unguarded.feed(_bytes(12, [0, 1, 2, 2, 3]))) == 5
    assert (unguarded.nodes[12].lost, unguarded.nodes[12].restarts) == (0, 1)
    assert "counter restart" not in parser.summary()


def test_the_loops_lost_count_does_not_grow_across_a_reconnection():
    """The live loop's ``lost`` (the gate's, logged per tick): 3 samples lost within the first stream; after
    a reconnection the counters restart at 0 and nothing more is counted lost."""
    loop = LiveLoop(CalibratingChain([decision()] * 200), StickArm(), neutral={1: (0.0, 0.0, 0.0)}, gate=QUICK_GATE)
    dt = 1 / 60
    counters = [c for c in range(40) if c not in (5, 6, 7)]
    ticks = [loop.tick(k * dt, [still_frame(c)]) for k, c in enumerate(counters)]
    assert ticks[-1].lost == 3
    after = [loop.tick((len(ticks) + k) * dt, [still_frame(k)], reconnected=k == 0) for k in range(20)]
    assert [t.lost for t in after] == [3] * 20 and after[0].hold is not None


# ------------------------------------------------------------------------------ a trial cut short
def test_a_trial_cut_short_keeps_its_wall_and_cpu_time():
    from sim.env import ArmSim
    from tasks.trials.session import Controller, Session, TickRecorder, TrialArm, TrialPlan

    sim = ArmSim()
    arm = TrialArm(sim, TrialPlan(trials=2, countdown_s=0.1), ready=True)
    session = Session(Controller.JOYSTICK, arm, TickRecorder(arm), "wall")
    for k in range(60):
        state = JoystickState({"F": 1.0})
        session.recorder.record(k * sim.dt, state, arm.step(state))
    session.cut_short("input lost")
    [result] = session.finished
    assert result.failure == "input lost" and result.end_tick == 60 and not result.success
    assert result.wall_time > 0.0 and result.cpu_time > 0.0
    assert arm.finished and len(arm.results) == 1


class FailingStick:
    """A joystick held forward that is unplugged after ``reads`` reads."""

    def __init__(self, reads: int):
        self.left = reads

    def read(self, now: float) -> JoystickState:
        if self.left == 0:
            raise BomiError("gamepad 0: unplugged")
        self.left -= 1
        return JoystickState({"F": 1.0})

    def close(self) -> None:
        """Nothing to release."""


@pytest.mark.real_time
def test_a_session_cut_short_by_a_lost_joystick_writes_its_times_and_report(tmp_path, monkeypatch, capsys):
    """A person's joystick lost 1 s into trial 1 (real time, 1.5 s): the command ends with one error
    line, and the cut-short trial is in trials.jsonl with its wall and CPU time, and in report.md."""
    import tasks.cli.trial as trial_cli
    from tasks.cli import main

    countdown_s = 0.5
    monkeypatch.setattr(trial_cli, "_person_stick", lambda index, headless: FailingStick(90))
    out = tmp_path / "person"
    code = main(["trial", "--controller", "joystick", "--trials", "2", "--countdown", str(countdown_s),
                 "--headless", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.strip().splitlines()[-1] == "bomi: error: gamepad 0: unplugged"
    [record] = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    assert record["failure"] == "input lost" and record["trial"] == 1
    # 90 ticks read: 30 of countdown, then 60 of the trial (1 s at 60 Hz on the wall clock)
    assert 0.9 < record["wall_time"] < 5.0 and 0.0 < record["cpu_time"] <= record["wall_time"] + 0.5
    report = (out / "report.md").read_text()
    assert "input lost" in report and np.isfinite(record["wall_time"])
