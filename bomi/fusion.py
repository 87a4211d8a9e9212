"""Per-node orientation fusion exactly as ../shared/docs/hardware.md section 3 describes it.

Magnetometer hard/soft-iron correction, mounting rotation, complementary filters on pitch and roll,
a 10 Hz low-pass on both, tilt-compensated complementary yaw. ``NodeFusion.update`` (one sample,
the stream) and ``NodeFusion.update_many`` (n samples in a row, a whole recording: ``fuse``) are the
same filter, the same IEEE operations in the same order, and agree bit for bit (tests/test_fusion.py).
Angles in degrees; inputs raw int16 LSB in the sensor's own axes.
"""
from __future__ import annotations

import math
from math import atan2, cos, degrees, radians, sin
from dataclasses import dataclass, field

import numpy as np

from bomi.frames import SAMPLE_PERIOD_S, ImuFrame, imu_index, imu_node_id
from bomi.recording import NodeData, NodeSample, Recording

GYRO_DEG_PER_LSB = 2000.0 / 32768.0
DT = SAMPLE_PERIOD_S  # the filters integrate over one nominal sample period
# A stream's first seconds, not used: from a zero state yaw settles within about 600 samples (hardware.md)
WARMUP_S = 12.0
GYRO_WEIGHT = 0.92
ACC_WEIGHT = 0.08
MAG_WEIGHT = 0.01
LOWPASS_B = 0.355   # y[n] = b x[n] + b x[n-1] + a y[n-1]: first order, 10 Hz at 62.5 Hz
LOWPASS_A = 0.2905
_GYRO_STEP = GYRO_DEG_PER_LSB * DT
# ``update_many`` below this many samples calls ``update`` per sample: its array passes cost a fixed
# ~90 us, ``update`` ~2.5 us a sample (the same bits either way)
ARRAY_PASSES_FROM = 64

Vector3 = tuple[float, float, float]
Matrix3 = tuple[Vector3, Vector3, Vector3]

IDENTITY: Matrix3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
HEADSET_HARD_IRON: Vector3 = (-127.4200, 158.6824, -57.7485)
HEADSET_SOFT_IRON: Matrix3 = (
    (1.6357e-4, -1.0404e-5, -1.4933e-6),
    (-1.0404e-5, 1.5810e-4, 6.6342e-7),
    (1.4933e-6, 6.6342e-7, 1.6295e-4),
)
HEADSET_MOUNTING: Matrix3 = ((0.0, 0.0, -1.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0))  # (x,y,z) -> (-z,-x,y)


def _as_vector(values, name: str) -> Vector3:
    vector = tuple(float(v) for v in values)
    if len(vector) != 3 or not all(math.isfinite(v) for v in vector):
        raise ValueError(f"{name} must be 3 finite numbers, got {values!r}")
    return vector


def _as_matrix(values, name: str) -> Matrix3:
    rows = tuple(tuple(float(v) for v in row) for row in values)
    if len(rows) != 3 or any(len(r) != 3 for r in rows) or not all(math.isfinite(v) for r in rows for v in r):
        raise ValueError(f"{name} must be a 3x3 matrix of finite numbers, got {values!r}")
    return rows


@dataclass(frozen=True)
class NodeCalibration:
    """A node's constants: magnetometer hard-iron offset h (LSB), soft-iron matrix C, mounting rotation.

    The defaults are the headset node's (IMU1) from hardware.md; ``NodeCalibration.uncalibrated()``
    is the sane default for other nodes (h = 0, C = I, no mounting rotation): the yaw filter only
    uses the direction of the field, so an uncalibrated C only costs heading accuracy.
    """

    hard_iron: Vector3 = HEADSET_HARD_IRON
    soft_iron: Matrix3 = HEADSET_SOFT_IRON
    mounting: Matrix3 = HEADSET_MOUNTING

    def __post_init__(self) -> None:
        object.__setattr__(self, "hard_iron", _as_vector(self.hard_iron, "hard_iron"))
        object.__setattr__(self, "soft_iron", _as_matrix(self.soft_iron, "soft_iron"))
        mounting = _as_matrix(self.mounting, "mounting")
        m = np.array(mounting)
        if not (np.allclose(m @ m.T, np.eye(3), atol=1e-6) and np.isclose(np.linalg.det(m), 1.0, atol=1e-6)):
            raise ValueError(f"mounting must be a rotation matrix (orthonormal, det +1), got {mounting!r}")
        object.__setattr__(self, "mounting", mounting)

    @classmethod
    def uncalibrated(cls) -> NodeCalibration:
        return cls(hard_iron=(0.0, 0.0, 0.0), soft_iron=IDENTITY, mounting=IDENTITY)

    @classmethod
    def default_for(cls, node: int) -> NodeCalibration:
        """Headset constants for node 1 (the headset IMU), uncalibrated for the others."""
        return cls() if node == 1 else cls.uncalibrated()


