"""tasks.participants.participant: profiles, motion model, frames, calibration (the P1 fit: tests/test_twin.py)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.signal

from bomi.chain import OnlineChain, train
from bomi.errors import BomiError
from bomi.frames import FrameParser, RowAssembler, SafetyKey, SampleIndex, encode_safety_key_frame
from bomi.fusion import DT, WARMUP_S, FusedRows
from bomi.profiles import load_profile
from tasks.participants.motion import fir_filter, minimum_jerk, tremor_filter
from tasks.participants.participant import (PARTICIPANT_DIR, CalibrationSession, Session, VirtualParticipant, calibration_session,
                                            load_participant, record_stream, session_recording)
from helpers import assert_agree, edited_copy

P1_TOML = PARTICIPANT_DIR / "P1.toml"


def still(params, **changes):
    """The participant without any variability, sway, tremor or spasm (exact postures and timing)."""
    def quiet(motion):
        zero = np.zeros_like(motion.posture_deg)
        return dataclasses.replace(motion, rep_std_deg=zero, day_gain_log_std=0.0, day_std_deg=zero, sway_std_deg=zero,
                                   tremor_std_deg=zero)
    return dataclasses.replace(params, neutral=quiet(params.neutral),
                               classes={k: quiet(m) for k, m in params.classes.items()}, spasm=None,
                               **{"onset_sd_s": 0.0, "reaction_sd_s": 0.0, **changes})


@pytest.fixture(scope="module")
def p1():
    return load_participant("P1"), load_profile("P1")


# ------------------------------------------------------------------------------------ profiles
@pytest.mark.parametrize("name", ["P1", "P4", "P5"])
def test_shipped_participants_match_their_bomi_profiles(name):
    params = load_participant(name)
    VirtualParticipant(params, load_profile(params.profile), seed=0)   # checks nodes and classes


@pytest.mark.parametrize("old, new, message", [
    ("onset_s = 0.8", "onset_s = -1", "onset_s: must be in [0.016, 10], got -1.0"),
    ("onset_s = 0.8", "", "onset_s: missing"),
    ("max_amplitude = 1.0", "max_amplitude = 1.0\nspeed = 3", "unknown key(s) ['speed']"),
    ("frequencies_hz = [0.000, 0.488", "frequencies_hz = [0.488, 0.000", "[tremor] frequencies_hz: must rise from 0"),
    ("label = 2", "label = 1", "[classes[1]] label: 1 is used by an earlier class"),
    ("label = 2", "label = 0", "[classes[1]] label: must be a positive integer, got 0"),
    ("rep_std_deg = [[", "rep_std_deg = [[-", "[neutral] rep_std_deg: holds standard deviations, they cannot be negative"),
    ("posture_deg = [[", "posture_deg = [[1.0], [", "[classes[0]] posture_deg: expected 3 values, got 1"),
    ("posture_deg = [[", "posture_deg = [[1, 2, 3], [", "[classes[0]] posture_deg: must be a 3 x 3 matrix"),
    ("labels = [0, 2", "labels = [0, 9", "[protocol] labels: must list classes of the participant ([0, 1, 2, 3, 4, 5, 6, 7, "
                                         "8]), not [9]"),
    ('"tremor" = "measured', '"tremor" = 3 #', "[provenance] tremor: expected a string, got 3"),
    ("least_lean = 0.580", "least_lean = 0.01", "[feel] least_lean: must be in [0.05, 1], got 0.01"),
    ('name = "P1"', 'name = "P1', "not valid TOML"),
])
def test_bad_participant_files_name_the_file_and_the_problem(tmp_path, old, new, message):
    path = edited_copy(P1_TOML, tmp_path / "bad.toml", old, new)
    with pytest.raises(BomiError) as err:
        load_participant(path)
    assert str(path) in str(err.value) and message in str(err.value)
    assert "\n" not in str(err.value)


def test_participant_must_fit_the_profile(p1, tmp_path):
    params, _ = p1
    with pytest.raises(BomiError, match="made for profile P1, not P4"):
        VirtualParticipant(params, load_profile("P4"), seed=0)
    with pytest.raises(BomiError, match=r"classes \[1, 2, 3, 4, 5, 6, 7\] do not match"):
        VirtualParticipant(dataclasses.replace(params, classes={k: v for k, v in params.classes.items() if k != 8}),
                           load_profile("P1"), seed=0)
    with pytest.raises(BomiError, match="no such participant file"):
        load_participant(tmp_path / "missing.toml")
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(BomiError, match="binary.toml: not valid TOML"):
        load_participant(binary)


# ------------------------------------------------------------------------------- motion model
def test_minimum_jerk_profile_hand_values():
    s = np.array([-1.0, 0.0, 0.25, 0.5, 0.75, 1.0, 2.0])
    expected = [0.0, 0.0, 10 / 64 - 15 / 256 + 6 / 1024, 0.5, 1 - (10 / 64 - 15 / 256 + 6 / 1024), 1.0, 1.0]
    np.testing.assert_allclose(minimum_jerk(s), expected, atol=1e-12)


def test_intent_moves_min_jerk_after_reaction_holds_and_returns(p1):
    params, profile = p1
    quiet = still(params)
    vp = VirtualParticipant(quiet, profile, seed=0)
    vp.advance(1.0)
    vp.set_intent(1, 0.5, 1.0)
    vp.advance(4.0)
    vp.set_intent(0, 0.0, 4.0)
    vp.advance(7.0)
    truth = vp.truth()
    neutral, posture = quiet.neutral.posture_deg, quiet.classes[1].posture_deg
    t0 = 1.0 + quiet.reaction_s

    def at(t):
        return truth.angles[int(round(t / DT))]
    np.testing.assert_allclose(at(t0 - DT), neutral, atol=1e-9)                          # not before the reaction
    k = int(np.ceil((t0 + quiet.onset_s / 2) / DT))                                   # about halfway
    s = (k * DT - t0) / quiet.onset_s
    assert 0.5 <= s < 0.5 + DT / quiet.onset_s
    np.testing.assert_allclose(truth.angles[k], neutral + 0.5 * minimum_jerk(s) * posture, atol=1e-9)
    np.testing.assert_allclose(at(3.9), neutral + 0.5 * posture, atol=1e-9)               # held at amplitude 0.5
    np.testing.assert_allclose(at(6.9), neutral, atol=1e-9)                               # back to neutral
    assert truth.intent[int(round(2.0 / DT))] == 1 and truth.amplitude[int(round(2.0 / DT))] == 0.5
    assert truth.intent[-1] == 0


def test_holding_is_the_per_sample_blend(p1):
    """The deliberate posture and the noise levels of chunks across several moves (some chunks inside a
    move, some after it is done, some spanning two) against the formulas evaluated sample by sample, to
    a few ulps (the chunk's polynomial on arrays, the reference's on floats: fused or not by the CPU)."""
    params, profile = p1
    vp = VirtualParticipant(params, profile, seed=3)
    for t, label, amplitude in [(0.5, 1, 0.8), (1.0, 2, 0.5), (4.0, 0, 0.0), (4.3, 3, 1.0)]:
        vp.set_intent(label, amplitude, t)
    chunks = [np.arange(a, b) * DT for a, b in [(0, 20), (20, 100), (100, 101), (101, 180), (180, 200), (200, 300),
                                                (300, 500), (500, 600)]]
    for t in chunks:
        posture, sway, tremor, label, amplitude = vp._holding(t)
        for i, ti in enumerate(t):
            k = max(int(np.searchsorted([m.t0 for m in vp._moves], ti, side="right")) - 1, 0)
            move = vp._moves[k]
            old, new = params.motion(vp._moves[max(k - 1, 0)].label), params.motion(move.label)
            s = min(max((ti - move.t0) / move.duration, 0.0), 1.0)
            p = s ** 3 * (10.0 - 15.0 * s + 6.0 * s ** 2)
            assert_agree(posture[i], move.start + p * (move.target - move.start), ulps=16,
                         scale=max(np.abs(move.start).max(), np.abs(move.target).max()))
            assert_agree(sway[i], (1 - p) * old.sway_std_deg + p * new.sway_std_deg, ulps=16)
            assert_agree(tremor[i], (1 - p) * old.tremor_std_deg + p * new.tremor_std_deg, ulps=16)
            assert (label[i], amplitude[i]) == (move.label, move.amplitude)


def test_low_range_participant_reaches_only_its_max_amplitude():
    params = still(load_participant("P5"))
    vp = VirtualParticipant(params, load_profile("P5"), seed=0)
    vp.set_intent(3, 1.0, 0.0)
    vp.advance(3.0)
    reached = vp.truth().angles[-1] - params.neutral.posture_deg
    np.testing.assert_allclose(reached, 0.4 * params.classes[3].posture_deg, atol=1e-9)


def test_tremor_and_sway_have_the_profiled_size_and_band(p1):
    params, profile = p1
    quiet = still(params)
    neutral = dataclasses.replace(quiet.neutral, tremor_std_deg=params.neutral.tremor_std_deg)
    vp = VirtualParticipant(dataclasses.replace(quiet, neutral=neutral), profile, seed=4)
    vp.advance(200.0)
    tremor = vp.truth().angles[:, 0, 0] - neutral.posture_deg[0, 0]
    assert tremor.std() == pytest.approx(params.neutral.tremor_std_deg[0, 0], rel=0.1)
    freqs, psd = scipy.signal.welch(tremor, fs=1 / DT, nperseg=256)
    profile_freqs, profile_power = params.tremor_spectrum
    assert psd[freqs > profile_freqs[-1] + 0.5].sum() / psd.sum() < 0.02       # nothing beyond the spectrum
    assert abs(freqs[np.argmax(psd)] - profile_freqs[np.argmax(profile_power)]) < 0.5   # same peak


def test_spasms_are_bursts_up_to_ten_degrees():
    params = load_participant("P4")
    quiet = still(params)
    vp = VirtualParticipant(dataclasses.replace(quiet, spasm=params.spasm), load_profile("P4"), seed=2)
    vp.advance(300.0)
    deviation = np.abs(vp.truth().angles - quiet.neutral.posture_deg).max(axis=(1, 2))
    # one burst reaches at most 10 deg; two that overlap add up (what the seeded draw holds)
    t = vp.truth().time_s
    single = np.ones_like(deviation, dtype=bool)
    for a in vp.spasm_onsets:
        for b in vp.spasm_onsets:
            if 0 < b - a < params.spasm.duration_s:
                single &= ~((t >= b) & (t <= a + params.spasm.duration_s))
    assert 5.0 < deviation[single].max() <= params.spasm.max_deg + 1e-9
    onsets = np.flatnonzero(np.diff((deviation > 0.01).astype(int)) == 1)
    assert 15 <= len(onsets) <= 45            # Poisson(0.1/s x 300 s = 30), bursts can merge


@pytest.mark.parametrize("n", [1, 23, 700])
def test_fir_filter_agrees_with_scipy_lfilter(p1, n):
    """The tremor's FIR filter, chunk after chunk, against scipy.signal.lfilter with the same state, to
    a few ulps of the taps' sum of magnitudes per output (two orders of the same products)."""
    b, _ = tremor_filter(p1[0].tremor_spectrum)
    rng = np.random.default_rng(n)
    state = expected_state = rng.standard_normal((len(b) - 1, 9))
    for _ in range(3):
        x = rng.standard_normal((n, 9))
        expected, expected_state = scipy.signal.lfilter(b, [1.0], x, axis=0, zi=expected_state)
        got, state = fir_filter(b, x, state)
        bound = np.abs(b).sum() * max(np.abs(x).max(), np.abs(expected_state).max())
        assert_agree(got, expected, ulps=4 * len(b), scale=bound)
        assert_agree(state, expected_state, ulps=4 * len(b), scale=bound)
        state = expected_state                         # each chunk from the same state


