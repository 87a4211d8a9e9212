"""The live path's safety (issue 27 item 1): the gate by hand, the loop on an injected clock, the
reader when the stream goes away, the log when the disk is full, the film when it falls behind.
End-to-end numbers: python benchmarks/faults.py live."""
from __future__ import annotations

import errno
import io
import json
import math
import os
import queue
import threading
import time

import numpy as np
import pytest

from bomi.fusion import DT, NodeCalibration, NodeFusion
from bomi.gate import ButtonEvidence, Gate, GateConfig, NodeGate, half_mean_ratio, raw_defect, settle_change
from bomi.serial_source import RetryPolicy, SerialSource, StreamReader
from tasks.trials.live import LiveLoop
from tasks.trials.displays import TickLog, VideoDisplay
from tasks.trials.person import FUSED_BACKLOG_FRAMES
from tests.test_live import QUICK_GATE, SETTLE, FakeClock, ScriptedChain, StickArm, decision, still_frame

STILL = still_frame(0)


# ------------------------------------------------------------------------------------------ gate
def test_settle_threshold_is_the_tolerance_times_the_decay_ratio():
    # half means of e_end * exp(-(t - t_end) / tau) over [t_end - tau, t_end], integrated by hand:
    # newer half: e_end * 2 (e^0.5 - 1), older: e_end * 2 (e - e^0.5); difference 2 (e^0.5 - 1)^2 e_end
    assert half_mean_ratio(1.6, 1.6) == pytest.approx(2 * (math.exp(0.5) - 1) ** 2)
    config = GateConfig()
    assert config.settle_samples == 100 and config.settle_change_deg == pytest.approx(0.5 * 0.8417, abs=1e-4)
    assert config.max_jump_deg == pytest.approx(9.6)


def test_a_decaying_yaw_settles_when_the_error_left_is_half_a_degree():
    """Yaw 120 deg away decaying with the filter's 100-sample constant: the signal test says settled
    at the sample where 120 exp(-n / 100) drops below 0.5 deg (n = 100 ln 240 = 548), not before."""
    gate = NodeGate(1, GateConfig(filter_age_samples=0))
    settled_at = None
    for n in range(1000):
        gate.fused((0.0, 0.0, 120.0 * math.exp(-n / 100)))
        if gate.settled and settled_at is None:
            settled_at = n
    assert 540 <= settled_at <= 556
    assert 120.0 * math.exp(-settled_at / 100) < 0.52


def test_a_back_and_forth_turn_during_the_decay_is_not_taken_for_a_settled_filter():
    """+-15 deg at 0.4 Hz on top of a decaying yaw fools the half-mean test within 3 s; the filter's
    age keeps the node warming up until the worst start has decayed (12 s: 750 samples)."""
    def yaw(n: int) -> float:
        return 120.0 * math.exp(-n / 100) + 15.0 * math.sin(2 * math.pi * 0.4 * n * DT)

    signal_only, gate = NodeGate(1, GateConfig(filter_age_samples=0)), NodeGate(1)
    fooled_at = settled_at = None
    for n in range(1200):
        signal_only.fused((0.0, 0.0, yaw(n)))
        gate.fused((0.0, 0.0, yaw(n)))
        if signal_only.settled and fooled_at is None:
            fooled_at = n
        if gate.settled and settled_at is None:
            settled_at = n
    assert fooled_at is not None and fooled_at * DT < 3.0
    assert settled_at is None or settled_at >= 749


def test_the_real_filter_from_its_zero_state_has_settled_within_the_gates_floor():
    """The fusion itself, a node facing about 179 deg and lying on its side (pitch and roll far from
    the zero state too): its yaw stays within 0.5 deg of the final heading from sample 594 on, inside
    the gate's floor of 750 and above the pure decay's 586 (the pitch/roll transient delays it)."""
    fusion = NodeFusion(NodeCalibration.uncalibrated())
    yaw = np.array([fusion.update((0, 0, 2048), (0, 0, 0), (-50, -3000, 0))[2] for _ in range(2000)])
    error = np.abs(yaw - yaw[-1])
    first_within = int(np.flatnonzero(error >= 0.5)[-1]) + 1
    assert abs(yaw[-1]) > 178.0
    assert 586 < first_within < GateConfig().filter_age_samples == 750


