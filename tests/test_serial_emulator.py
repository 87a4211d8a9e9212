"""Serial source (loop://, pty, socket://), emulator and `bomi capture`/`bomi emulate` round trips."""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import tty
from types import SimpleNamespace

import numpy as np
import pytest

from tasks.cli import main
from bomi.emulator import READER_SETTLE_S, EmulatorConfig, EmulatorStats, frame_chunks, open_sink, play, raw_samples
from bomi.errors import BomiError
from bomi.frames import FrameParser, ImuFrame, RowAssembler, encode_imu_frame
from bomi.fusion import NodeFusion
from bomi.gate import NodeGate
from bomi.recording import NodeData, Recording, read_recording, write_recording
from bomi.serial_source import RetryPolicy, SerialSource
from tasks.operators.stick import arm_profile

pytestmark = pytest.mark.real_time  # emulators and recorders paced on the wall clock

FAST_RETRY = RetryPolicy(attempts=2, first_delay_s=0.01, max_delay_s=0.01)


def imu(node_id: int, counter: int, value: int = 0) -> ImuFrame:
    return ImuFrame(node_id, 16, counter, (value, -value, 1), (2, value, -3), (value, 4, -5))


def collect(source: SerialSource, count: int, duration_s: float = 5.0) -> list[ImuFrame]:
    frames: list[ImuFrame] = []
    for _, batch in source.batches(duration_s):
        frames += batch
        if len(frames) >= count:
            break
    return frames


def int_recording(samples: int, nodes=(1, 2, 3), seed: int = 1) -> Recording:
    rng = np.random.default_rng(seed)
    data = {i: NodeData(*(rng.integers(-32768, 32768, (samples, 3)).astype(float) for _ in range(3)),
                        np.zeros((samples, 3))) for i in nodes}
    return Recording(data, np.zeros(samples, dtype=int))


# --------------------------------------------------------------------------------- serial source
def test_retry_policy_doubles_up_to_the_cap():
    assert RetryPolicy(attempts=6, first_delay_s=0.5, max_delay_s=4).delays() == [0.5, 1, 2, 4, 4, 4]


def test_loop_url_garbage_and_frames():
    sent = [imu(10, k, 100 * k) for k in range(5)]
    with SerialSource("loop://") as source:
        source.port.write(b"\x33\x00garbage" + b"".join(encode_imu_frame(f) for f in sent))
        assert collect(source, 5) == sent
    assert source.parser.discarded_bytes == 9


def test_pty_stream_then_vanished_port_retries_and_gives_up_in_one_line():
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    messages, sleeps = [], []
    source = SerialSource(path, retry=FAST_RETRY, log=messages.append, sleep=sleeps.append)
    with source:
        os.write(master, b"".join(encode_imu_frame(imu(11, k)) for k in (0, 1, 3)))
        assert [f.counter for f in collect(source, 3)] == [0, 1, 3]
        assert source.parser.nodes[11].lost == 1
        os.close(master)
        os.close(slave)
        with pytest.raises(BomiError) as error:
            collect(source, 1)
    assert "\n" not in str(error.value)
    assert str(error.value).startswith(f"{path}: stream lost and not back after 2 attempts")
    assert sleeps == [0.01, 0.01]
    assert messages[0].startswith(f"bomi: {path}: stream lost (")
    assert messages[1:] == [f"bomi: {path}: retry 1 of 2 in 0.01 s", f"bomi: {path}: retry 2 of 2 in 0.01 s"]


def test_socket_reconnects_after_the_peer_drops():
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    first = [imu(12, k, k) for k in range(4)]
    second = [imu(12, k, -k) for k in range(4, 9)]

    def serve():
        for frames in (first, second):
            client, _ = server.accept()
            time.sleep(READER_SETTLE_S)  # pyserial drops what is ready when it opens the socket
            # split a frame across the reconnection: its head is garbage, the parser resyncs
            payload = b"".join(encode_imu_frame(f) for f in frames)
            client.sendall(payload if frames is second else payload + encode_imu_frame(imu(12, 99))[:10])
            client.close()
        server.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    messages = []
    with SerialSource(f"socket://127.0.0.1:{port}", retry=FAST_RETRY, log=messages.append) as source:
        assert collect(source, 9) == first + second
    thread.join(5)
    assert source.reconnections == 1
    assert messages[-1] == f"bomi: socket://127.0.0.1:{port}: reconnected"
    assert source.parser.nodes[12].lost == 0