# --------------------------------------------------------------------------------------- frames
@pytest.mark.parametrize("name", ["P1", "P4"])
def test_stream_does_not_depend_on_how_time_is_sliced(name):
    params = load_participant(name)
    profile = load_profile(name)
    one, many = VirtualParticipant(params, profile, seed=5), VirtualParticipant(params, profile, seed=5)
    for vp in (one, many):                      # intents known in advance, so both see the same ones
        vp.set_intent(3 if name == "P1" else 2, 0.7, 2.0)
    whole = one.advance(8.0)
    pieces = b"".join(many.advance(t) for t in np.r_[np.arange(1, 480) / 60.0, [8.0]])
    assert whole == pieces
    np.testing.assert_allclose(one.truth().angles, many.truth().angles, atol=1e-9)   # filter round-off only



@pytest.mark.parametrize("name", ["P1", "P4"])
def test_passing_time_then_one_pass_is_making_the_samples_at_each_cue(name):
    """pass_time (a protocol synthesised in one pass) against deliveries at every cue (the naive
    reference): the same intents' timing, the same frames and arrivals, the angles to filter round-off."""
    params, profile = load_participant(name), load_profile(name)
    one, many = VirtualParticipant(params, profile, seed=7), VirtualParticipant(params, profile, seed=7)
    cues = [(1.0, 3 if name == "P1" else 2, 1.0), (2.5, 0, 0.0), (2.6, 1, 0.6), (4.0, 0, 0.0)]
    parts = []
    for t, label, amplitude in cues:
        one.pass_time(t)
        parts.append(many.deliveries(t))
        one.set_intent(label, amplitude, t)
        many.set_intent(label, amplitude, t)
    parts.append(many.deliveries(6.0))
    whole = one.deliveries(6.0)
    assert whole.stream() == b"".join(p.stream() for p in parts)
    assert np.array_equal(whole.arrival_s, np.concatenate([p.arrival_s for p in parts]))
    assert [m.t0 for m in one._moves] == [m.t0 for m in many._moves]
    np.testing.assert_allclose(one.truth().angles, many.truth().angles, atol=1e-9)


