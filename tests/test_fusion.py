"""Fusion against hardware.md: the worked example frame, hand-computed steps, batch == streaming."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bomi.compiled import interpreted
from bomi.fusion import HEADSET_SOFT_IRON, NodeCalibration, NodeFusion, fuse, fuse_samples, neutral_offsets
from helpers import assert_same_angles

K_DT = 2000 / 32768 / 62.5
# hardware.md worked example, decoded (headset, counter 42): mag, gyro, acc in raw LSB
MAG, GYRO, ACC = (-1631, -2177, 5939), (-1, -11, 5), (-733, -847, 15625)


def hand_heading(pitch: float, roll: float) -> float:
    """hardware.md step 5 for the example's magnetometer: C . (mx - h0, my - h1, -mz - h2), mounted."""
    v = np.array([-1631 + 127.4200, -2177 - 158.6824, -5939 + 57.7485])
    m = np.array(HEADSET_SOFT_IRON) @ v
    m1, m2, m3 = -m[2], -m[0], m[1]
    c_p, s_p = math.cos(math.radians(-pitch)), math.sin(math.radians(-pitch))
    c_r, s_r = math.cos(math.radians(roll)), math.sin(math.radians(roll))
    y_h = s_p * c_r * m1 + c_p * m2 + s_p * s_r * m3
    z_h = -s_r * m1 + c_r * m3
    return math.degrees(math.atan2(-z_h, -y_h))


def test_worked_example_first_step_by_hand():
    # Mounting (x, y, z) -> (-z, -x, y): acc (-15625, 733, -847), gyro (-5, 1, -11).
    pitch_state = 0.08 * math.degrees(math.atan2(-733, 15625)) + 0.92 * (0 - (-11) * K_DT)
    roll_state = 0.08 * math.degrees(math.atan2(847, 15625)) + 0.92 * (0 + 1 * K_DT)
    assert pitch_state == pytest.approx(-0.2049884236, abs=1e-9)   # computed on paper: -0.21487 + 0.00988
    pitch, roll = 0.355 * pitch_state, 0.355 * roll_state           # low-pass from zero state
    yaw = 0.01 * hand_heading(pitch, roll) + 0.99 * (0 + (-5) * K_DT)

    out = NodeFusion().update(ACC, GYRO, MAG)
    assert out == pytest.approx((pitch, roll, yaw), abs=1e-12)
    assert out == pytest.approx((-0.0727709, 0.0884400, 1.2032404), abs=1e-6)


def test_second_step_carries_filter_states():
    node = NodeFusion()
    p1, r1, y1 = node.update(ACC, GYRO, MAG)
    p_state1, r_state1 = p1 / 0.355, r1 / 0.355
    p_state2 = 0.08 * math.degrees(math.atan2(-733, 15625)) + 0.92 * (p_state1 + 11 * K_DT)
    r_state2 = 0.08 * math.degrees(math.atan2(847, 15625)) + 0.92 * (r_state1 + K_DT)
    p2 = 0.355 * p_state2 + 0.355 * p_state1 + 0.2905 * p1
    r2 = 0.355 * r_state2 + 0.355 * r_state1 + 0.2905 * r1
    y2 = 0.01 * hand_heading(p2, r2) + 0.99 * (y1 - 5 * K_DT)
    assert node.update(ACC, GYRO, MAG) == pytest.approx((p2, r2, y2), abs=1e-12)


def test_static_tilt_settles_to_accelerometer_angle():
    """No rotation: pitch/roll converge to the accelerometer tilt times the low-pass DC gain 0.71/0.7095."""
    acc = np.tile([[-16000.0, 3000.0, -2000.0]], (400, 1))   # already in body axes (identity mounting)
    gyro = np.zeros((400, 3))
    mag = np.tile([[0.2, 0.5, -0.8]], (400, 1))
    pitch, roll, _ = fuse(acc, gyro, mag, NodeCalibration.uncalibrated())
    dc_gain = (0.355 + 0.355) / (1 - 0.2905)
    assert pitch[-1] == pytest.approx(dc_gain * math.degrees(math.atan2(-3000, 16000)), abs=1e-9)
    assert roll[-1] == pytest.approx(dc_gain * math.degrees(math.atan2(2000, 16000)), abs=1e-9)
    assert abs(pitch[99] - pitch[-1]) < 0.01 * abs(pitch[-1])   # settled within ~100 samples


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_batch_equals_streaming_exactly(seed):
    rng = np.random.default_rng(seed)
    acc, gyro, mag = (rng.integers(-32768, 32768, (60, 3)) for _ in range(3))
    cal = NodeCalibration()
    batch = np.column_stack(fuse(acc, gyro, mag, cal))
    node = NodeFusion(cal)
    stream = np.array([node.update(a, g, m) for a, g, m in zip(acc, gyro, mag)])
    assert np.array_equal(batch, stream)


def test_refusing_published_raw_columns_tracks_published_pitch_and_roll(p1_days):
    """The published raw columns are pre-rotated (dataset README), so only close tracking is expected."""
    node = p1_days[1].nodes[1]
    pitch, roll, _ = fuse(node.acc[:3000], node.gyro[:3000], node.mag[:3000], NodeCalibration.uncalibrated())
    assert np.corrcoef(pitch[600:], node.angles[600:3000, 0])[0, 1] > 0.9
    assert np.corrcoef(roll[600:], node.angles[600:3000, 1])[0, 1] > 0.95


def test_calibration_validation_and_neutral():
    with pytest.raises(ValueError, match="rotation matrix"):
        NodeCalibration(mounting=((2, 0, 0), (0, 1, 0), (0, 0, 1)))
    with pytest.raises(ValueError, match="3 finite numbers"):
        NodeCalibration(hard_iron=(0, 0))
    angles = np.arange(30.0).reshape(10, 3)
    assert neutral_offsets(angles, 2).tolist() == [1.5, 2.5, 3.5]


