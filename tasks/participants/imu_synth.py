"""What a real IMU node would send for a given orientation trajectory, and the base-station bytes.

Array in, array out. The orientation of a node is given as the angles the host fusion
(``bomi.fusion``, ../shared/docs/hardware.md section 3) defines, in degrees per sample:

- pitch = atan2(-ay, -ax) and roll = atan2(-az, -ax) of the gravity reading in the mounted
  ("body") axes: body x points down at zero tilt;
- yaw = the tilt-compensated magnetometer heading atan2(-zh, -yh) of the fusion.

The body rotation (level frame -> body) used for gravity and the gyroscope is
``Rx(yaw) Rz(-pitch') Ry(roll)`` with ``tan(pitch') = tan(pitch) cos(roll)``, which makes the two
accelerometer angles exactly ``pitch`` and ``roll`` and gives, at small angles, the fusion's rate
conventions (pitch rate = -gz, roll rate = +gy, yaw rate = +gx). The magnetometer reads the earth
field that the fusion's heading formula turns into ``yaw`` (see docs/virtual_participant.md for
why that is not the field of a right-handed sensor under the same rotation). Every vector is then
taken back to the sensor's own axes (inverse mounting), the magnetometer is distorted by the
inverse of the node's hard/soft-iron correction, noise is added and values are rounded to int16.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache

import numpy as np
from scipy.spatial.transform import Rotation

from bomi.frames import COUNTER_MODULO, DEFAULT_PERIOD_MS, encode_imu_frames, imu_node_id
from bomi.fusion import DT, GYRO_DEG_PER_LSB, NodeCalibration

ACC_LSB_PER_G = 1000.0 / 0.061          # LSM9DS0 at +-2 g: 0.061 mg/LSB
GYRO_LSB_PER_DEG_S = 1.0 / GYRO_DEG_PER_LSB
INT16_MIN, INT16_MAX = -32768, 32767


@dataclass(frozen=True)
class EarthField:
    """The earth magnetic field as the magnetometer sees it.

    ``strength_lsb`` is its magnitude in raw LSB (about 5,000 for the headset node: its
    soft-iron matrix maps that to |m| = 0.8, the size seen in the real data); the default
    inclination of 70 deg is southern Quebec's, where the dataset was recorded.
    """

    strength_lsb: float = 5000.0
    inclination_deg: float = 70.0

    def at_zero_heading(self) -> np.ndarray:
        """The field in level axes (x down) at heading 0, in raw LSB."""
        dip = np.radians(self.inclination_deg)
        return self.strength_lsb * np.array([np.sin(dip), -np.cos(dip), 0.0])


@dataclass(frozen=True)
class NodeArrays:
    """k nodes' calibrations as the synthesis uses them, stacked node by node: (k, 3, 3) ``mounting``
    and ``soft_iron``, (k, 3) ``hard_iron``, and (k,) ``units``: raw LSB -> each node's corrected
    magnetometer units, its soft-iron matrix's mean gain (cube-root determinant). Made once per set of
    calibrations (``node_arrays``: every chunk of the stream asks for them)."""

    mounting: np.ndarray
    soft_iron: np.ndarray
    hard_iron: np.ndarray
    units: np.ndarray


@cache
def node_arrays(cals: tuple[NodeCalibration, ...]) -> NodeArrays:
    mounting, soft_iron, hard_iron = (np.array([getattr(cal, name) for cal in cals], dtype=float)
                                      for name in ("mounting", "soft_iron", "hard_iron"))
    units = np.array([float(np.cbrt(abs(np.linalg.det(matrix)))) for matrix in soft_iron])
    for array in (mounting, soft_iron, hard_iron, units):
        array.flags.writeable = False
    return NodeArrays(mounting, soft_iron, hard_iron, units)


@dataclass(frozen=True)
class SensorNoise:
    """White noise standard deviations, in LSB of each sensor (assumptions, see the docs)."""

    acc_lsb: float = 20.0
    gyro_lsb: float = 4.0
    mag_lsb: float = 25.0


@dataclass(frozen=True)
class RawImu:
    """Raw int16 sensor counts in the sensor's own axes, each (n, 3)."""

    acc: np.ndarray
    gyro: np.ndarray
    mag: np.ndarray

    def __len__(self) -> int:
        return len(self.acc)


# scipy's Rotation applies a vector to a stack of rotations (input of three dimensions) on its
# vectorised array-API path and to a plain list (two dimensions) on its compiled per-rotation path,
# summing the products in another order (round-off that, tests/test_imu_synth.py, does not reach a
# count). A calibration session (tens of thousands of rotations at once) takes the former, as it
# always has (the former's from_euler was the cheaper one for it), a task's chunks the latter (the
# former costs a fixed ~0.2 ms a call): kept so, every sample is the one it always was.
STACKED_FROM = 2000