def test_unopenable_port_is_one_line_error():
    with pytest.raises(BomiError, match=r"^socket://127.0.0.1:1: cannot open the port \(.*refused"):
        SerialSource("socket://127.0.0.1:1").open()


# --------------------------------------------------------------------------------- row assembly
def test_rows_hold_the_previous_frame_of_a_lost_node():
    assembler = RowAssembler((10, 11))
    stream = [imu(10, 0), imu(10, 1), imu(11, 1), imu(10, 2), imu(10, 3), imu(11, 3)]
    rows = [row for f in stream if (row := assembler.push(f)) is not None]
    # 11's counters 0 and 2 are lost: the first row is dropped (no value of 11 yet), in the
    # third 11's counter 1 is held
    assert [(r[10].counter, r[11].counter) for r in rows] == [(1, 1), (2, 1), (3, 3)]
    assert assembler.held == 1
    assert assembler.push(imu(12, 4)) is None


# --------------------------------------------------------------------------------- emulator
def test_published_mat_values_are_refused(shared_data):
    path = shared_data / "day1_testp.mat"
    with pytest.raises(BomiError, match=r"day1_testp.mat: node 1 mag at row 1 is .* whole int16"):
        raw_samples(read_recording(path))


def test_out_of_range_values_are_refused():
    rec = int_recording(3, nodes=(2,))
    rec.nodes[2].gyro[1, 2] = 40000
    with pytest.raises(BomiError, match="node 2 gyro at row 2 is"):
        raw_samples(rec)


def test_frame_chunks_loss_and_corruption_are_seeded_and_counted():
    raw = raw_samples(int_recording(300))
    config = EmulatorConfig(loss=0.09, corrupt=0.001, seed=7)
    runs = []
    for _ in range(2):
        stats = EmulatorStats()
        runs.append(([chunk for _, chunk in frame_chunks(raw, config, stats)], stats))
    assert runs[0] == runs[1]
    chunks, stats = runs[0]
    assert stats.samples == 300 and stats.frames_sent + stats.frames_dropped == 900
    assert 0.05 < stats.frames_dropped / 900 < 0.13
    assert sum(map(len, chunks)) == 32 * stats.frames_sent
    assert stats.bytes_corrupted > 0


def test_frame_chunks_timing_and_exact_values_without_loss():
    rec = int_recording(300)
    raw = raw_samples(rec)
    timed = list(frame_chunks(raw, EmulatorConfig(rate_hz=62.5), EmulatorStats()))
    assert [t for t, _ in timed[:3]] == [0.0, 0.016, 0.032]
    frames = FrameParser(confirm_frames=1).feed(b"".join(chunk for _, chunk in timed))  # decoding only
    assert [f.node_id for f in frames[:4]] == [10, 11, 12, 10]
    assert [f.counter for f in frames[::3]] == [k % 256 for k in range(300)]
    node2 = [f for f in frames if f.node_id == 11]
    np.testing.assert_array_equal([f.acc for f in node2], rec.nodes[2].acc)
    np.testing.assert_array_equal([f.mag for f in node2], rec.nodes[2].mag)


def test_play_keeps_the_real_rate():
    class Clock:
        now = 100.0

    sent = []

    class ListSink:
        def write(self, data: bytes) -> bool:
            sent.append((Clock.now, data))
            return True

    def sleep(delay: float) -> None:
        Clock.now += delay

    assert play(iter([(0.0, b"a"), (0.016, b"b"), (0.032, b"c")]), ListSink(), lambda: Clock.now, sleep)
    assert [round(t - 100, 6) for t, _ in sent] == [0.0, 0.016, 0.032]


