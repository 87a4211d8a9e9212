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


@cache
def noise_scale(noise: SensorNoise) -> np.ndarray:
    """The (9,) noise standard deviations of a sample's acc, gyro and mag values (read-only)."""
    scale = np.repeat([noise.acc_lsb, noise.gyro_lsb, noise.mag_lsb], 3)
    scale.flags.writeable = False
    return scale


@dataclass(frozen=True)
class RawImu:
    """Raw int16 sensor counts in the sensor's own axes, each (n, 3)."""

    acc: np.ndarray
    gyro: np.ndarray
    mag: np.ndarray

    def __len__(self) -> int:
        return len(self.acc)


# scipy's Rotation computes a stack of rotations (input of three dimensions) on its vectorised
# array-API path and a plain list (two dimensions) on its compiled per-rotation path: the same
# quaternions, but vectors applied by summing in another order (round-off that,
# tests/test_imu_synth.py, does not reach a count). The compiled path costs about 1.3 us a rotation
# (scipy 1.17), the vectorised one a fixed ~0.2 ms a call: a calibration session (tens of thousands
# of rotations at once) takes the latter, a task's chunks the former.
STACKED_FROM = 2000


def euler_rotations(seq: str, angles: np.ndarray, degrees: bool = False) -> Rotation:
    """``Rotation.from_euler`` of (n, 3) angles; as a (1, n) stack when n >= STACKED_FROM (see there):
    index it with ``rotation_rows``, reshape what it returns (its arrays have the extra leading axis)."""
    angles = np.atleast_2d(angles)
    return Rotation.from_euler(seq, angles[None] if len(angles) >= STACKED_FROM else angles, degrees=degrees)


def rotation_rows(rotations: Rotation, rows: slice) -> Rotation:
    """``rotations[rows]`` of a plain list or of a ``euler_rotations`` stack alike (scipy's own
    indexing, a raw quaternion slice, for both)."""
    return Rotation(rotations.as_quat()[..., rows, :], normalize=False, copy=False)


def body_rotation(angles_deg: np.ndarray) -> Rotation:
    """Level-from-body rotations for (n, 3) fusion angles (pitch, roll, yaw) in degrees (``euler_rotations``)."""
    pitch, roll, yaw = np.radians(np.atleast_2d(angles_deg)).T
    pitch_euler = np.arctan(np.tan(pitch) * np.cos(roll))
    return euler_rotations("XZY", np.column_stack([yaw, -pitch_euler, roll]))


def magnetometer_reading(angles_deg: np.ndarray, field: EarthField = EarthField()) -> np.ndarray:
    """Magnetometer in body axes (raw LSB, undistorted) whose fusion heading is the given yaw, (n, 3).

    The fusion compensates tilt with Rz(-pitch) Ry(roll) and reads heading atan2(-zh, -yh), so
    the body field is Ry(-roll) Rz(pitch) Rx(yaw) applied to the zero-heading field.
    """
    pitch, roll, yaw = np.atleast_2d(angles_deg).T
    to_body = euler_rotations("YZX", np.column_stack([-roll, pitch, yaw]), degrees=True)
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
    rounded = np.rint(values)
    return np.clip(rounded, INT16_MIN, INT16_MAX, out=rounded).astype(np.int16)


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
    rotations = body_rotation(np.concatenate([first, angles]).reshape(-1, 3))    # row i * k + node
    now = rotation_rows(rotations, slice(k, None))
    acc_body = -now.apply([1.0, 0.0, 0.0], inverse=True).reshape(n, k, 3)   # (scipy: inv().apply's bits, one call)
    if linear_acc_g is not None:
        acc_body = acc_body + linear_acc_g
    rate = np.degrees((rotation_rows(rotations, slice(None, -k)).inv() * now).as_rotvec()).reshape(n, k, 3) / DT
    field_lsb = magnetometer_reading(angles.reshape(-1, 3), field).reshape(n, k, 3)
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
    counts = to_int16(clean + draws * noise_scale(noise))
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

    def rows(self, start: int, stop: int | None = None) -> Delivery:
        """Frames ``start:stop`` (in arrival order)."""
        rows = slice(start, stop)
        return Delivery(self.arrival_s[rows], self.node_index[rows], self.sample_index[rows], self.frames[rows])

    def until(self, t_end: float) -> tuple[Delivery, Delivery]:
        """Split into what has arrived by ``t_end`` and the rest."""
        k = int(np.searchsorted(self.arrival_s, t_end, side="right"))
        return self.rows(0, k), self.rows(k)


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
    n = len(sample_index)
    nodes_by_slot, ids_by_slot = _node_numbers(tuple(node for node, _ in by_node))
    draws = np.empty((len(by_node), n, 2))     # (nodes, n, 2), each node's row from its own generator
    # every node's samples as rows of one (nodes * n, 9) array (mag, gyro, acc): each frame's values in one gather
    values = np.empty((len(by_node), n, 9), dtype=np.int16)
    for slot, (node, raw) in enumerate(by_node):
        rngs[node].random(out=draws[slot])
        values[slot, :, 0:3], values[slot, :, 3:6], values[slot, :, 6:9] = raw.mag, raw.gyro, raw.acc
    sent = sample_time_s + link.latency_s - link.jitter_s * np.log1p(-draws[..., 1])   # exponential jitter
    kept = draws[..., 0] >= link.loss_fraction
    sent[~kept] = -np.inf                      # lost frames hold nothing up
    slots, rows = np.nonzero(kept)             # per frame: its node's slot and its sample's row
    arrival = np.ceil(np.maximum.accumulate(sent, axis=1)[slots, rows] / link.burst_s) * link.burst_s
    if not_before_s:
        arrival = np.maximum(arrival, np.array([not_before_s.get(node, -np.inf) for node, _ in by_node])[slots])
    nodes = nodes_by_slot[slots]
    indices = sample_index[rows].astype(int)
    order = np.lexsort((nodes, indices, arrival))
    slots, rows, indices = slots[order], rows[order], indices[order]
    values = values.reshape(-1, 9)[slots * n + rows]
    frames = encode_imu_frames(ids_by_slot[slots], indices % COUNTER_MODULO, values[:, 0:3], values[:, 3:6],
                               values[:, 6:9], period_ms)   # every node's frames in one pass, in arrival order
    return Delivery(arrival[order], nodes[order], indices, frames)


@cache
def _node_numbers(nodes: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(k,) node indices and their node ids on the wire, as arrays (read-only): ``deliver``'s per-slot lookups."""
    index, ids = np.array(nodes, dtype=int), np.array([imu_node_id(node) for node in nodes])
    index.flags.writeable = ids.flags.writeable = False
    return index, ids
