"""tasks.participants.imu_synth: hand-computed sensor readings, and the round trip through bomi.fusion."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bomi.frames import FrameParser
from helpers import assert_agree
from bomi.fusion import GYRO_DEG_PER_LSB, NodeCalibration, fuse
from tasks.participants.imu_synth import (STACKED_FROM, EarthField, LinkModel, RawImu, SensorNoise, deliver, distort_magnetometer, synthesize_nodes,
                             synthesize_raw, to_int16, euler_rotations, node_arrays, rotation_rows)

NO_NOISE = SensorNoise(0.0, 0.0, 0.0)
HEADSET = NodeCalibration()
UNCALIBRATED = NodeCalibration.uncalibrated()
# an arbitrary node: tilted mounting, strong soft iron with cross terms, large hard-iron offset
ODD = NodeCalibration(hard_iron=(300.0, -450.0, 120.0),
                      soft_iron=((2.1e-4, 3e-5, -1e-5), (3e-5, 1.5e-4, 2e-5), (-1e-5, 2e-5, 1.8e-4)),
                      mounting=tuple(map(tuple, Rotation.from_euler("zyx", [30, -20, 75], degrees=True).as_matrix())))
SETTLE = 900   # yaw settles within ~600 samples from the zero state (hardware.md); margin added


def fused(raw: RawImu, cal: NodeCalibration) -> np.ndarray:
    return np.column_stack(fuse(raw.acc.astype(float), raw.gyro.astype(float), raw.mag.astype(float), cal))


def test_neutral_headset_reads_one_g_on_sensor_z():
    # body x (down) = -sensor z for the headset mounting, so gravity's reaction is +1 g on sensor z
    raw = synthesize_raw(np.zeros((1, 3)), HEADSET, np.random.default_rng(0), NO_NOISE)
    assert raw.acc[0].tolist() == [0, 0, round(1000 / 0.061)]
    assert raw.gyro[0].tolist() == [0, 0, 0]


@pytest.mark.parametrize("column, body_axis, sign", [(0, 2, -1), (1, 1, +1), (2, 0, +1)])
def test_constant_rates_follow_the_fusion_sign_conventions(column, body_axis, sign):
    # pitch rate = -gz K, roll rate = +gy K, yaw rate = +gx K (body axes); 10 deg/s ramp
    angles = np.zeros((40, 3))
    angles[:, column] = 10.0 * np.arange(40) / 62.5
    raw = synthesize_raw(angles, UNCALIBRATED, np.random.default_rng(0), NO_NOISE)
    expected = np.zeros(3)
    expected[body_axis] = sign * 10.0 / GYRO_DEG_PER_LSB
    assert np.abs(raw.gyro[1:] - expected).max() <= 1   # rounding only


def test_headset_pitch_rate_lands_on_sensor_y():
    # body z = sensor y for (x, y, z) -> (-z, -x, y); a 10 deg/s pitch-up means body gz = -10 deg/s
    angles = np.column_stack([10.0 * np.arange(20) / 62.5, np.zeros(20), np.zeros(20)])
    raw = synthesize_raw(angles, HEADSET, np.random.default_rng(0), NO_NOISE)
    assert raw.gyro[5].tolist() == [0, round(-10.0 / GYRO_DEG_PER_LSB), 0]


def test_magnetometer_distortion_is_undone_by_the_hardware_correction():
    rng = np.random.default_rng(1)
    corrected = rng.normal(0.0, 0.8, (50, 3))
    raw, = distort_magnetometer(corrected[None], node_arrays((ODD,)))
    h, c = np.array(ODD.hard_iron), np.array(ODD.soft_iron)
    # hardware.md step 1, written out: m = C (mx - h0, my - h1, -mz - h2)
    again = np.array([c @ np.array([x - h[0], y - h[1], -z - h[2]]) for x, y, z in raw])
    np.testing.assert_allclose(again, corrected, atol=1e-9)


def test_int16_saturates_and_rounds():
    assert to_int16(np.array([40000.0, -40000.0, 1.5, -2.4])).tolist() == [32767, -32768, 2, -2]


@pytest.mark.parametrize("cal", [HEADSET, UNCALIBRATED, ODD], ids=["headset", "uncalibrated", "odd"])
@pytest.mark.parametrize("target", [(0, 0, 0), (29, -2, -3), (2, 24, -21), (-2, -28, 30), (-25, 5, -12),
                                    (10, -20, 60), (40, 35, -120)])
def test_static_round_trip_through_fusion(cal, target):
    """Settled fusion of the synthesised data returns the intended angles.

    Without noise the only error is int16 rounding: 1 LSB of a ~16,400 LSB gravity is 0.004 deg;
    the horizontal earth field is only ~1,700 LSB (70 deg inclination), so 1 LSB of it is ~0.03 deg
    of heading; 0.1 deg leaves room for both and the yaw filter's residual after SETTLE samples.
    """
    angles = np.tile(np.array(target, float), (SETTLE, 1))
    out = fused(synthesize_raw(angles, cal, np.random.default_rng(0), NO_NOISE), cal)
    np.testing.assert_allclose(out[-1], target, atol=0.1)


def minimum_jerk_path(start, stop, n_move, n_hold, n_before=SETTLE):
    s = np.linspace(0.0, 1.0, n_move)
    profile = np.r_[np.zeros(n_before), s ** 3 * (10 - 15 * s + 6 * s ** 2), np.ones(n_hold)]
    return np.asarray(start, float) + profile[:, None] * (np.asarray(stop, float) - np.asarray(start, float))


@pytest.mark.parametrize("stop", [(28, -3, -1), (3, 25, -21), (-3, -26, 27), (-1, -3, -12)])
def test_dynamic_round_trip_with_noise(stop):
    """A 0.8 s minimum-jerk move then a 5 s hold, with sensor noise: steady state within 0.3 deg.

    During the move the complementary filter lags (the gyro is the true body rate, not the angle
    rates), and the yaw correction has a 1.6 s time constant, hence judging the last 0.5 s.
    """
    start = (-2.5, 1.5, -1.9)
    angles = minimum_jerk_path(start, np.add(start, stop), 50, 312)
    out = fused(synthesize_raw(angles, HEADSET, np.random.default_rng(3)), HEADSET)
    steady = slice(-31, None)
    np.testing.assert_allclose(out[steady].mean(axis=0), angles[-1], atol=0.3)
    assert np.abs(out[SETTLE:] - angles[SETTLE:]).max() < 5.0   # no runaway during the move


def make_raw(n: int, seed: int) -> dict[int, RawImu]:
    rng = np.random.default_rng(seed)
    return {node: RawImu(*(rng.integers(-30000, 30000, (n, 3)).astype(np.int16) for _ in range(3)))
            for node in (1, 2, 3)}


def generators(seed: int) -> dict[int, np.random.Generator]:
    return {node: np.random.default_rng([seed, node]) for node in (1, 2, 3)}


def test_delivery_loses_frames_but_counters_advance_and_values_survive():
    n = 3000
    raw = make_raw(n, 0)
    index = np.arange(n)
    out = deliver(raw, index, index / 62.5, generators(5))
    parser = FrameParser()
    frames = parser.feed(out.stream())
    assert len(frames) == len(out.frames)
    lost = 3 * n - len(frames)
    assert 0.08 < lost / (3 * n) < 0.10                    # 9 % +- ~4 binomial sigmas
    # the parser's lost count (from counters) sees every dropped frame after each node's first
    first = {node: int(out.sample_index[out.node_index == node].min()) for node in (1, 2, 3)}
    last = {node: int(out.sample_index[out.node_index == node].max()) for node in (1, 2, 3)}
    assert parser.total_lost == lost - sum(first.values()) - sum(n - 1 - last[k] for k in last)
    for frame, node, k in zip(frames, out.node_index, out.sample_index):
        assert (frame.acc, frame.gyro, frame.mag) == (tuple(raw[node].acc[k]), tuple(raw[node].gyro[k]),
                                                      tuple(raw[node].mag[k]))
        assert frame.counter == k % 256 and frame.node_id == 9 + node


def test_delivery_is_bursty_ordered_interleaved_and_seeded():
    n = 1000
    raw = make_raw(n, 1)
    index = np.arange(n)
    out = deliver(raw, index, index / 62.5, generators(7))
    assert np.all(np.diff(out.arrival_s) >= 0)
    for node in (1, 2, 3):
        assert np.all(np.diff(out.sample_index[out.node_index == node]) > 0)   # a node never overtakes itself
        arrival = out.arrival_s[out.node_index == node]
        assert np.all(arrival >= out.sample_index[out.node_index == node] / 62.5)  # nothing arrives before it is sampled
    assert len(out.arrival_s) / len(np.unique(out.arrival_s)) > 4           # bursts: several frames per arrival
    assert len(set(out.node_index[:12].tolist())) == 3                        # nodes interleaved
    again = deliver(raw, index, index / 62.5, generators(7))
    other = deliver(raw, index, index / 62.5, generators(8))
    assert again.stream() == out.stream() and other.stream() != out.stream()


def test_delivery_in_pieces_equals_delivery_in_one_piece():
    raw = make_raw(500, 3)
    index = np.arange(500)
    whole = deliver(raw, index, index / 62.5, generators(4))
    rngs, last, parts = generators(4), {}, []
    for piece in np.array_split(index, [1, 7, 90, 91, 300]):
        part = deliver({n: RawImu(r.acc[piece], r.gyro[piece], r.mag[piece]) for n, r in raw.items()},
                       piece, piece / 62.5, rngs, not_before_s=last)
        last.update({int(n): float(part.arrival_s[part.node_index == n].max()) for n in np.unique(part.node_index)})
        parts.append(part)
    arrival = np.concatenate([p.arrival_s for p in parts])
    frames = [f for p in parts for f in p.frames]
    order = np.argsort(arrival, kind="stable")
    assert [frames[i] for i in order] == whole.frames
    np.testing.assert_array_equal(arrival[order], whole.arrival_s)


def test_nodes_delivered_together_are_each_node_delivered_alone_interleaved():
    """The link's arithmetic over all nodes at once against one node at a time (each its own generator),
    the frames then put in arrival order by hand: the same frames, arrival times and indices."""
    raw, index, floor = make_raw(400, 5), np.arange(400), {2: 3.5}
    together = deliver(raw, index, index / 62.5, generators(3), not_before_s=floor)
    alone = [deliver({node: raw[node]}, index, index / 62.5, {node: generators(3)[node]}, not_before_s=floor)
             for node in (3, 1, 2)]
    arrival, node, sample = (np.concatenate([getattr(a, name) for a in alone])
                             for name in ("arrival_s", "node_index", "sample_index"))
    frames = [f for a in alone for f in a.frames]
    order = np.lexsort((node, sample, arrival))
    assert together.frames == [frames[i] for i in order]
    assert np.array_equal(together.arrival_s, arrival[order]) and together.arrival_s.min() < 3.5
    assert np.array_equal(together.node_index, node[order]) and np.array_equal(together.sample_index, sample[order])
    assert together.arrival_s[together.node_index == 2].min() == 3.5


def test_no_loss_link_delivers_everything():
    raw = make_raw(200, 2)
    index = np.arange(200)
    out = deliver(raw, index, index / 62.5, generators(0), LinkModel(loss_fraction=0.0))
    assert len(out.frames) == 600
    early, late = out.until(1.0)
    assert early.arrival_s.max() <= 1.0 < late.arrival_s.min()
    assert early.stream() + late.stream() == out.stream()


def test_several_nodes_at_once_equal_one_node_at_a_time():
    rng = np.random.default_rng(9)
    angles = rng.normal(0.0, 20.0, (30, 3, 3))
    previous = rng.normal(0.0, 20.0, (3, 3))
    cals = [HEADSET, UNCALIBRATED, ODD]
    together = synthesize_nodes(angles, cals, [rng] * 3, NO_NOISE, previous_deg=previous)
    for node, cal in enumerate(cals):
        alone = synthesize_raw(angles[:, node], cal, rng, NO_NOISE, previous_deg=previous[node])
        for name in ("acc", "gyro", "mag"):
            np.testing.assert_array_equal(getattr(together[node], name), getattr(alone, name))


def test_linear_acceleration_tilts_the_accelerometer_angles():
    # 0.1 g along body y at zero tilt: acc = (-1, 0.1, 0) g, so pitch settles at atan2(-0.1, 1)
    n = 400
    linear = np.zeros((n, 1, 3))
    linear[:, 0, 1] = 0.1
    raw = synthesize_nodes(np.zeros((n, 1, 3)), [UNCALIBRATED], [np.random.default_rng(0)], NO_NOISE,
                           linear_acc_g=linear)[0]
    pitch, roll, _ = fused(raw, UNCALIBRATED)[-1]
    assert pitch == pytest.approx(np.degrees(np.arctan2(-0.1, 1.0)), abs=0.01) and abs(roll) < 0.01


@pytest.mark.parametrize("seq, degrees", [("XZY", False), ("YZX", True)])
def test_stacked_rotations_are_the_listed_rotations(seq, degrees):
    """euler_rotations' stack (scipy's vectorised path, for long trajectories) against scipy's plain
    list (its per-rotation path): the same quaternions and relative rotation vectors (the gyro) to 4
    ulps of their largest magnitude (the two paths may take different SIMD code on one CPU: seen
    exact on AVX2, 2 ulps apart on AVX-512); applied vectors (gravity, the earth field) summed in
    another order, to round-off."""
    rng = np.random.default_rng(11)
    angles = rng.normal(0.0, 40.0 if degrees else 0.7, (STACKED_FROM + 9, 3))
    angles[::50] = 0.0
    stacked, listed = euler_rotations(seq, angles, degrees), Rotation.from_euler(seq, angles, degrees=degrees)
    assert stacked.shape == (1, len(angles)) and listed.shape == (len(angles),)
    assert_agree(stacked.as_quat()[0], listed.as_quat())
    now, before = rotation_rows(stacked, slice(3, None)), rotation_rows(stacked, slice(None, -3))
    assert_agree((before.inv() * now).as_rotvec()[0], (listed[:-3].inv() * listed[3:]).as_rotvec())
    field = EarthField(inclination_deg=63.0).at_zero_heading()
    np.testing.assert_allclose(now.apply(field)[0], listed[3:].apply(field), rtol=0, atol=1e-9)


def test_a_trajectory_synthesised_whole_is_synthesised_in_pieces_count_for_count():
    """Whole (scipy's stacked path) against short pieces (its per-rotation path, the naive reference):
    the same int16 counts of every sensor (the round-off of an applied vector does not reach a count)."""
    rng = np.random.default_rng(4)
    angles = np.cumsum(rng.normal(0.0, 0.4, (1500, 2, 3)), axis=0) + [[10.0, -5.0, 30.0], [0.0, 3.0, -20.0]]
    cals = [NodeCalibration(), NodeCalibration.uncalibrated()]
    whole = synthesize_nodes(angles, cals, [np.random.default_rng(s) for s in (1, 2)])
    rngs, pieces, previous = [np.random.default_rng(s) for s in (1, 2)], [], None
    for lo in range(0, 1500, 100):
        pieces.append(synthesize_nodes(angles[lo:lo + 100], cals, rngs, previous_deg=previous))
        previous = angles[lo + 99]
    for k in range(2):
        for name in ("acc", "gyro", "mag"):
            assert np.array_equal(getattr(whole[k], name), np.vstack([getattr(p[k], name) for p in pieces]))