@pytest.mark.parametrize("name", ["P1", "P4"])
def test_calibration_and_task_share_the_person_but_not_the_noise(name):
    """Same seed: the task participant is the person who calibrated (same day's postures), but sway,
    tremor, spasms, sensor noise and frame loss are drawn afresh, so the streams differ from the start."""
    params, profile = load_participant(name), load_profile(name)
    seed = 7
    session = calibration_session(params, profile, seed, order=[(1, 1.0)], warmup_s=12.0)
    calibration_bytes, _ = session.delivery.until(10.0)
    task = VirtualParticipant(params, profile, seed)
    task_frames = task.deliveries(10.0)
    assert calibration_bytes.stream() == VirtualParticipant(params, profile, seed, session=Session.CALIBRATION).advance(10.0)
    assert len(task_frames.frames) > 1000 and calibration_bytes.stream() != task_frames.stream()
    # frames carry noisy raw counts: hardly one is repeated byte for byte
    assert len(set(calibration_bytes.frames) & set(task_frames.frames)) < 0.01 * len(task_frames.frames)
    truth_cal, truth_task = session.truth, task.truth()
    n = min(len(truth_cal.time_s), len(truth_task.time_s))
    assert not np.allclose(truth_cal.angles[:n], truth_task.angles[:n], atol=0.01)   # sway/tremor differ
    calibrating = VirtualParticipant(params, profile, seed, session=Session.CALIBRATION).day_postures
    for label, posture in task.day_postures.items():
        np.testing.assert_array_equal(posture, calibrating[label])
    other_day = VirtualParticipant(params, profile, seed + 1).day_postures
    assert any(not np.array_equal(other_day[k], v) for k, v in task.day_postures.items())