# --------------------------------------------------------------------------------- round trips
def _emulate_to_pty(rec_path, config: EmulatorConfig) -> tuple[str, threading.Thread, EmulatorStats]:
    sink = open_sink("pty", linger_s=5)
    stats = EmulatorStats()

    def run():
        sink.wait_for_reader()
        play(frame_chunks(raw_samples(read_recording(rec_path)), config, stats), sink)
        sink.finish()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return sink.description, thread, stats


def test_emulator_to_pty_to_capture_gives_back_raw_values(tmp_path, capsys):
    rec_path = tmp_path / "rec.csv"
    write_recording(rec_path, int_recording(150))
    path, thread, _ = _emulate_to_pty(rec_path, EmulatorConfig(rate_hz=250))
    out = tmp_path / "capture.csv"
    assert main(["capture", "--port", path, "--duration", "1.5", "--out", str(out)]) == 0
    thread.join(10)
    original, captured = read_recording(rec_path), read_recording(out)
    assert captured.node_indices == (1, 2, 3) and len(captured) == 150
    for i in (1, 2, 3):
        for signal in ("acc", "gyro", "mag"):
            np.testing.assert_array_equal(getattr(captured.nodes[i], signal), getattr(original.nodes[i], signal))
    assert np.all(np.diff(captured.time) >= 0)
    assert "0 lost" in capsys.readouterr().out


def test_capture_with_loss_counts_what_the_emulator_dropped(tmp_path, capsys):
    rec_path = tmp_path / "rec.csv"
    write_recording(rec_path, int_recording(200, nodes=(1, 2)))
    path, thread, stats = _emulate_to_pty(rec_path, EmulatorConfig(rate_hz=250, loss=0.09, seed=3))
    out = tmp_path / "capture.csv"
    assert main(["capture", "--port", path, "--duration", "1.8", "--out", str(out), "--nodes", "1,2"]) == 0
    thread.join(10)
    summary = capsys.readouterr().out
    captured, original = read_recording(out), read_recording(rec_path)
    # rows end with the last complete sample; lost frames are counted between received ones
    lost = [int(n) for n in re.findall(r"(\d+) lost", summary)]
    assert stats.frames_dropped - 2 <= sum(lost) <= stats.frames_dropped
    assert len(captured) >= 190
    acc = captured.nodes[1].acc
    # every captured row of node 1 is one of the original samples, in order
    index = [int(np.flatnonzero((original.nodes[1].acc == row).all(axis=1))[0]) for row in acc]
    assert index == sorted(index)


def test_emulator_to_socket_to_capture(tmp_path, capsys):
    rec_path = tmp_path / "rec.csv"
    write_recording(rec_path, int_recording(250, nodes=(2, 4)))
    sink = open_sink("socket://127.0.0.1:0")
    stats = EmulatorStats()

    def run():
        sink.wait_for_reader()
        play(frame_chunks(raw_samples(read_recording(rec_path)), EmulatorConfig(rate_hz=250), stats), sink)
        sink.finish()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    out = tmp_path / "capture.csv"
    assert main(["capture", "--port", sink.description, "--duration", "0.8", "--out", str(out)]) == 0
    thread.join(10)
    captured, original = read_recording(out), read_recording(rec_path)
    assert captured.node_indices == (2, 4) and 80 < len(captured) < 250  # the capture ends first
    np.testing.assert_array_equal(captured.nodes[4].mag, original.nodes[4].mag[:len(captured)])
    assert stats.samples < 250  # the emulator noticed the reader went away


