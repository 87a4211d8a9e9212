"""Per-node orientation fusion exactly as ../shared/docs/hardware.md section 3 describes it.

Magnetometer hard/soft-iron correction, mounting rotation, complementary filters on pitch and roll,
a 10 Hz low-pass on both, tilt-compensated complementary yaw. ``NodeFusion.update`` (one sample,
the stream) and ``NodeFusion.update_many`` (n samples in a row, a whole recording: ``fuse``) are the
same filter, one compiled kernel (``fuse_samples``), and agree bit for bit (tests/test_fusion.py).
Angles in degrees; inputs raw int16 LSB in the sensor's own axes.
"""
from __future__ import annotations

import itertools
import math
from math import atan2, cos, degrees, radians, sin
from dataclasses import dataclass, field, replace

import numpy as np

from bomi.compiled import kernel
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


@kernel
def fuse_samples(state: np.ndarray, constants: np.ndarray, acc: np.ndarray, gyro: np.ndarray, mag: np.ndarray,
                 out: np.ndarray) -> None:
    """The filter over n samples in a row: (n, 3) raw LSB each (float64) -> ``out`` (n, 3) (pitch,
    roll, yaw), advancing ``state`` (pitch_state, roll_state, yaw_state, pitch, roll) in place.
    ``constants``: hard iron (3), soft iron (9, row by row), mounting (9, row by row).

    hardware.md section 3 term by term: the matrix products (soft iron, then the mounting rotation
    of acc, gyro and the corrected field) written out, the complementary filters, the low-pass and
    the tilt-compensated yaw, on floats (a ``bomi.compiled.kernel``: one call a chunk of the stream
    or a whole recording, the same bits compiled or not)."""
    h0, h1, h2 = constants[0], constants[1], constants[2]
    s00, s01, s02, s10, s11, s12, s20, s21, s22 = constants[3], constants[4], constants[5], constants[6], \
        constants[7], constants[8], constants[9], constants[10], constants[11]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = constants[12], constants[13], constants[14], constants[15], \
        constants[16], constants[17], constants[18], constants[19], constants[20]
    pitch_state, roll_state, yaw_state, pitch, roll = state[0], state[1], state[2], state[3], state[4]
    step, keep = _GYRO_STEP, 1.0 - MAG_WEIGHT
    for i in range(acc.shape[0]):
        x, y, z = mag[i, 0] - h0, mag[i, 1] - h1, -mag[i, 2] - h2
        c0, c1, c2 = s00 * x + s01 * y + s02 * z, s10 * x + s11 * y + s12 * z, s20 * x + s21 * y + s22 * z
        x, y, z = acc[i, 0], acc[i, 1], acc[i, 2]
        ax, ay, az = r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z
        x, y, z = gyro[i, 0], gyro[i, 1], gyro[i, 2]
        gx, gy, gz = r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z
        m1, m2, m3 = r00 * c0 + r01 * c1 + r02 * c2, r10 * c0 + r11 * c1 + r12 * c2, r20 * c0 + r21 * c1 + r22 * c2

        previous_pitch_state, previous_roll_state = pitch_state, roll_state
        pitch_state = ACC_WEIGHT * degrees(atan2(-ay, -ax)) + GYRO_WEIGHT * (previous_pitch_state - gz * step)
        roll_state = ACC_WEIGHT * degrees(atan2(-az, -ax)) + GYRO_WEIGHT * (previous_roll_state + gy * step)
        pitch = LOWPASS_B * (pitch_state + previous_pitch_state) + LOWPASS_A * pitch
        roll = LOWPASS_B * (roll_state + previous_roll_state) + LOWPASS_A * roll

        p, r = radians(-pitch), radians(roll)
        c_p, s_p, c_r, s_r = cos(p), sin(p), cos(r), sin(r)
        y_h = s_p * c_r * m1 + c_p * m2 + s_p * s_r * m3
        z_h = -s_r * m1 + c_r * m3
        yaw_state = MAG_WEIGHT * degrees(atan2(-z_h, -y_h)) + keep * (yaw_state + gx * step)
        out[i, 0], out[i, 1], out[i, 2] = pitch, roll, yaw_state
    state[0], state[1], state[2], state[3], state[4] = pitch_state, roll_state, yaw_state, pitch, roll