def test_raw_defects_zero_and_saturated_values():
    ok = ((100, -200, 4000), (3, -2, 0), (-16000, 50, 300))
    assert raw_defect(*ok) is None
    assert raw_defect((1, 2, 3), (0, 0, 0), (0, 0, 0)) == "accelerometer all zero"
    assert raw_defect((0, 0, 0), (0, 0, 0), (1, 0, 0)) == "magnetometer all zero"
    assert raw_defect((1, 2, 3), (0, 32767, 0), (1, 0, 0)) == "gyroscope saturated"
    assert raw_defect((1, -32768, 3), (0, 0, 0), (1, 0, 0)) == "magnetometer saturated"
    assert raw_defect((1, 2, 3), (0, 0, 0), (32767, 0, 0)) == "accelerometer saturated"
    assert settle_change(np.array([[0, 0, 0], [0, 0, 0], [1, -3, 0], [1, -3, 0]])) == 3.0


def _plausible_samples(gate: NodeGate, n: int, counter: int, now: float) -> int:
    for k in range(n):
        assert gate.count(counter + k) is None and gate.check_raw(STILL.mag, STILL.gyro, STILL.acc)
        gate.fused((0.0, 0.0, 0.0))
        gate.arrived(now, 1)
    return counter + n


def test_an_implausible_frame_holds_the_node_until_a_full_window_is_plausible_and_steady():
    config = GateConfig(settle_samples=10, filter_age_samples=0)
    gate = NodeGate(2, config)
    counter = _plausible_samples(gate, 10, 0, 0.0)
    assert gate.verdict(0.0) is None
    assert not gate.check_raw(STILL.mag, STILL.gyro, (0, 0, 0))                    # never reaches the filter
    assert gate.verdict(0.0) == "node 2: accelerometer all zero"
    counter = _plausible_samples(gate, 9, counter + 1, 0.0)
    assert gate.verdict(0.0) == "node 2: accelerometer all zero"                    # 9 of 10: still held
    counter = _plausible_samples(gate, 1, counter, 0.0)
    assert gate.verdict(0.0) == "node 2: accelerometer all zero"                    # steady, but not 1.6 s yet
    _plausible_samples(gate, 1, counter, config.resume_s)
    assert gate.verdict(config.resume_s) is None
    assert gate.verdict(config.resume_s + 0.1) == "no frames from node 2"            # 100 ms: missing


def test_angle_jumps_and_floods_are_implausible_counters_out_of_step_and_gaps_are_breaks():
    config = GateConfig(settle_samples=4, filter_age_samples=0)
    gate = NodeGate(1, config)
    counter = _plausible_samples(gate, 4, 0, 0.0)
    gate.count(counter)
    gate.fused((0.0, 0.0, 9.5))                                                      # 594 deg/s: a person can
    assert gate.verdict(0.0) is None
    gate.count(counter + 1)
    gate.fused((0.0, 0.0, 19.2))                                                     # 606 deg/s: no one can
    assert gate.verdict(0.0) == "node 1: angle jump in one sample (10 deg)"
    gate = NodeGate(1, config)
    counter = _plausible_samples(gate, 4, 0, 0.0)
    assert gate.count(counter + 2) is None                                           # 2 lost: fine
    assert gate.lost == 2 and gate.settled
    assert gate.count(counter + 2) == "a packet-counter jump (a step of 0)"          # repeated: a new stream
    assert gate.count(counter + 2 + 17) == "a packet-counter jump (a step of 17)"    # 256 ms lost at once
    gate.restart(counter + 19)
    assert gate.lost == 2 and not gate.settled and gate.fused_samples == 0
    assert gate.verdict(0.0) == "warming up (node 1)"
    assert gate.arrived(0.99, 1) is None and gate.arrived(2.0, 1) == "a 1.0 s gap in its frames"
    gate = NodeGate(1, config)
    _plausible_samples(gate, 4, 0, 0.0)
    gate.arrived(0.5, 100)                                                           # 104 in 1 s > 1.5 x 62.5 + 2
    assert gate.verdict(0.5) == "node 1: more frames than its rate allows (104 in 1 s)"