def test_cli_emulate_prints_the_pty_path_and_capture_records_it(tmp_path, capsys):
    rec_path = tmp_path / "rec.csv"
    write_recording(rec_path, int_recording(60, nodes=(1,)))
    emulator = subprocess.Popen([sys.executable, "-m", "tasks.cli", "emulate", "--recording", str(rec_path),
                                 "--to", "pty", "--rate", "100", "--linger", "3"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        path = emulator.stdout.readline().strip()
        assert path.startswith("/dev/pts/")
        out = tmp_path / "capture.csv"
        assert main(["capture", "--port", path, "--duration", "1.2", "--out", str(out)]) == 0
        _, errors = emulator.communicate(timeout=10)
    finally:
        emulator.kill()
    assert emulator.returncode == 0
    assert "end of recording: 60 samples, 60 frames sent, 0 dropped" in errors
    np.testing.assert_array_equal(read_recording(out).nodes[1].gyro, read_recording(rec_path).nodes[1].gyro)


# --------------------------------------------------------------------------------- bad input
def test_capture_never_overwrites(tmp_path, capsys):
    out = tmp_path / "capture.csv"
    out.write_text("precious\n")
    assert main(["capture", "--port", "loop://", "--duration", "0.1", "--out", str(out)]) == 2
    assert capsys.readouterr().err == f"bomi: error: {out}: file exists, not overwriting it\n"
    assert out.read_text() == "precious\n"


def test_capture_of_a_silent_stream_writes_nothing(tmp_path, capsys):
    out = tmp_path / "capture.csv"
    assert main(["capture", "--port", "loop://", "--duration", "0.2", "--out", str(out)]) == 2
    assert capsys.readouterr().err == "bomi: error: loop://: no IMU frames received; nothing recorded\n"
    assert not out.exists()


def test_emulate_refuses_a_malformed_recording(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("ACC1X,ACC1Y\n1,2\n")
    assert main(["emulate", "--recording", str(bad), "--to", "pty"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"bomi: error: {bad}: ") and err.count("\n") == 1


def test_emulate_rejects_impossible_settings(tmp_path, capsys):
    rec_path = tmp_path / "rec.csv"
    write_recording(rec_path, int_recording(5))
    assert main(["emulate", "--recording", str(rec_path), "--to", "pty", "--loss", "1.5"]) == 2
    assert capsys.readouterr().err == \
        "bomi: error: argument --loss: must be in [0, 1), got '1.5' (see bomi emulate --help)\n"


# --------------------------------------------------------------------------------- guided calibration
TEST_PROFILE = """
name = "T"
[neutral]
samples = 10
[[nodes]]
index = 1
node_id = 10
site = "head"
[[classes]]
label = 0
name = "neutral posture"
function = "neutral"
[[classes]]
label = 1
name = "tilt left"
function = "F"
node = 1
[[classes]]
label = 2
name = "tilt right"
function = "B"
node = 1
"""
POSTURE_ACC = {0: (-16000, 0, 1000), 1: (-14000, 8000, 1000), 2: (-14000, -8000, 1000)}


def posture_recording(labels: list[int], samples_each: int, seed: int = 0) -> Recording:
    """One headset node holding a posture (gravity direction) per label, with sensor noise."""
    rng = np.random.default_rng(seed)
    series = np.repeat(labels, samples_each)
    n = len(series)
    acc = np.array([POSTURE_ACC[c] for c in series], float) + rng.integers(-50, 50, (n, 3))
    node = NodeData(acc, rng.integers(-5, 5, (n, 3)).astype(float), np.tile([200.0, -300.0, 400.0], (n, 1)),
                    np.zeros((n, 3)))
    return Recording({1: node}, series)


def held_neutral_then(body: Recording, profile_path) -> tuple[Recording, int]:
    """``body`` after a held neutral just long enough for `bomi record`'s gate to open on it (what a person
    does while record waits: hold still), and that length: the neutral's fused samples fed offline to the
    gate `bomi record` uses, up to and including the one on which it says settled (about 9 s here: the
    filter's yaw starts at 0 and decays towards this node's heading, 124 deg)."""
    lead = posture_recording([0], 1500, seed=1)  # 24 s, more than enough
    fusion = NodeFusion(arm_profile(str(profile_path)).nodes[0].calibration)
    gate, node = NodeGate(1), lead.nodes[1]
    for n in range(1, len(lead) + 1):
        gate.fused(fusion.update(node.acc[n - 1], node.gyro[n - 1], node.mag[n - 1]))
        if gate.settled:
            break
    joined = NodeData(*(np.vstack([getattr(node, name)[:n], getattr(body.nodes[1], name)])
                        for name in ("acc", "gyro", "mag", "angles")))
    return Recording({1: joined}, np.r_[lead.labels[:n], body.labels]), n


def test_calibration_schedule_of_p1():
    from bomi.profiles import load_profile
    from bomi.protocol import calibration_schedule

    profile = load_profile("P1")
    sequence = calibration_schedule(profile)
    assert len(sequence) == 1 + 2 * 8 * 3 and sequence[-1].end_s == 5 + 24 * 10
    assert [s.label for s in sequence[:6]] == [0, 1, 0, 2, 0, 3]
    assert [s.label for s in sequence[1:49:2]] == list(range(1, 9)) * 3
    assert all(a.end_s == b.start_s for a, b in zip(sequence, sequence[1:]))
    session = calibration_schedule(profile, sequences=3, amplitudes=(1.0, 0.5), hold_s=4, neutral_s=2)
    assert len(session) == 1 + 2 * 8 * 3 * 3 * 2 and session[-1].end_s == 2 + 144 * 6
    assert session[1].prompt.endswith("at 100 % of your range") and session[3].prompt.endswith("at 50 % of your range")
    assert session[3].label == 1 and session[5].label == 2


def test_record_labels_whole_segments_and_trains(tmp_path, capsys):
    from bomi.model_io import load_model

    profile = tmp_path / "t.toml"
    profile.write_text(TEST_PROFILE)
    rec_path = tmp_path / "stream.csv"
    stream, lead_in = held_neutral_then(posture_recording([0, 1, 0, 2, 0, 0, 0, 0], 25), profile)
    write_recording(rec_path, stream)
    path, thread, _ = _emulate_to_pty(rec_path, EmulatorConfig())
    out, model = tmp_path / "calibration.csv", tmp_path / "model.json"
    assert main(["record", "--profile", str(profile), "--port", path, "--out", str(out), "--repetitions", "1",
                 "--hold", "0.4", "--neutral", "0.4", "--train", str(model)]) == 0
    thread.join(10)
    recorded, streamed = read_recording(out), read_recording(rec_path)
    labels = recorded.labels
    starts = np.r_[0, np.flatnonzero(np.diff(labels)) + 1]
    assert labels[starts].tolist() == [0, 1, 0, 2, 0]
    assert all(abs(n - 25) <= 4 for n in np.diff(np.r_[starts, len(labels)]))  # 0.4 s at 62.5 Hz
    raw = np.hstack([streamed.nodes[1].acc, streamed.nodes[1].gyro])
    first = int(np.flatnonzero((raw == np.r_[recorded.nodes[1].acc[0], recorded.nodes[1].gyro[0]]).all(axis=1))[0])
    assert lead_in <= first <= lead_in + 8  # the protocol starts once the gate has opened, not before, nor long after
    np.testing.assert_array_equal(recorded.nodes[1].acc, streamed.nodes[1].acc[first:first + len(labels)])
    assert load_model(model).classes.tolist() == [0, 1, 2]
    assert (f"{model}: model of profile T; 3 classes:\n  c0 neutral: neutral posture\n  c1 F: tilt left\n"
            "  c2 B: tilt right\n") in capsys.readouterr().out


def test_rows_read_in_a_bunch_are_timed_back_one_sample_period_apart():
    from bomi.fusion import sample_times

    period = 1 / 62.5
    np.testing.assert_allclose(sample_times(1.0, 3, 0.5), [1.0 - 2 * period, 1.0 - period, 1.0])
    assert sample_times(1.0, 1, 0.5) == [1.0]
    assert sample_times(1.0, 0, 0.5) == []
    np.testing.assert_allclose(sample_times(1.0, 4, 0.97), [0.97, 0.97, 1.0 - period, 1.0])  # never before the last row



def test_recording_clock_starts_at_the_first_read_and_never_runs_ahead_of_it():
    """A backlog in the first read stays with the first prompt; rows read in a bunch after the host
    stalled for a second are timed back one sample period apart (timed by their arrival, all ten would
    fall into whatever segment is current when the host reads again, and a whole held posture could be
    labelled with the next prompt)."""
    from tqdm import tqdm

    from tasks.experiments.streams import timed_rows

    def frames(n, first):
        return [ImuFrame(10, 16, (first + k) % 256, (0, 0, 0), (0, 0, 0), (0, 0, 1000)) for k in range(n)]

    batches = [(0.5, frames(40, 0)), (0.52, frames(1, 40)), (1.5, frames(10, 41))]  # a backlog, then a stall
    source = SimpleNamespace(parser=FrameParser(), url="test")
    timed = list(timed_rows(iter(batches), RowAssembler((10,)), source, tqdm(disable=True)))
    times = [t for t, _ in timed]
    period = 1 / 62.5
    assert times[:40] == [0.5] * 40  # what waited in the port's buffer belongs to the first prompt
    assert times[40] == 0.52
    np.testing.assert_allclose(times[41:], 1.5 - period * np.arange(9, -1, -1))

def test_interrupted_record_keeps_only_completed_segments(tmp_path):
    profile = tmp_path / "t.toml"
    profile.write_text(TEST_PROFILE)
    rec_path = tmp_path / "stream.csv"
    write_recording(rec_path, held_neutral_then(posture_recording([0, 1, 0, 2, 0] * 4, 30), profile)[0])
    path, thread, _ = _emulate_to_pty(rec_path, EmulatorConfig())
    out = tmp_path / "calibration.csv"
    recorder = subprocess.Popen([sys.executable, "-m", "tasks.cli", "record", "--profile", str(profile), "--port", path,
                                 "--out", str(out), "--hold", "0.5", "--neutral", "0.5"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                # a person's Ctrl-C: the default SIGINT even when this test runs as a background
                                # job, whose children inherit SIGINT ignored (they then finish unhindered)
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # Interrupt on the recorder's own progress: its prompt for the third segment means two are
    # written, and 0.25 s later it is in the middle of that 0.5 s segment, 5 s before the end.
    watchdog = threading.Timer(40, recorder.kill)  # the gate's wait (about 9 s), then 0.5 s segments
    watchdog.start()
    try:
        errors, prompts = [], 0
        while prompts < 3 and (line := recorder.stderr.readline()):
            errors.append(line)
            prompts += line.startswith(("relax:", "HOLD "))
        time.sleep(0.25)
        recorder.send_signal(signal.SIGINT)
        errors.append(recorder.communicate(timeout=10)[1])
    finally:
        watchdog.cancel()
        recorder.kill()
    thread.join(10)
    assert prompts == 3 and recorder.returncode == 130 and "".join(errors).endswith("bomi: interrupted\n")
    labels = read_recording(out).labels
    runs = np.diff(np.r_[0, np.flatnonzero(np.diff(labels)) + 1, len(labels)])
    assert 2 <= len(runs) < 13 and all(abs(n - 31) <= 4 for n in runs)  # 0.5 s segments, none cut short


def record_from_p1(tmp_path, capsys, emulate: list[str], record: list[str]) -> tuple[int, str, Recording | None]:
    """`bomi record --profile P1 --repetitions 1 RECORD` from `bomi emulate --participant P1 --seed 3
    EMULATE` (its own process, a pty, real time): exit code, stderr, the recording."""
    emulator = subprocess.Popen([sys.executable, "-m", "tasks.cli", "emulate", "--participant", "P1", "--to", "pty",
                                 "--seed", "3", "--linger", "0.5", *emulate],
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        path = emulator.stdout.readline().strip()
        assert path.startswith("/dev/")
        out = tmp_path / "p1.csv"
        code = main(["record", "--profile", "P1", "--port", path, "--out", str(out), "--repetitions", "1",
                     "--retries", "0", *record])
    finally:
        emulator.kill()
    return code, capsys.readouterr().err, read_recording(out) if out.exists() else None


def test_record_from_a_virtual_participant_starts_after_the_filters_settle(tmp_path, capsys):
    """P1 at seed 3 sits facing -112 deg, in neutral throughout (`bomi emulate --participant`, its own
    process, real time): the receiver's filters start at yaw 0 and need ~9 s to reach the heading. The
    recording starts after that: its first yaw is within the gate's tolerance of the yaw 5 s later (plus
    P1's own sway over those 5 s: 1 deg in all), where the stream's first second is ~85 deg off."""
    from bomi.fusion import DT
    from bomi.gate import SETTLE_TOLERANCE_DEG
    from bomi.profiles import load_profile
    from bomi.protocol import calibration_schedule
    from tasks.participants.participant import load_participant
    from tasks.participants.wire import participant_blocks

    # P1 in neutral for 30 s; 8.5 s of protocol
    code, err, recorded = record_from_p1(tmp_path, capsys, ["--neutral", "30", "--hold", "0.5", "--duration", "25"],
                                         ["--hold", "0.5", "--neutral", "0.5"])
    assert code == 0, err
    later = round(5.0 / DT)
    for node in recorded.nodes.values():
        assert abs(node.angles[0, 2] - node.angles[later, 2]) < 2 * SETTLE_TOLERANCE_DEG
    assert "hold still: warming up (node 1)" in err and "record: every node settled after " in err
    # the same stream fused from its first sample, as the recorder's filters were: without the wait the
    # recording would have started ~85 deg away from where it settles
    profile = load_profile("P1")
    blocks = list(participant_blocks(load_participant("P1"), profile, 3,
                                     calibration_schedule(profile, hold_s=0.5, neutral_s=30), 25.0))
    first_row = np.r_[recorded.nodes[1].mag[0], recorded.nodes[1].gyro[0], recorded.nodes[1].acc[0]]
    for node in profile.nodes:
        raw = np.vstack([block[node.index] for block in blocks])
        fusion = NodeFusion(node.calibration)
        yaw = np.array([fusion.update(row[6:9], row[3:6], row[0:3])[2] for row in raw.tolist()])
        if node.index == 1:
            start = int(np.flatnonzero((raw == first_row).all(axis=1))[0])
        assert abs(yaw[start] - recorded.nodes[node.index].angles[0, 2]) < 1e-6   # every frame went to the filter
        assert abs(yaw[:round(1 / DT)].mean() - yaw[start + later]) > 50             # the warm-up, not recorded
    assert start * DT > 5.0


def _tilting(seconds: float) -> Recording:
    """One node lying flat, then tilting on at 5 deg/s (it never holds still), the magnetometer still:
    held still it settles in about 4 s (its heading is near the filter's initial 0). Not a back-and-forth
    motion: the gate's half-window test passes such a motion when a window is symmetric about a turn."""
    t = np.arange(round(seconds * 62.5)) / 62.5
    tilt = np.radians(5.0 * t)
    acc = np.column_stack([16000 * np.sin(tilt), np.zeros_like(t), 16000 * np.cos(tilt)]).round()
    n = len(t)
    return Recording({1: NodeData(acc, np.zeros((n, 3)), np.tile([3000.0, 0.0, 2000.0], (n, 1)), np.zeros((n, 3)))},
                     np.zeros(n, dtype=int))


@pytest.mark.parametrize("stream, wait_s, reason", [
    ("tilting", 14.0, r"still warming up: its angles changed by \d+\.\d\d deg between the halves of the last 1\.6 s"),
    ("zero accelerometer", 2.0, r"accelerometer all zero")])
def test_record_of_a_node_that_never_settles_is_one_error_line_and_no_file(tmp_path, capsys, monkeypatch,
                                                                             stream, wait_s, reason):
    from tasks.cli import stream as stream_cli

    profile = tmp_path / "t.toml"
    profile.write_text(TEST_PROFILE)
    rec = _tilting(wait_s + 3.0)
    if stream == "tilting":  # the same node held still is trusted within the wait: the motion is what holds it
        still = NodeData(np.tile([0.0, 0.0, 16000.0], (len(rec), 1)), rec.nodes[1].gyro, rec.nodes[1].mag)
        fusion, gate = NodeFusion(arm_profile(str(profile)).nodes[0].calibration), NodeGate(1)
        for k in range(round(wait_s * 62.5)):
            gate.fused(fusion.update(still.acc[k], still.gyro[k], still.mag[k]))
        assert gate.settled
    else:
        rec.nodes[1].acc[:] = 0
    rec_path = tmp_path / "stream.csv"
    write_recording(rec_path, rec)
    path, thread, _ = _emulate_to_pty(rec_path, EmulatorConfig())
    monkeypatch.setattr(stream_cli, "SETTLE_WAIT_S", wait_s)
    out = tmp_path / "calibration.csv"
    started = time.monotonic()
    code = main(["record", "--profile", str(profile), "--port", path, "--out", str(out), "--retries", "0"])
    took = time.monotonic() - started
    thread.join(10)
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and not out.exists()
    assert [line for line in err if line.startswith("bomi: error: ")] == err[-1:]
    assert re.fullmatch(rf"bomi: error: {path}: node 1 did not settle in {wait_s:g} s \({reason}[^)]*\); "
                        "nothing recorded", err[-1]), err[-1]
    assert wait_s < took < wait_s + 1.5


def test_emulate_settle_first_keeps_the_participant_in_step_with_records_prompts(tmp_path, capsys):
    """`bomi emulate --participant P1 --settle-first` holds still until a receiver's gate would open, then
    performs the protocol; `bomi record` starts its prompts when its gate opens: the label record gives
    each row is the cue the participant was following at that sample on >= 90 % of the rows (the rest: a
    few samples at some of the 17 changes, the emulator's estimate against the recorder's batches: 0-4 rows
    measured). Without the lead-in the participant would be 12 s (almost 10 segments) ahead of the prompts."""
    from bomi.fusion import DT
    from bomi.profiles import load_profile
    from bomi.protocol import calibration_schedule
    from tasks.participants.participant import load_participant
    from tasks.participants.wire import delayed, participant_blocks, settled_after

    segments = ["--neutral", "0.5", "--hold", "0.75"]   # 10.5 s of protocol
    code, err, recorded = record_from_p1(tmp_path, capsys, ["--settle-first", *segments], segments)
    assert code == 0, err
    params, profile = load_participant("P1"), load_profile("P1")
    lead_s = settled_after(params, profile, 3)
    cues = delayed(calibration_schedule(profile, hold_s=0.75, neutral_s=0.5), lead_s)
    raw = np.vstack([block[1] for block in participant_blocks(params, profile, 3, cues, lead_s + 15.0)])
    index = {tuple(row): k for k, row in enumerate(raw.tolist())}
    node = recorded.nodes[1]
    rows = [index[tuple(row)] for row in np.hstack([node.mag, node.gyro, node.acc]).tolist()]
    followed = np.array([next(cue.label for cue in cues if cue.start_s <= k * DT < cue.end_s) for k in rows])
    assert np.mean(followed == recorded.labels) >= 0.9
    assert rows[0] * DT >= lead_s


def test_ctrl_c_while_record_waits_for_the_gate_writes_nothing(tmp_path):
    profile = tmp_path / "t.toml"
    profile.write_text(TEST_PROFILE)
    rec = _tilting(8.0)
    rec.nodes[1].acc[:] = 0                                  # never plausible: record keeps waiting
    rec_path = tmp_path / "stream.csv"
    write_recording(rec_path, rec)
    path, thread, _ = _emulate_to_pty(rec_path, EmulatorConfig())
    out = tmp_path / "calibration.csv"
    recorder = subprocess.Popen([sys.executable, "-m", "tasks.cli", "record", "--profile", str(profile), "--port", path,
                                 "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # as in the test above
    watchdog = threading.Timer(20, recorder.kill)
    watchdog.start()
    try:
        waiting = "hold still: node 1: accelerometer all zero"
        while (line := recorder.stderr.readline()) and not line.startswith(waiting):
            pass
        recorder.send_signal(signal.SIGINT)
        rest = recorder.communicate(timeout=10)[1]
    finally:
        watchdog.cancel()
        recorder.kill()
    thread.join(10)
    assert line.startswith(waiting)
    assert recorder.returncode == 130 and rest.endswith("bomi: interrupted\n") and not out.exists()