def test_stream_parses_with_about_nine_percent_loss_and_nothing_from_the_future(p1):
    params, profile = p1
    vp = VirtualParticipant(params, profile, seed=1)
    parser = FrameParser()
    seen = 0
    for step in range(1, 301):                   # 10 s in 60 Hz control ticks
        t = step / 30.0
        chunk = vp.deliveries(t)
        assert (chunk.arrival_s <= t).all() and (chunk.sample_index * DT <= t).all()
        seen += len(parser.feed(chunk.stream()))
        if step == 90:
            vp.set_intent(2, 1.0, t)
    generated = len(vp.truth().time_s)
    assert set(parser.nodes) == {10, 11, 12}
    assert 0.80 < seen / (3 * generated) < 0.95
    assert 0.06 < parser.nodes[10].loss_fraction < 0.12


# --------------------------------------------------------------------------------- calibration
@pytest.fixture(scope="module")
def session(p1) -> CalibrationSession:
    params, profile = p1
    params = dataclasses.replace(params, reaction_sd_s=0.0, onset_sd_s=0.0)   # the layout's hold lengths: fixed timing
    return calibration_session(params, profile, seed=3, repetitions=2, hold_s=3.0, neutral_s=3.0,
                               amplitudes=(1.0, 0.5))


def test_calibration_protocol_layout(p1, session):
    params, _ = p1
    rate = 1 / DT
    held = session.holding & session.recorded
    for label in params.classes:
        count = np.sum(held & (session.cue == label))
        assert abs(count - 2 * 2 * 3.0 * rate) <= 4        # 2 repetitions x 2 amplitudes x 3 s
    cues = session.cue[session.recorded]
    changes = cues[np.r_[True, np.diff(cues) != 0]]
    motions = [c for c in changes if c]
    assert motions == [c for _ in range(2) for c in sorted(params.classes) for _ in range(2)]
    assert not session.recorded[: int(12.0 * rate) - 1].any()
    # holding means the posture is reached: the truth sits at its target, far from neutral, for class 1
    head_pitch = session.truth.angles[held & (session.cue == 1), 0, 0] - params.neutral.posture_deg[0, 0]
    assert np.median(head_pitch) > 10.0