def test_gate_of_several_nodes_names_the_first_untrusted_one():
    gate = Gate((1, 2), GateConfig(settle_samples=4, filter_age_samples=0))
    assert gate.verdict(0.0) == "no frames from node 1"
    _plausible_samples(gate.node[1], 4, 0, 0.0)
    gate.node[2].arrived(0.0, 1)
    assert gate.verdict(0.0) == "warming up (node 2)" and not gate.settled


def test_button_evidence_needs_consecutive_decisions():
    evidence = ButtonEvidence(3, frozenset({"B1", "B2"}))
    assert evidence.admit(["F", "B1", "B1", "B1", "B1", "B2", "F", "B1"]) == \
        [True, False, False, True, True, False, True, False]
    evidence.reset()
    assert evidence.admit(["B1", "B1"]) == [False, False]


# ---------------------------------------------------------------------------- the loop, by ticks
def loop_for(decisions, **kwargs) -> tuple[LiveLoop, StickArm, ScriptedChain]:
    chain, arm = ScriptedChain(decisions), StickArm()
    return LiveLoop(chain, arm, neutral={1: (0.0, 0.0, 0.0)}, gate=kwargs.pop("gate", QUICK_GATE), **kwargs), arm, chain


def test_nothing_moves_and_nothing_reaches_the_chain_until_the_filter_settles():
    loop, arm, chain = loop_for([decision(nu=0.5)] * 10)
    ticks = [loop.tick(k * DT, [still_frame(k)]) for k in range(6)]
    assert [t.hold for t in ticks[:SETTLE - 1]] == ["warming up (node 1)"] * (SETTLE - 1)
    assert chain.pushed == 6 - (SETTLE - 1)
    assert [t.command.linear[1] != 0 for t in ticks] == [False] * (SETTLE - 1) + [True] * (6 - SETTLE + 1)


def test_zero_frames_stop_the_arm_on_the_tick_they_arrive_and_control_resumes_after_a_window():
    seen = []
    loop, arm, chain = loop_for([decision(nu=0.5)] * 100, observers=[seen.append])
    k = 0
    for _ in range(8):
        loop.tick(k * DT, [still_frame(k)])
        k += 1
    assert np.linalg.norm(seen[-1].command.linear) > 0
    zero = still_frame(k)
    bad = type(zero)(zero.node_id, zero.period_ms, zero.counter, zero.mag, zero.gyro, (0, 0, 0))
    tick = loop.tick(k * DT, [bad])
    k += 1
    assert tick.hold == "node 1: accelerometer all zero" and not tick.command.linear.any()
    resumed = []
    for _ in range(SETTLE + 2):
        resumed.append(loop.tick(k * DT, [still_frame(k)]))
        k += 1
    assert [t.hold is None for t in resumed] == [False] * (SETTLE - 1) + [True] * 3
    assert len(seen) == 8 + 1 + SETTLE + 2                                            # the observer saw every tick


def test_a_backlog_is_decided_whole_but_only_its_newest_decision_acts():
    """0.8 s of frames in one tick (the host stalled): the filter and the chain take every one (a filter
    that missed them would lag), the stick the newest decision only; nothing holds the arm."""
    b1 = next(cls.label for cls in ScriptedChain([]).profile.classes if cls.function == "B1")
    loop, arm, chain = loop_for([decision(nu=0.5)] * 6 + [decision(label=b1, function="B1", nu=0.0)] * 40
                                + [decision(nu=0.25)] * 10)
    for k in range(6):
        loop.tick(k * DT, [still_frame(k)])
    pushed = chain.pushed
    tick = loop.tick((5 + 50) * DT, [still_frame(6 + j) for j in range(50)])
    assert chain.pushed - pushed == 50 and len(tick.decisions) == 50
    assert tick.skipped == 49 and not arm.states[-1].pressed                           # no B1 from the backlog
    assert tick.hold is None and arm.states[-1].deflection                             # the newest decision drives