# The quaternion arithmetic of scipy's Rotation (scalar last) that the synthesis uses, by the numpy
# operations of its vectorised path (scipy.spatial.transform._rotation_xp: from_euler's elementary
# compose, compose_quat, the normalisation of a product, inv, as_rotvec) in the same order: the same
# bits as either of scipy's paths (tests/test_imu_synth.py compares them on random rotations), on a
# whole chunk in a few array operations, not per rotation or through the array API's dispatch. A
# quaternion is taken apart into its components (x, y, z, w), each an (n,) array or, where scipy's
# component is a constant 0, the float 0.0: the same IEEE operations on fewer elements.
_AXIS = {"X": 0, "Y": 1, "Z": 2}
Components = tuple   # (x, y, z, w): each an (n,) array or a float


def compose_quats(p: Components, q: Components) -> Components:
    """Components of the rotations p then q (scipy's ``compose_quat``, not normalised)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    cross = (p1 * q2 - p2 * q1, p2 * q0 - p0 * q2, p0 * q1 - p1 * q0)   # numpy.cross, term by term
    return (p3 * q0 + q3 * p0 + cross[0], p3 * q1 + q3 * p1 + cross[1], p3 * q2 + q3 * p2 + cross[2],
            p3 * q3 - p0 * q0 - p1 * q1 - p2 * q2)


def euler_quats(seq: str, angles: np.ndarray, degrees: bool = False) -> np.ndarray:
    """``Rotation.from_euler(seq, angles, degrees).as_quat()`` of (n, 3) angles, ``seq`` intrinsic (upper case)."""
    angles = np.atleast_2d(np.asarray(angles, dtype=float))
    if degrees:
        angles = angles * (np.pi / 180.0)
    quat = None
    for column, axis in enumerate(seq):
        half = angles[:, column] / 2.0
        elementary = [0.0, 0.0, 0.0, np.cos(half)]
        elementary[_AXIS[axis]] = np.sin(half)
        quat = elementary if quat is None else compose_quats(quat, elementary)
    return np.stack(quat, axis=-1)


def inverse_quats(quat: np.ndarray) -> np.ndarray:
    """Quaternions of the inverse rotations (scipy's ``inv``)."""
    out = quat.copy()
    out[..., :3] *= -1
    return out


def relative_rotvecs(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """``(Rotation(before).inv() * Rotation(after)).as_rotvec()`` of two (n, 4) quaternion arrays (radians)."""
    quat = np.stack(compose_quats(tuple(inverse_quats(before).T), tuple(after.T)), axis=-1)
    quat = quat / np.linalg.norm(quat, ord=2, axis=-1, keepdims=True)     # the product's normalisation
    flip = quat[..., 3] < 0                                                # as_rotvec's canonical sign
    zero_w = quat[..., 3] == 0
    flip = flip | (zero_w & (quat[..., 0] < 0))
    zero_wx = zero_w & (quat[..., 0] == 0)
    flip = flip | (zero_wx & (quat[..., 1] < 0))
    zero_wxy = zero_wx & (quat[..., 1] == 0)
    flip = flip | (zero_wxy & (quat[..., 2] < 0))
    quat = np.where(flip[..., None], -quat, quat)
    ax_norm = np.linalg.norm(quat[..., :3], ord=2, axis=-1, keepdims=True)
    angle = 2 * np.arctan2(ax_norm, quat[..., 3][..., None])
    small_angle = angle <= 1e-3
    angle2 = angle ** 2
    small_scale = 2 + angle2 / 12 + 7 * angle2 ** 2 / 2880
    large_scale = angle / (np.sin(angle / 2.0) + small_angle.astype(angle.dtype))
    return np.where(small_angle, small_scale, large_scale) * quat[..., :3]


def rotations(quat: np.ndarray) -> Rotation:
    """scipy Rotations of (n, 4) quaternions (to apply to vectors), as a (1, n) stack when n >=
    STACKED_FROM (see there): reshape what they return (its arrays have the extra leading axis)."""
    return Rotation(quat[None] if len(quat) >= STACKED_FROM else quat, normalize=False, copy=False)


def body_quats(angles_deg: np.ndarray) -> np.ndarray:
    """Level-from-body rotations (quaternions, (n, 4)) for (n, 3) fusion angles (pitch, roll, yaw) in degrees."""
    pitch, roll, yaw = np.radians(np.atleast_2d(angles_deg)).T
    pitch_euler = np.arctan(np.tan(pitch) * np.cos(roll))
    return euler_quats("XZY", np.column_stack([yaw, -pitch_euler, roll]))


def magnetometer_reading(angles_deg: np.ndarray, field: EarthField = EarthField()) -> np.ndarray:
    """Magnetometer in body axes (raw LSB, undistorted) whose fusion heading is the given yaw, (n, 3).

    The fusion compensates tilt with Rz(-pitch) Ry(roll) and reads heading atan2(-zh, -yh), so
    the body field is Ry(-roll) Rz(pitch) Rx(yaw) applied to the zero-heading field.
    """
    pitch, roll, yaw = np.atleast_2d(angles_deg).T
    to_body = rotations(euler_quats("YZX", np.column_stack([-roll, pitch, yaw]), degrees=True))
    return to_body.apply(field.at_zero_heading()).reshape(-1, 3)


# Each node's products below are numpy's for that node alone: a stack of matrices goes through the same
# BLAS (matmul) or LAPACK (solve) call per node as one matrix does.
def to_sensor_axes(body_vectors: np.ndarray, arrays: NodeArrays) -> np.ndarray:
    """Undo each node's mounting rotation (body = mounting @ sensor) for its (n, 3) row vectors, (k, n, 3)."""
    return np.asarray(body_vectors, dtype=float) @ arrays.mounting


def distort_magnetometer(corrected_sensor: np.ndarray, arrays: NodeArrays) -> np.ndarray:
    """Raw magnetometer LSB whose correction m = C (mx - h0, my - h1, -mz - h2) gives each node's
    ``corrected_sensor``, (k, n, 3)."""
    uncorrected = np.linalg.solve(arrays.soft_iron, np.asarray(corrected_sensor, float).transpose(0, 2, 1))
    raw = uncorrected.transpose(0, 2, 1) + arrays.hard_iron[:, None]
    raw[..., 2] *= -1.0
    return raw


def to_int16(values: np.ndarray) -> np.ndarray:
    """Round and saturate to the sensor's signed 16-bit range."""
    return np.clip(np.rint(values), INT16_MIN, INT16_MAX).astype(np.int16)


def synthesize_nodes(angles_deg: np.ndarray, cals: Sequence[NodeCalibration], rngs: Sequence[np.random.Generator],
                     noise: SensorNoise = SensorNoise(), field: EarthField = EarthField(),
                     previous_deg: np.ndarray | None = None,
                     linear_acc_g: np.ndarray | None = None) -> list[RawImu]:
    """Raw int16 acc/gyro/mag (sensor axes) of k nodes from their (n, k, 3) fusion angles in degrees.

    Accelerometer: gravity's reaction (+ the optional (n, k, 3) body-axis ``linear_acc_g``).
    Gyroscope: the body angular velocity over each sample interval (backward difference);
    ``previous_deg`` (k, 3) is the orientation one sample before the first row (streaming),
    without it the first rate is zero. Magnetometer: see ``magnetometer_reading``, then the
    node's distortion. All nodes share one set of rotations (the costly part). Each node's
    noise comes from its own generator, sample by sample, so a trajectory cut into pieces gets
    the same noise as in one piece.
    """
    angles = np.asarray(angles_deg, dtype=float)
    n, k, _ = angles.shape
    first = angles[:1] if previous_deg is None else np.asarray(previous_deg, dtype=float).reshape(1, k, 3)
    quats = body_quats(np.concatenate([first, angles]).reshape(-1, 3))    # row i * k + node
    now = quats[k:]
    acc_body = -rotations(inverse_quats(now)).apply([1.0, 0.0, 0.0]).reshape(n, k, 3)
    if linear_acc_g is not None:
        acc_body = acc_body + linear_acc_g
    rate = np.degrees(relative_rotvecs(quats[:-k], now)).reshape(n, k, 3) / DT
    field_lsb = magnetometer_reading(angles.reshape(-1, 3), field).reshape(n, k, 3)
    scale = np.repeat([noise.acc_lsb, noise.gyro_lsb, noise.mag_lsb], 3)
    if not len(cals) == len(rngs) == k:
        raise ValueError(f"angles of {k} nodes, {len(cals)} calibrations and {len(rngs)} generators")
    arrays = node_arrays(tuple(cals))
    clean, draws = np.empty((2, k, n, 9))   # per node: acc, gyro, mag in sensor axes, and the noise
    clean[..., 0:3] = to_sensor_axes(acc_body.transpose(1, 0, 2), arrays)
    clean[..., 3:6] = to_sensor_axes(rate.transpose(1, 0, 2), arrays)
    field_sensor = to_sensor_axes((field_lsb * arrays.units[:, None]).transpose(1, 0, 2), arrays)
    clean[..., 6:9] = distort_magnetometer(field_sensor, arrays)
    for node, rng in enumerate(rngs):
        draws[node] = rng.standard_normal((n, 9))
    clean[..., 0:3] *= ACC_LSB_PER_G
    clean[..., 3:6] *= GYRO_LSB_PER_DEG_S
    counts = to_int16(clean + draws * scale)
    return [RawImu(acc=c[:, 0:3], gyro=c[:, 3:6], mag=c[:, 6:9]) for c in counts]


def synthesize_raw(angles_deg: np.ndarray, cal: NodeCalibration, rng: np.random.Generator,
                   noise: SensorNoise = SensorNoise(), field: EarthField = EarthField(),
                   previous_deg: Sequence[float] | None = None) -> RawImu:
    """One node: raw int16 acc/gyro/mag (sensor axes) for an (n, 3) trajectory of fusion angles."""
    angles = np.atleast_2d(np.asarray(angles_deg, dtype=float))[:, None]
    previous = None if previous_deg is None else np.reshape(previous_deg, (1, 3))
    return synthesize_nodes(angles, [cal], [rng], noise, field, previous)[0]


@dataclass(frozen=True)
class LinkModel:
    """Radio/USB link between the nodes and the host: frame loss and bursty delivery.

    Each frame is lost with probability ``loss_fraction`` (its counter still advances). A
    surviving frame reaches the base station after ``latency_s`` plus an exponential jitter
    of mean ``jitter_s``; the base station forwards what it holds every ``burst_s``, so frames
    arrive in bursts. Frames of one node never overtake each other.
    """

    loss_fraction: float = 0.09
    latency_s: float = 0.004
    jitter_s: float = 0.006
    burst_s: float = 0.032


@dataclass(frozen=True)
class Delivery:
    """Frames as they reach the host, in arrival order (all arrays (m,))."""

    arrival_s: np.ndarray
    node_index: np.ndarray      # 1-based IMU index (1 = headset, node id 10)
    sample_index: np.ndarray    # index of the sample on the node's clock
    frames: list[bytes]

    def stream(self) -> bytes:
        return b"".join(self.frames)

    def until(self, t_end: float) -> tuple[Delivery, Delivery]:
        """Split into what has arrived by ``t_end`` and the rest."""
        k = int(np.searchsorted(self.arrival_s, t_end, side="right"))
        return (Delivery(self.arrival_s[:k], self.node_index[:k], self.sample_index[:k], self.frames[:k]),
                Delivery(self.arrival_s[k:], self.node_index[k:], self.sample_index[k:], self.frames[k:]))


def deliver(raw_by_node: dict[int, RawImu], sample_index: np.ndarray, sample_time_s: np.ndarray,
            rngs: Mapping[int, np.random.Generator], link: LinkModel = LinkModel(),
            not_before_s: Mapping[int, float] | None = None,
            period_ms: int = DEFAULT_PERIOD_MS) -> Delivery:
    """Encode each node's samples as 32-byte frames, drop ~``loss_fraction`` of them, interleave by arrival.

    ``sample_index`` (n,) numbers the samples on the nodes' clock (it also gives the packet
    counter, modulo 256); ``sample_time_s`` (n,) is when they were taken. ``rngs`` holds one
    generator per node, drawn sample by sample (so samples cut into pieces fare as in one piece).
    ``not_before_s`` gives per node the arrival time of its last frame of an earlier call.
    """
    sample_index = np.asarray(sample_index)
    by_node = sorted(raw_by_node.items())
    draws = np.stack([rngs[node].random((len(raw), 2)) for node, raw in by_node])     # (nodes, n, 2)
    sent = sample_time_s + link.latency_s - link.jitter_s * np.log1p(-draws[..., 1])   # exponential jitter
    kept = draws[..., 0] >= link.loss_fraction
    sent[~kept] = -np.inf                      # lost frames hold nothing up
    slots, rows = np.nonzero(kept)             # per frame: its node's slot and its sample's row
    arrival = np.ceil(np.maximum.accumulate(sent, axis=1)[slots, rows] / link.burst_s) * link.burst_s
    times = np.maximum(arrival, np.array([(not_before_s or {}).get(node, -np.inf) for node, _ in by_node])[slots])
    nodes = np.array([node for node, _ in by_node], dtype=int)[slots]
    indices = sample_index[rows].astype(int)
    order = np.lexsort((nodes, indices, times))
    slots, rows, indices = slots[order], rows[order], indices[order]
    node_ids = np.array([imu_node_id(node) for node, _ in by_node])[slots]
    values = {name: np.stack([getattr(raw, name) for _, raw in by_node])[slots, rows] for name in ("mag", "gyro", "acc")}
    frames = encode_imu_frames(node_ids, indices % COUNTER_MODULO, values["mag"], values["gyro"], values["acc"],
                               period_ms)   # every node's frames in one pass, in arrival order
    return Delivery(times[order], nodes[order], indices, frames)