def test_cue_and_holding_follow_the_protocols_timing(p1, session):
    """Each sample's cue and whether it is held, against the protocol's timing computed here and
    read sample by sample: cues at the end of the warm-up's first neutral and of every hold, each
    hold starting reaction + onset after its cue (the union of the holds, the cue of the latest
    cue at or before the sample)."""
    params, _ = p1
    settle = params.reaction_s + params.onset_s
    motions = [label for _ in range(2) for label in sorted(params.classes) for _ in (1.0, 0.5)]
    cues, holds, t = [(0.0, 0)], [(WARMUP_S, WARMUP_S + 3.0)], WARMUP_S + 3.0
    for label in [x for m in motions for x in (m, 0)]:   # each motion then neutral, 3 s held each
        cues.append((t, label))
        holds.append((t + settle, t + settle + 3.0))
        t += settle + 3.0
    cue = [max((c for c in cues if c[0] <= time), key=lambda c: c[0])[1] for time in session.truth.time_s.tolist()]
    holding = [any(start <= time < stop for start, stop in holds) for time in session.truth.time_s.tolist()]
    assert session.cue.tolist() == cue and session.holding.tolist() == holding
    assert session.holding.sum() > 0.5 * len(holding) and len(set(cue)) == len(params.classes) + 1


def test_session_recording_fuses_back_to_the_true_angles(p1, session):
    _, profile = p1
    rec = session_recording(session, profile)
    index = np.rint(rec.time / DT).astype(int)            # the newest sample in each row
    assert np.all(np.diff(index) >= 0)
    assert (session.recorded & session.holding)[index].all() and (rec.labels == session.cue[index]).all()
    # rows as `bomi record` assembles them: one per sample unless every node's frame of it was lost
    assert 0.9 < len(rec) / (session.recorded & session.holding).sum() <= 1.0
    truth = session.truth.angles[index]
    for k, node in enumerate(profile.node_indices):
        error = rec.nodes[node].angles - truth[:, k]
        assert np.median(np.abs(error[:, :2])) < 0.3   # pitch, roll: filter lag on tremor, held lost frames
        assert np.median(np.abs(error[:, 2])) < 1.0    # yaw: its 1.6 s magnetometer time constant