@dataclass
class NodeFusion:
    """Streaming fusion of one node; the filter states start at zero as on the original host."""

    calibration: NodeCalibration = field(default_factory=NodeCalibration)
    pitch_state: float = 0.0
    roll_state: float = 0.0
    yaw_state: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0

    def update(self, acc, gyro, mag) -> Vector3:
        """One sample of raw LSB (sensor axes) -> (pitch, roll, yaw) in degrees.

        The matrix products (soft iron, then the mounting rotation of acc, gyro and the corrected
        field) are written out term by term: this runs once per sample of every node."""
        cal = self.calibration
        (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = cal.soft_iron
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = cal.mounting
        h0, h1, h2 = cal.hard_iron
        x, y, z = mag[0] - h0, mag[1] - h1, -mag[2] - h2
        c0, c1, c2 = s00 * x + s01 * y + s02 * z, s10 * x + s11 * y + s12 * z, s20 * x + s21 * y + s22 * z
        x, y, z = acc[0], acc[1], acc[2]
        ax, ay, az = r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z
        x, y, z = gyro[0], gyro[1], gyro[2]
        gx, gy, gz = r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z
        m1, m2, m3 = r00 * c0 + r01 * c1 + r02 * c2, r10 * c0 + r11 * c1 + r12 * c2, r20 * c0 + r21 * c1 + r22 * c2
        step = _GYRO_STEP

        previous_pitch_state, previous_roll_state = self.pitch_state, self.roll_state
        self.pitch_state = pitch_state = (ACC_WEIGHT * degrees(atan2(-ay, -ax))
                                          + GYRO_WEIGHT * (previous_pitch_state - gz * step))
        self.roll_state = roll_state = (ACC_WEIGHT * degrees(atan2(-az, -ax))
                                        + GYRO_WEIGHT * (previous_roll_state + gy * step))
        self.pitch = pitch = LOWPASS_B * (pitch_state + previous_pitch_state) + LOWPASS_A * self.pitch
        self.roll = roll = LOWPASS_B * (roll_state + previous_roll_state) + LOWPASS_A * self.roll

        p, r = radians(-pitch), radians(roll)
        c_p, s_p, c_r, s_r = cos(p), sin(p), cos(r), sin(r)
        y_h = s_p * c_r * m1 + c_p * m2 + s_p * s_r * m3
        z_h = -s_r * m1 + c_r * m3
        self.yaw_state = yaw = (MAG_WEIGHT * degrees(atan2(-z_h, -y_h))
                                + (1.0 - MAG_WEIGHT) * (self.yaw_state + gx * step))
        return pitch, roll, yaw

    def update_many(self, acc: np.ndarray, gyro: np.ndarray, mag: np.ndarray) -> np.ndarray:
        """``update`` of n samples in a row, (n, 3) raw LSB each -> (n, 3) (pitch, roll, yaw); the
        state advances as n calls of ``update`` would advance it, to the bit.

        The same filter with the work split by kind: the products, sums and libm functions of every
        sample at once (numpy elementwise operations are the same IEEE operations in the same order;
        the transcendental functions are ``math``'s, mapped, as ``update`` calls them), and only the
        recursions (complementary filters, low-pass) as a loop over plain floats. A few samples
        (fewer than ARRAY_PASSES_FROM: a chunk of the stream) go through ``update`` one by one."""
        cal = self.calibration
        (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = cal.soft_iron
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = cal.mounting
        h0, h1, h2 = cal.hard_iron
        mag, acc, gyro = (np.asarray(v, dtype=float).reshape(-1, 3) for v in (mag, acc, gyro))
        if len(acc) < ARRAY_PASSES_FROM:
            return np.array([self.update(*sample) for sample in zip(acc.tolist(), gyro.tolist(), mag.tolist())],
                            dtype=float).reshape(-1, 3)
        x, y, z = mag[:, 0] - h0, mag[:, 1] - h1, -mag[:, 2] - h2
        c0, c1, c2 = s00 * x + s01 * y + s02 * z, s10 * x + s11 * y + s12 * z, s20 * x + s21 * y + s22 * z
        x, y, z = acc[:, 0], acc[:, 1], acc[:, 2]
        ax, ay, az = r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z
        x, y, z = gyro[:, 0], gyro[:, 1], gyro[:, 2]
        gx, gy, gz = r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z
        m1, m2, m3 = r00 * c0 + r01 * c1 + r02 * c2, r10 * c0 + r11 * c1 + r12 * c2, r20 * c0 + r21 * c1 + r22 * c2
        step = _GYRO_STEP

        tilt_pitch = (ACC_WEIGHT * _degrees_atan2(-ay, -ax)).tolist()
        tilt_roll = (ACC_WEIGHT * _degrees_atan2(-az, -ax)).tolist()
        turn_pitch, turn_roll = (gz * step).tolist(), (gy * step).tolist()
        pitch_state, roll_state, pitch, roll = self.pitch_state, self.roll_state, self.pitch, self.roll
        pitches, rolls = [], []
        for tp, tr, dp, dr in zip(tilt_pitch, tilt_roll, turn_pitch, turn_roll):
            previous_pitch_state, previous_roll_state = pitch_state, roll_state
            pitch_state = tp + GYRO_WEIGHT * (previous_pitch_state - dp)
            roll_state = tr + GYRO_WEIGHT * (previous_roll_state + dr)
            pitch = LOWPASS_B * (pitch_state + previous_pitch_state) + LOWPASS_A * pitch
            roll = LOWPASS_B * (roll_state + previous_roll_state) + LOWPASS_A * roll
            pitches.append(pitch)
            rolls.append(roll)
        self.pitch_state, self.roll_state, self.pitch, self.roll = pitch_state, roll_state, pitch, roll

        p = np.array(list(map(radians, map(float.__neg__, pitches))))
        r = np.array(list(map(radians, rolls)))
        c_p, s_p = np.array(list(map(cos, p.tolist()))), np.array(list(map(sin, p.tolist())))
        c_r, s_r = np.array(list(map(cos, r.tolist()))), np.array(list(map(sin, r.tolist())))
        y_h = s_p * c_r * m1 + c_p * m2 + s_p * s_r * m3
        z_h = -s_r * m1 + c_r * m3
        heading = (MAG_WEIGHT * _degrees_atan2(-z_h, -y_h)).tolist()
        turn_yaw = (gx * step).tolist()
        yaw, keep, yaws = self.yaw_state, 1.0 - MAG_WEIGHT, []
        for hd, dy in zip(heading, turn_yaw):
            yaw = hd + keep * (yaw + dy)
            yaws.append(yaw)
        self.yaw_state = yaw
        return np.column_stack([pitches, rolls, yaws]).reshape(-1, 3)


def _degrees_atan2(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """math.degrees(math.atan2(y, x)) of every element (libm's, as ``NodeFusion.update`` computes it)."""
    return np.array(list(map(degrees, map(atan2, y.tolist(), x.tolist()))), dtype=float)


def fuse(acc: np.ndarray, gyro: np.ndarray, mag: np.ndarray,
         cal: NodeCalibration | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batch fusion of a whole recording of one node: (n, 3) arrays -> pitch, roll, yaw arrays (n,)."""
    out = NodeFusion(cal or NodeCalibration()).update_many(acc, gyro, mag)
    return out[:, 0], out[:, 1], out[:, 2]


def neutral_offsets(angles: np.ndarray, samples: int = 100) -> np.ndarray:
    """Neutral-offset calibration: mean (pitch, roll, yaw) over the first ``samples`` rows of neutral posture."""
    return np.asarray(angles, dtype=float)[:samples].mean(axis=0)


@dataclass
class FusedRows:
    """Rows of frames (by node id) -> recording samples (by node index), each frame fused once."""

    calibrations: dict[int, NodeCalibration]  # by node index
    _fusion: dict[int, NodeFusion] = field(init=False, repr=False)
    _last: dict[int, tuple[ImuFrame, Vector3]] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        self._fusion = {imu_node_id(i): NodeFusion(cal) for i, cal in self.calibrations.items()}

    @property
    def node_ids(self) -> tuple[int, ...]:
        return tuple(self._fusion)

    def samples(self, row: dict[int, ImuFrame]) -> dict[int, NodeSample]:
        """The row's raw values and fused angles, keyed by node index."""
        return {imu_index(node_id): NodeSample(frame.acc, frame.gyro, frame.mag, self.angles(frame))
                for node_id, frame in row.items()}

    def angles(self, frame: ImuFrame) -> Vector3:
        """The frame's fused angles; fused once, when first asked (a row may hold a node's frame over
        a loss, and `bomi record` fuses frames one by one before they make rows)."""
        node_id = frame.node_id
        last = self._last.get(node_id)
        if last is None or last[0] is not frame:  # a held frame is not fused twice
            last = self._last[node_id] = (frame, self._fusion[node_id].update(frame.acc, frame.gyro, frame.mag))
        return last[1]


def fused_recording(rec: Recording, calibrations: dict[int, NodeCalibration]) -> Recording:
    """The recording with every node's angles recomputed from its raw ACC/GYRO/MAG columns."""
    nodes = {}
    for index, node in rec.nodes.items():
        pitch, roll, yaw = fuse(node.acc, node.gyro, node.mag, calibrations[index])
        nodes[index] = NodeData(acc=node.acc, gyro=node.gyro, mag=node.mag, angles=np.column_stack([pitch, roll, yaw]))
    return Recording(nodes=nodes, labels=rec.labels, time=rec.time, source=rec.source)