def test_a_backlog_faster_than_the_rate_is_not_replayed_only_the_newest_window_reaches_the_chain():
    b1 = next(cls.label for cls in ScriptedChain([]).profile.classes if cls.function == "B1")
    backlog_decisions = [decision(label=b1, function="B1", nu=0.0)] * 40 + [decision(nu=0.25)] * 200
    loop, arm, chain = loop_for([decision(nu=0.5)] * 6 + backlog_decisions)
    for k in range(6):
        loop.tick(k * DT, [still_frame(k)])
    pushed = chain.pushed
    assert FUSED_BACKLOG_FRAMES < 100
    tick = loop.tick(6 * DT, [still_frame(6 + j) for j in range(100)])               # 1.6 s of frames at once
    assert chain.pushed - pushed == 8                                                  # the newest window
    assert tick.skipped == 92 + 7 and not arm.states[-1].pressed                       # no B1 from the backlog
    assert tick.hold == "node 1: a backlog (92 frames not fused)"                      # the filter lags them
    # held while the burst is within the last second, then for resume_s more
    later = [loop.tick((7 + j) * DT, [still_frame(106 + j)]) for j in range(int((1 + QUICK_GATE.resume_s) / DT) + 3)]
    released = next(t.t for t in later if t.hold is None)
    assert 1.0 + QUICK_GATE.resume_s - 2 * DT <= released - tick.t <= 1.0 + QUICK_GATE.resume_s + 2 * DT


def test_a_button_acts_only_after_the_profile_hold():
    b1 = next(cls.label for cls in ScriptedChain([]).profile.classes if cls.function == "B1")
    needed = math.ceil(ScriptedChain([]).profile.button_hold_s / DT - 1e-9)
    blip = [decision(label=b1, function="B1", nu=0.0)] * (needed - 1) + [decision(label=0, function="neutral", nu=0.0)]
    held = [decision(label=b1, function="B1", nu=0.0)] * (needed + 2)
    script = [decision(label=0, function="neutral", nu=0.0)] * SETTLE + blip + held
    loop, arm, chain = loop_for(script)
    presses = []
    for k in range(SETTLE - 1 + len(script)):       # the first SETTLE - 1 frames warm the gate up
        loop.tick(k * DT, [still_frame(k)])
        presses.append(bool(arm.states[-1].pressed))
    assert sum(presses) == 1
    assert presses.index(True) == SETTLE - 1 + SETTLE + len(blip) + needed - 1


# ------------------------------------------------------------------------- stream, log, film
def test_a_lost_stream_never_holds_up_a_poll_and_stop_cuts_the_backoff_short():
    master, slave = os.openpty()
    source = SerialSource(os.ttyname(slave), retry=RetryPolicy(attempts=6, first_delay_s=2.0), log=lambda m: None)
    reader = StreamReader(source).start()
    os.write(master, b"\x00" * 10)
    time.sleep(0.1)
    os.close(master)                                                                    # the emulator goes away
    os.close(slave)
    longest = 0.0
    end = time.monotonic() + 1.0
    while time.monotonic() < end:                                                      # the source reconnects meanwhile
        start = time.monotonic()
        assert reader.poll() == ([], [])
        longest = max(longest, time.monotonic() - start)
        time.sleep(DT)
    start = time.monotonic()
    reader.stop()
    assert longest < 0.05 and time.monotonic() - start < 0.5             # a backoff would take 2 s