def live_record(stream: bytes, profile) -> tuple[dict, np.ndarray]:
    """The naive reference of ``record_stream``: `bomi record`'s live steps frame by frame (parser,
    RowAssembler, FusedRows fusing each frame once when a row first holds it, SampleIndex)."""
    ids = tuple(node.node_id for node in profile.nodes)
    assembler, fused = RowAssembler(ids), FusedRows({node.index: node.calibration for node in profile.nodes})
    sample_index, index_of, columns, indices = SampleIndex(), {}, {node.index: [] for node in profile.nodes}, []
    for frame in FrameParser().feed(stream):
        if frame.node_id not in ids:
            continue
        index_of[frame.node_id, frame.counter] = sample_index(frame)
        row = assembler.push(frame)
        if row is not None:
            for node, sample in fused.samples(row).items():
                columns[node].append(np.concatenate([sample.acc, sample.gyro, sample.mag, sample.angles]))
            indices.append(max(index_of[f.node_id, f.counter] for f in row.values()))
    return {node: np.array(rows, dtype=float) for node, rows in columns.items()}, np.array(indices)


@pytest.mark.parametrize("noise", [False, True])
def test_record_stream_is_the_live_recording_to_the_bit(p1, noise):
    """The whole-stream recording (batch parse, rows, fusion) against `bomi record`'s live steps,
    on a session with the link's losses (held frames), and with garbage bytes and a safety-key
    frame in it (the parser's own path)."""
    params, profile = p1
    session = calibration_session(params, profile, 5, repetitions=1, hold_s=1.0, neutral_s=1.0, warmup_s=1.0)
    stream = session.delivery.stream()
    if noise:
        stream = stream[:6400] + b"\x33\x00garbage" + encode_safety_key_frame(SafetyKey.STANDBY, 3) + stream[6400:]
    rec, index = record_stream(stream, profile, "test")
    columns, expected_index = live_record(stream, profile)
    assert np.array_equal(index, expected_index) and len(rec) > 100
    for node, data in rec.nodes.items():
        got = np.hstack([data.acc, data.gyro, data.mag, data.angles])
        assert np.array_equal(got.view(np.int64), columns[node].view(np.int64))


def test_online_chain_on_the_virtual_stream_follows_the_intent(p1, session):
    """Train on a calibration session exactly as `bomi train` does, then drive the live chain with bytes."""
    params, profile = p1
    model = train([session_recording(session, profile)], profile)
    chain = OnlineChain(model, profile)
    vp = VirtualParticipant(params, profile, seed=11)
    parser = FrameParser()
    schedule = {14.0: 1, 19.0: 0, 24.0: 4, 29.0: 0, 34.0: 2, 39.0: 0}
    decisions = []
    for step in range(1, 60 * 44):
        t = step / 60.0
        decisions += [(t, d.label) for d in chain.push_frames(parser.feed(vp.advance(t)))]
        if step == 60 * 12:
            chain.begin_neutral_calibration()
        for when, label in schedule.items():
            if abs(t - when) < 1e-9:
                vp.set_intent(label, 1.0, t)
    times, labels = map(np.array, zip(*decisions))
    for start, label in [(16.0, 1), (21.0, 0), (26.0, 4), (31.0, 0), (36.0, 2), (41.0, 0)]:
        hold = labels[(times > start) & (times < start + 3.0)]
        assert np.mean(hold == label) > 0.9, (label, np.bincount(hold))


# ------------------------------------------------------------------- spasms, range, timing (issue 53)
def test_a_class_range_share_scales_its_posture():
    p5 = load_participant("P5")
    assert p5.classes[3].posture_deg.tolist() == [[0.0, 0.0, 0.0], [0.0, 0.1 * 25.0, 0.0]]   # P5.toml: 0.1 x 25 deg
    assert p5.classes[4].posture_deg.tolist() == [[0.0, 0.0, 0.0], [0.0, -25.0, 0.0]]        # the others as written