def naive_update(state: dict, cal: NodeCalibration, acc, gyro, mag) -> tuple[float, float, float]:
    """hardware.md section 3 with numpy matrices (an independent form of NodeFusion.update)."""
    mount, soft = np.array(cal.mounting), np.array(cal.soft_iron)
    m = mount @ (soft @ (np.array([mag[0], mag[1], -mag[2]], float) - np.array(cal.hard_iron)))
    a, g = mount @ np.array(acc, float), mount @ np.array(gyro, float)
    step = 2000.0 / 32768.0 / 62.5
    pitch_state = 0.08 * math.degrees(math.atan2(-a[1], -a[0])) + 0.92 * (state["ps"] - g[2] * step)
    roll_state = 0.08 * math.degrees(math.atan2(-a[2], -a[0])) + 0.92 * (state["rs"] + g[1] * step)
    state["p"] = 0.355 * (pitch_state + state["ps"]) + 0.2905 * state["p"]
    state["r"] = 0.355 * (roll_state + state["rs"]) + 0.2905 * state["r"]
    state["ps"], state["rs"] = pitch_state, roll_state
    p, r = math.radians(-state["p"]), math.radians(state["r"])
    y_h = math.sin(p) * math.cos(r) * m[0] + math.cos(p) * m[1] + math.sin(p) * math.sin(r) * m[2]
    z_h = -math.sin(r) * m[0] + math.cos(r) * m[2]
    state["y"] = 0.01 * math.degrees(math.atan2(-z_h, -y_h)) + 0.99 * (state["y"] + g[0] * step)
    return state["p"], state["r"], state["y"]


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_update_follows_the_documented_formulas_with_any_calibration(seed):
    rng = np.random.default_rng(seed)
    mounting = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    mounting *= np.sign(np.linalg.det(mounting))   # a rotation
    cal = NodeCalibration(hard_iron=rng.normal(scale=100, size=3), soft_iron=np.eye(3) * 1e-4 + rng.normal(scale=1e-5, size=(3, 3)),
                          mounting=mounting)
    node, state = NodeFusion(cal), {"ps": 0.0, "rs": 0.0, "p": 0.0, "r": 0.0, "y": 0.0}
    for acc, gyro, mag in zip(*(rng.integers(-20000, 20000, (40, 3)).tolist() for _ in range(3))):
        assert node.update(acc, gyro, mag) == pytest.approx(naive_update(state, cal, acc, gyro, mag), abs=1e-9)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.lists(st.integers(0, 300), max_size=4))
def test_update_many_is_update_sample_by_sample_to_the_bit(seed, cuts):
    """The batch filter against the per-sample ``update``, over any calibration, whole and cut into
    pieces (a stream's chunks) of any length, the filter state carried across the cuts."""
    rng = np.random.default_rng(seed)
    mounting = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    mounting *= np.sign(np.linalg.det(mounting))
    cal = NodeCalibration(hard_iron=rng.normal(scale=100, size=3), soft_iron=np.eye(3) * 1e-4 + rng.normal(scale=1e-5, size=(3, 3)),
                          mounting=mounting)
    acc, gyro, mag = (rng.integers(-32768, 32768, (300, 3)) for _ in range(3))
    acc[::7] = 0                                  # zero tilt components and signed zeros on the way
    reference = NodeFusion(cal)
    expected = np.array([reference.update(a, g, m) for a, g, m in zip(acc.tolist(), gyro.tolist(), mag.tolist())])
    node, pieces = NodeFusion(cal), []
    assert np.array_equal(NodeFusion(cal).update_many(acc, gyro, mag).view(np.int64), expected.view(np.int64))
    bounds = [0, *sorted(cuts), 300]
    for lo, hi in zip(bounds, bounds[1:]):
        pieces.append(node.update_many(acc[lo:hi], gyro[lo:hi], mag[lo:hi]))
    got = np.vstack(pieces)
    assert np.array_equal(got.view(np.int64), expected.view(np.int64))
    assert node == reference   # the filter state too: a stream may go on from there


def test_the_compiled_filter_agrees_with_the_interpreted_one(p1_days):
    """``fuse_samples`` compiled by numba (where installed) and run as the Python function it is: the
    same angles, and the same filter state after the day (pitch, roll and yaw states, the low-passed
    pitch and roll: what a stream goes on from), to FILTER_FORMS_DEG over a real day of P1's three
    nodes (the published raw columns). The state's five values are degrees of the same stable filter
    as the angles (each decays by 0.92, 0.99 or 0.29 a sample), so the roundings of the two forms stay
    as far below the tolerance in the state as in the angles."""
    for index, node in p1_days[2].nodes.items():
        cal, raw = NodeCalibration.default_for(index), [np.ascontiguousarray(v, dtype=float) for v in (node.acc, node.gyro, node.mag)]
        compiled_fusion, interpreted_fusion = NodeFusion(cal), NodeFusion(cal)
        out_compiled, out_interpreted = np.empty((len(raw[0]), 3)), np.empty((len(raw[0]), 3))
        fuse_samples(compiled_fusion.state, compiled_fusion._constants, *raw, out_compiled)
        interpreted(fuse_samples)(interpreted_fusion.state, interpreted_fusion._constants, *raw, out_interpreted)
        assert_same_angles(out_compiled, out_interpreted)
        assert not np.array_equal(compiled_fusion.state, NodeFusion(cal).state)     # the day moved it
        assert_same_angles(compiled_fusion.state, interpreted_fusion.state)