@dataclass(eq=False)
class NodeFusion:
    """Streaming fusion of one node; the filter states start at zero as on the original host."""

    calibration: NodeCalibration = field(default_factory=NodeCalibration)
    # (pitch_state, roll_state, yaw_state, pitch, roll): what ``fuse_samples`` advances
    state: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        cal = self.calibration
        self._constants = np.array([*cal.hard_iron, *(v for row in cal.soft_iron for v in row),
                                    *(v for row in cal.mounting for v in row)], dtype=float)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, NodeFusion):
            return NotImplemented
        return self.calibration == other.calibration and self.state.tolist() == other.state.tolist()

    def update(self, acc, gyro, mag) -> Vector3:
        """One sample of raw LSB (sensor axes) -> (pitch, roll, yaw) in degrees."""
        raw = np.array((acc, gyro, mag), dtype=float)
        out = np.empty((1, 3))
        fuse_samples(self.state, self._constants, raw[0:1], raw[1:2], raw[2:3], out)
        pitch, roll, yaw = out[0].tolist()
        return pitch, roll, yaw

    def update_many(self, acc: np.ndarray, gyro: np.ndarray, mag: np.ndarray) -> np.ndarray:
        """``update`` of n samples in a row, (n, 3) raw LSB each -> (n, 3) (pitch, roll, yaw): one
        call of the filter over all of them."""
        acc, gyro, mag = (np.ascontiguousarray(v, dtype=float).reshape(-1, 3) for v in (acc, gyro, mag))
        out = np.empty((len(acc), 3))
        fuse_samples(self.state, self._constants, acc, gyro, mag, out)
        return out


def load_filter() -> None:
    """Run the filter once on a scratch state: its first call in a process imports numba and loads
    the compiled ``fuse_samples`` (~0.5 s), which a paced stream (``bomi live``) must not spend
    between two samples; afterwards a call costs microseconds."""
    NodeFusion().update((0, 0, -16384), (0, 0, 0), (100, 0, 0))