def test_a_motion_sets_off_its_spasm_once_its_posture_is_reached():
    from tasks.participants.params import EvokedSpasm
    p4 = dataclasses.replace(load_participant("P4"), spasm=None, reaction_sd_s=0.0,
                             evoked_spasm=EvokedSpasm((1,), 1.0, (1.0, 1.0), (0.5, 0.5)))
    profile = load_profile("P4")
    vp = VirtualParticipant(p4, profile, seed=2)
    reached = vp.set_intent(1, 1.0, 1.0)
    assert reached == pytest.approx(1.0 + p4.reaction_s + p4.onset_s)
    assert vp.set_intent(2, 1.0, 6.0) is not None and vp.set_intent(2, 1.0, 6.5) is None   # held: nothing new
    vp.deliveries(9.0)
    truth = vp.truth()
    move = vp.moves[1]
    pitch = truth.angles[:, 0, 0]

    def mean_pitch(start: float, stop: float) -> float:
        return float(pitch[(truth.time_s >= start) & (truth.time_s < stop)].mean())

    # the raised cosine peaks half-way: half the move's excursion pulled back, around the middle second
    dip = mean_pitch(reached + 0.45, reached + 0.55) - mean_pitch(reached + 1.2, reached + 2.0)
    excursion = (move.target - move.start)[0, 0]
    assert dip == pytest.approx(-0.5 * excursion, abs=2.0)
    # c2's move sets off nothing: after c1's spasm, only the c2 move
    assert len(vp._evoked) == 1


def test_a_clonic_spasm_beats_at_its_rate_between_the_posture_and_the_pulled_back_point():
    from tasks.participants.params import EvokedSpasm
    p4 = dataclasses.replace(load_participant("P4"), spasm=None, reaction_sd_s=0.0,
                             evoked_spasm=EvokedSpasm((1,), 1.0, (2.0, 2.0), (0.5, 0.5), beat_hz=5.0))
    vp = VirtualParticipant(p4, load_profile("P4"), seed=2)
    reached = vp.set_intent(1, 1.0, 1.0)
    vp.deliveries(6.0)
    truth = vp.truth()
    excursion = (vp.moves[1].target - vp.moves[1].start)[0, 0]
    during = (truth.time_s >= reached) & (truth.time_s < reached + 2.0)
    pulled = truth.angles[during, 0, 0] - truth.angles[(truth.time_s >= reached + 2.5), 0, 0].mean()
    # the deepest beat, in the spasm's middle, pulls back the full half excursion; the pull averages a quarter
    # of that over the spasm (its raised-cosine course and its beats, a half each)
    assert pulled.min() == pytest.approx(-0.5 * excursion, abs=2.0)
    assert pulled.mean() == pytest.approx(-0.5 * 0.5 * 0.5 * excursion, abs=1.0)   # (raised cosine x beats: 1/4)
    # ten beats in two seconds: above the spasm's own slow course (0.5 Hz), the pull's spectrum peaks at 5 Hz
    spectrum = np.abs(np.fft.rfft(pulled - pulled.mean()))
    frequencies = np.fft.rfftfreq(len(pulled), truth.time_s[1] - truth.time_s[0])
    fast = frequencies >= 2.0
    assert frequencies[fast][np.argmax(spectrum[fast])] == pytest.approx(5.0, abs=0.5)
    assert spectrum[fast].max() > 5 * np.median(spectrum[fast])


def test_a_rest_keeps_its_carry_over_of_the_rest_before_and_rests_keep_their_spread():
    p1 = load_participant("P1")
    assert p1.rest_carry[2].tolist() == [0.756, 0.753, 0.796]             # P1.toml [neutral] carry_over
    assert load_participant("P4").rest_carry is None                      # absent: each rest drawn anew

    def rest_offsets(params) -> np.ndarray:
        vp = VirtualParticipant(dataclasses.replace(params, reaction_sd_s=0.0), load_profile("P1"), seed=5)
        for k in range(1, 801):
            vp.set_intent(1 if k % 2 else 0, 1.0, 3.0 * k)
        return np.array([m.target - params.neutral.posture_deg for m in vp.moves if m.label == 0])

    carried = rest_offsets(p1)
    fresh = rest_offsets(dataclasses.replace(p1, rest_carry=None))
    lag1 = lambda x: np.mean(x[1:] * x[:-1], axis=0) / np.mean(x * x, axis=0)  # noqa: E731
    assert lag1(carried) == pytest.approx(p1.rest_carry, abs=0.12)     # 400 rests: sampling error about 0.05
    assert np.abs(lag1(fresh)).max() < 0.15
    # the stationary spread is rep_std either way (the AR(1) keeps the variance)
    for offsets in (carried, fresh):
        assert offsets.std(axis=0) == pytest.approx(p1.neutral.rep_std_deg, rel=0.2)