class FullDisk(io.StringIO):
    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_full_disk_gives_one_warning_and_control_goes_on():
    warnings = []
    log = TickLog(FullDisk(), "live.jsonl", warn=warnings.append)
    loop, arm, chain = loop_for([decision(nu=0.5)] * 40)
    clock = FakeClock()

    class Frames:
        parser, error, k, reconnections = None, None, 0, 0

        def poll(self):
            self.k += 1
            return [still_frame(self.k)], []

    source = Frames()
    from bomi.frames import FrameParser
    source.parser = FrameParser()
    summary = loop.run(source, duration_s=30 * DT, log=log, clock=clock, sleep=clock.sleep)
    assert summary.ticks >= 28 and warnings == [
        "bomi: warning: live.jsonl: cannot write (No space left on device); logging stopped, control goes on"]
    assert log.failed == "No space left on device"
    assert np.linalg.norm(arm.joystick.update(arm.states[-1]).linear) > 0               # still driving


def test_filming_never_waits_a_film_frame_is_dropped_instead():
    """A film frame due on every tick (1000 fps, a tick every 2 ms of the loop's clock) and a queue of
    one that nobody empties: the first frame is queued, the other 49 dropped, and no tick waits (a
    blocking put would never return: the ticks run in a thread given 10 s)."""
    film = VideoDisplay.__new__(VideoDisplay)
    film.arm = type("A", (), {"data": type("D", (), {"qpos": np.zeros(3)})()})()
    clock = FakeClock()
    film.clock, film.fps, film._next, film.frames, film.dropped = clock, 1000.0, None, 0, 0
    film._frames = queue.Queue(1)

    def ticks():
        for _ in range(50):
            film.sync(lambda: "a | b | c | d | e | f")
            clock.sleep(0.002)
    ticking = threading.Thread(target=ticks, daemon=True)
    ticking.start()
    ticking.join(10.0)
    assert not ticking.is_alive()
    assert film.frames == 1 and film.dropped == 49
    assert json.dumps(film._frames.get_nowait()[2])   # the caption: two lines of the status


@pytest.mark.real_time
def test_a_real_film_process_receives_the_arms_layout_and_writes_a_playable_film(tmp_path, monkeypatch):
    """The film's own (spawned) process gets the real arm's layout and writes the MP4: the layout must
    pickle (its per-tick tables once did not, and `bomi live --video` stopped with an internal error)."""
    import imageio.v3 as iio

    import tasks.trials.displays
    # its start (imports, the scene, numba's kernels from a cold cache) beside three busy test workers on
    # two cores has taken over the 60 s a user waits (twice, 2026-12-07); what is tested here is the film
    monkeypatch.setattr(tasks.trials.displays, "FILM_START_S", 300.0)

    from sim.env import ArmSim

    sim, clock = ArmSim(), FakeClock()
    film = VideoDisplay(sim, tmp_path / "film.mp4", clock=clock)
    for _ in range(5):
        film.sync(lambda: "a | b | c | d | e | f")
        deadline = time.monotonic() + 30.0   # the film process takes each frame before the next is due
        while film._frames.qsize() and time.monotonic() < deadline:
            time.sleep(0.01)
        clock.sleep(0.25)                    # the loop's (simulated) clock: a film frame due at every sync
    film.close()
    sim.close()
    # every state sent and none dropped; the film fills each slot up to the last state's time (1.0 s)
    assert film.frames == 5 and film.dropped == 0
    assert iio.imread(tmp_path / "film.mp4").shape[0] == math.floor(1.0 * film.fps) + 1


def test_a_poll_parses_the_newest_bytes_only_and_counts_the_rest():
    from bomi.frames import ImuFrame, encode_imu_frame
    from bomi.serial_source import POLL_BYTES
    master, slave = os.openpty()
    reader = StreamReader(SerialSource(os.ttyname(slave), log=lambda m: None)).start()
    frames = b"".join(encode_imu_frame(ImuFrame(10, 16, k % 256, STILL.mag, STILL.gyro, STILL.acc)) for k in range(2000))
    view = memoryview(frames)
    while view:                                         # 64 kB at once: a backlog of 32 s of one node
        view = view[os.write(master, view[:4096]):]
    time.sleep(0.3)
    start = time.monotonic()
    got, _ = reader.poll()
    took = time.monotonic() - start
    reader.stop()
    os.close(master)
    assert len(got) == POLL_BYTES // 32 and got[-1].counter == 1999 % 256     # the newest ones
    assert reader.dropped_bytes == len(frames) - POLL_BYTES and took < 0.05