def fuse(acc: np.ndarray, gyro: np.ndarray, mag: np.ndarray,
         cal: NodeCalibration | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batch fusion of a whole recording of one node: (n, 3) arrays -> pitch, roll, yaw arrays (n,)."""
    out = NodeFusion(cal or NodeCalibration()).update_many(acc, gyro, mag)
    return out[:, 0], out[:, 1], out[:, 2]


def neutral_offsets(angles: np.ndarray, samples: int = 100) -> np.ndarray:
    """Neutral-offset calibration: mean (pitch, roll, yaw) over the first ``samples`` rows of neutral posture."""
    return np.asarray(angles, dtype=float)[:samples].mean(axis=0)


def sample_times(arrival: float, count: int, previous: float) -> list[float]:
    """Times of ``count`` rows read together at ``arrival``, one sample period apart, the last one at
    ``arrival`` and none before ``previous`` (the last row's time). Rows that come in a bunch because the
    host fell behind (a loaded machine, a pause of the interpreter) were sampled over that stall: timed by
    their arrival, a whole held posture could fall into the next prompt's segment and be labelled with it."""
    return [max(previous, arrival - (count - 1 - i) * DT) for i in range(count)]


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

    def restart(self, index: int) -> None:
        """Node ``index``'s filter started again (after a break in its stream: ``bomi.gate``)."""
        node_id = imu_node_id(index)
        self._fusion[node_id] = NodeFusion(self.calibrations[index])
        self._last.pop(node_id, None)


def fused_recording(rec: Recording, calibrations: dict[int, NodeCalibration]) -> Recording:
    """The recording with every node's angles recomputed from its raw ACC/GYRO/MAG columns."""
    nodes = {}
    for index, node in rec.nodes.items():
        pitch, roll, yaw = fuse(node.acc, node.gyro, node.mag, calibrations[index])
        nodes[index] = NodeData(acc=node.acc, gyro=node.gyro, mag=node.mag, angles=np.column_stack([pitch, roll, yaw]))
    return Recording(nodes=nodes, labels=rec.labels, time=rec.time, source=rec.source)



MOUNTING_AGREE_DEG = 10.0   # fused pitch or roll further than this (median over the rows) from the file's own: a warning


def angle_disagreement(own: np.ndarray, fused: np.ndarray) -> np.ndarray:
    """Median absolute difference of pitch and roll (degrees, wrapped to +-180) between two (n, 3)
    angle series. Yaw is left out: the recorded heading is not the host fusion's (dataset README)."""
    diff = (np.asarray(fused)[:, :2] - np.asarray(own)[:, :2] + 180.0) % 360.0 - 180.0
    return np.median(np.abs(diff), axis=0)


def axis_mountings() -> list[Matrix3]:
    """The 24 rotations that map the sensor's axes onto the body's axes (signed permutations, det +1)."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[range(3), perm] = signs
            if np.linalg.det(m) > 0:
                out.append(tuple(tuple(float(v) for v in row) for row in m))
    return out


def agreeing_mounting(node: NodeData, calibration: NodeCalibration) -> tuple[Matrix3, np.ndarray]:
    """The mounting (with ``calibration``'s iron constants) whose fused pitch and roll agree with the
    node's own angle columns, and its ``angle_disagreement``: the first within MOUNTING_AGREE_DEG of
    ``calibration``'s, none (the sensor's own axes), then the other ``axis_mountings`` (pitch and roll
    of a node that mostly stays upright can agree under several), else the nearest."""
    def disagreement(mounting: Matrix3) -> np.ndarray:
        pitch, roll, yaw = fuse(node.acc, node.gyro, node.mag, replace(calibration, mounting=mounting))
        return angle_disagreement(node.angles, np.column_stack([pitch, roll, yaw]))
    candidates = list(dict.fromkeys([calibration.mounting, IDENTITY, *axis_mountings()]))
    scored = []
    for mounting in candidates:
        left = disagreement(mounting)
        if left.max() <= MOUNTING_AGREE_DEG:
            return mounting, left
        scored.append((float(left.max()), mounting, left))
    _, best, left = min(scored, key=lambda entry: entry[0])
    return best, left


def mounting_warnings(rec: Recording, fused: Recording, calibrations: dict[int, NodeCalibration]) -> list[str]:
    """One warning per node whose fused pitch or roll disagree with the angle columns ``rec`` already
    holds by more than MOUNTING_AGREE_DEG (the mounting the fusion assumed is not the one the logger
    used), offering the axis mounting that agrees when one does."""
    lines = []
    for index, node in rec.nodes.items():
        if node.angles is None:
            continue
        pitch, roll = angle_disagreement(node.angles, fused.nodes[index].angles)
        if max(pitch, roll) <= MOUNTING_AGREE_DEG:
            continue
        line = (f"warning: {rec.source}: node {index}: the fused angles differ from the file's own angle columns by "
                f"a median {pitch:.1f} deg of pitch and {roll:.1f} deg of roll (more than {MOUNTING_AGREE_DEG:g}): "
                f"the mounting assumed ({_matrix_text(calibrations[index].mounting)}) is not the one the logger used")
        mounting, left = agreeing_mounting(node, calibrations[index])
        if left.max() <= MOUNTING_AGREE_DEG:
            line += (f"; mounting = {_matrix_text(mounting)} agrees (median {left[0]:.1f} / {left[1]:.1f} deg): "
                     "put it in the node's [nodes.calibration] of the profile")
        lines.append(line)
    return lines


def _matrix_text(m: Matrix3) -> str:
    return "[" + ", ".join("[" + ", ".join(f"{v:g}" for v in row) + "]" for row in m) + "]"