def test_reaction_and_move_times_vary_as_gamma_draws_of_the_stated_mean_and_spread():
    params = dataclasses.replace(load_participant("P1"), reaction_s=0.6, reaction_sd_s=0.2, onset_s=1.0, onset_sd_s=0.1)
    vp = VirtualParticipant(params, load_profile("P1"), seed=4)
    cues = np.arange(400) * 5.0
    for k, t in enumerate(cues):
        vp.set_intent(1 + k % 2, 1.0, float(t))
    starts = np.array([m.t0 for m in vp.moves[1:]])
    durations = np.array([m.duration for m in vp.moves[1:]])
    reactions = starts - cues
    assert reactions.mean() == pytest.approx(0.6, abs=0.03) and reactions.std() == pytest.approx(0.2, rel=0.15)
    assert durations.mean() == pytest.approx(1.0, abs=0.02) and durations.std() == pytest.approx(0.1, rel=0.15)
    assert (reactions > 0).all()


def test_the_recorded_day_is_the_fitted_posture_on_every_seed():
    from tasks.participants.params import recorded_day
    p1 = load_participant("P1")
    for seed in (1, 2):
        days = VirtualParticipant(recorded_day(p1), load_profile("P1"), seed).day_postures
        assert all(np.array_equal(days[label], m.posture_deg) for label, m in p1.classes.items())
    drawn = VirtualParticipant(p1, load_profile("P1"), 1).day_postures
    assert not np.array_equal(drawn[1], p1.classes[1].posture_deg)


def test_a_participant_leans_up_to_its_most_lean_and_no_further():
    p1, p4 = load_participant("P1"), load_participant("P4")
    assert p1.feel.most_lean == 1.246                                # measured on its five days ([provenance])
    assert p4.feel.most_lean == 1.0                                  # absent from the file: the posture
    far = dataclasses.replace(p4, feel=dataclasses.replace(p4.feel, most_lean=1.1))
    vp = VirtualParticipant(far, load_profile("P4"), seed=1)
    vp.set_intent(1, 1.1, 0.0)
    with pytest.raises(ValueError, match=r"amplitude must be in \[0, 1.1\]"):
        vp.set_intent(2, 1.2, 5.0)
    with pytest.raises(ValueError, match=r"amplitude must be in \[0, 1\]"):
        VirtualParticipant(p4, load_profile("P4"), seed=1).set_intent(1, 1.1, 0.0)
    with pytest.raises(ValueError, match=r"amplitude must be in \[0, 1.246\]"):
        VirtualParticipant(p1, load_profile("P1"), seed=1).set_intent(1, 1.3, 0.0)


def test_a_corrected_lean_keeps_its_posture_with_an_error_in_proportion_to_the_correction():
    """A move from rest lands a repetition's spread (rep_std, scaled by the lean) from the day's posture;
    a correction of the lean held within the class keeps that posture and errs by rep_std x the
    correction's size (signal-dependent motor noise): hand-computed spreads over 400 seeds."""
    params = dataclasses.replace(load_participant("P1"), reaction_sd_s=0.0, rest_carry=None)
    profile, rep = load_profile("P1"), params.classes[1].rep_std_deg
    first, corrected = [], []
    for seed in range(400):
        vp = VirtualParticipant(params, profile, seed)
        vp.set_intent(1, 0.8, 0.0)
        vp.set_intent(1, 0.95, 3.0)
        day, neutral = vp.day_postures[1], params.neutral.posture_deg
        from_rest, correction = (m.target - neutral for m in vp.moves[-2:])
        first.append(from_rest - 0.8 * day)
        corrected.append(correction - from_rest * 0.95 / 0.8)   # what the posture kept does not explain
    # 400 draws: a spread's sampling error is about 3.5 %
    assert np.std(first, axis=0) == pytest.approx(0.8 * rep, rel=0.15)
    assert np.std(corrected, axis=0) == pytest.approx(0.15 * rep, rel=0.15)