def test_the_loop_is_deterministic_given_each_ticks_frames(p1_model_file):
    """What a replay relies on: the same frames on the same ticks give the same decisions, commands and
    hand path, with the real chain and arm (P1 at seed 3, facing -112 deg: warm-up, neutral, then F)."""
    from bomi.chain import OnlineChain
    from bomi.classifier import NEUTRAL_LABEL
    from bomi.emulator import EmulatorConfig, EmulatorStats, block_chunks
    from bomi.frames import FrameParser
    from bomi.model_io import load_model
    from bomi.profiles import load_profile
    from bomi.protocol import Cue
    from sim.env import ArmSim
    from tasks.participants.participant import load_participant
    from tasks.participants.wire import participant_blocks
    from tasks.operators.stick import profile_layout

    profile = load_profile("P1")
    f_label = next(cls.label for cls in profile.classes if cls.function == "F")
    cues = [Cue(NEUTRAL_LABEL, "neutral", 0.0, 16.0), Cue(f_label, "F", 16.0, 24.0)]    # settled at 12 s
    chunks = list(block_chunks(participant_blocks(load_participant("P1"), profile, 3, cues, 20.0),
                               EmulatorConfig(), EmulatorStats()))
    parser, per_tick, i = FrameParser(), [], 0
    for k in range(20 * 60):
        data = b""
        while i < len(chunks) and chunks[i][0] <= k / 60:
            data += chunks[i][1]
            i += 1
        per_tick.append(parser.feed(data, k / 60))

    def run() -> list[tuple]:
        sim = ArmSim(layout=profile_layout(profile))
        path = []
        loop = LiveLoop(OnlineChain(load_model(p1_model_file), profile), sim,
                        observers=[lambda tick: path.append((tick.hold, tuple(tick.command.linear),
                                                             tuple(sim.data.qpos)))])
        for k, frames in enumerate(per_tick):
            loop.tick(k / 60, frames)
        sim.close()
        return path

    first, second = run(), run()
    assert first == second
    holds = [hold for hold, _, _ in first]
    assert holds[0] is not None and holds[0].startswith(("warming up", "no frames")) and holds[-1] is None
    assert any(any(linear) for _, linear, _ in first)                                  # F drove the arm


def test_the_emulated_participant_starts_as_a_real_stream_does_the_warm_up_is_visible():
    """Raw samples from the first one, the receiver's filter from its zero state: a participant facing
    100 deg reads yaw 0 at first, and the heading (+ P1's neutral yaw) only after the filter's decay."""
    from bomi.classifier import NEUTRAL_LABEL
    from bomi.profiles import load_profile
    from bomi.protocol import Cue
    from tasks.participants.participant import load_participant
    from tasks.participants.wire import MAX_HEADING_DEG, participant_blocks, session_heading

    params, profile = load_participant("P1"), load_profile("P1")
    block = next(participant_blocks(params, profile, 0, [Cue(NEUTRAL_LABEL, "neutral", 0.0, 12.0)], 12.0,
                                    block_s=12.0, heading_deg=100.0))
    fusion = NodeFusion(profile.nodes[0].calibration)
    yaw = np.array([fusion.update(row[6:9], row[3:6], row[0:3])[2] for row in block[1].tolist()])
    expected = 100.0 + params.neutral.posture_deg[0, 2]
    assert abs(yaw[0]) < 2.0                                       # the filter starts at 0
    assert abs(yaw[round(1.6 / DT)] - expected * (1 - math.exp(-1))) < 5.0   # one time constant: 63 %
    assert abs(yaw[-60:].mean() - expected) < 3.0                  # settled after ~10 s
    headings = [session_heading(seed) for seed in range(200)]
    assert max(map(abs, headings)) <= MAX_HEADING_DEG and np.std(headings) > 60   # spread over the compass
