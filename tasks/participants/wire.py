"""A virtual participant on the wire: the raw samples ``bomi emulate --participant`` plays, the
participant following the cues of ``bomi record``'s calibration protocol (no arm, no live loop).

The stream starts the way a real node's does: the samples are the sensors' from the first one,
and the receiver's orientation filter starts from its zero state. A person sits facing some
compass heading, which the magnetometer sees: every node's yaw carries the participant's heading
(``heading_deg``; by default drawn from the seed, uniform in +-``MAX_HEADING_DEG``), so the
filter's warm-up transient is as large as a real person's (yaw starts at 0 and decays towards the
heading with the filter's 1.6 s time constant; P1's fitted angles alone are within 7 deg of zero,
which hid it). The range stops short of +-180 deg: there the magnetometer heading wraps between
+180 and -180 and the host filter (hardware.md step 5) averages across the wrap, a limitation of
the documented host, not of a person.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import replace

import numpy as np

from bomi.classifier import NEUTRAL_LABEL
from bomi.frames import FrameParser
from bomi.fusion import DT, NodeFusion
from bomi.gate import Gate
from bomi.profiles import Profile
from bomi.protocol import Cue
from tasks.participants.imu_synth import Delivery, LinkModel
from tasks.participants.participant import ParticipantParams, VirtualParticipant

LOSSLESS_LINK = LinkModel(loss_fraction=0.0)  # the emulator applies its own --loss
MAX_HEADING_DEG = 150.0
_HEADING_STREAM = 0x4845   # a seed stream of its own for the heading ("HE"): the participant's other draws are unchanged


def session_heading(seed: int) -> float:
    """The compass heading (deg) a participant of ``seed`` sits facing."""
    return float(np.random.default_rng([_HEADING_STREAM, seed]).uniform(-MAX_HEADING_DEG, MAX_HEADING_DEG))


def facing(params: ParticipantParams, heading_deg: float) -> ParticipantParams:
    """The participant turned to ``heading_deg``: every node's yaw, neutral and class postures alike
    (class postures are changes from the neutral one), moves by the heading."""
    posture = params.neutral.posture_deg.copy()
    posture[:, 2] += heading_deg
    return replace(params, neutral=replace(params.neutral, posture_deg=posture))


def participant_blocks(params: ParticipantParams, profile: Profile, seed: int, cues: Sequence[Cue],
                       end_s: float, block_s: float = 1.0,
                       heading_deg: float | None = None) -> Iterator[dict[int, np.ndarray]]:
    """Raw samples (per node index, (m, 9) mag, gyro, acc) of a virtual participant following ``cues``,
    made ``block_s`` at a time up to ``end_s``. At each cue's start the participant takes up its class
    (full amplitude; after its reaction time), as someone following ``bomi record``'s prompts.
    ``heading_deg``: where they sit facing (default ``session_heading(seed)``; module docstring)."""
    heading = session_heading(seed) if heading_deg is None else heading_deg
    vp = VirtualParticipant(facing(params, heading), profile, seed, link=LOSSLESS_LINK)
    pending = [cue for cue in cues if cue.start_s < end_s]
    t = 0.0
    while t < end_s:
        t = min(t + block_s, end_s)
        parts = []
        while pending and pending[0].start_s <= t:
            cue = pending.pop(0)
            parts.append(vp.deliveries(cue.start_s))
            vp.set_intent(cue.label, 0.0 if cue.label == NEUTRAL_LABEL else 1.0, cue.start_s)
        parts += [vp.deliveries(t), vp.flush()]
        yield raw_block(parts)


def settled_after(params: ParticipantParams, profile: Profile, seed: int, limit_s: float = 60.0) -> float:
    """Seconds of held neutral after which a receiver's gate (``bomi.gate``, as in `bomi record` and
    `bomi live`) trusts every node of this participant's stream: each node fused from its first sample,
    as the receiver's filter is. What a person told to hold still does before the protocol starts.
    ``limit_s`` if the gate never opens within it."""
    gate = Gate(profile.node_indices)
    fusion = {node.index: NodeFusion(node.calibration) for node in profile.nodes}
    neutral = [Cue(NEUTRAL_LABEL, "neutral", 0.0, limit_s)]
    n = 0
    for block in participant_blocks(params, profile, seed, neutral, limit_s):
        for k in range(len(block[profile.node_indices[0]])):
            n += 1
            for index, node_gate in gate.node.items():
                mag, gyro, acc = block[index][k, 0:3], block[index][k, 3:6], block[index][k, 6:9]
                node_gate.count(n % 256)       # one sender, in step: never a break
                if node_gate.check_raw(mag, gyro, acc):
                    node_gate.fused(fusion[index].update(acc, gyro, mag))
            if gate.settled:
                return n * DT
    return limit_s


def delayed(cues: Sequence[Cue], lead_s: float) -> list[Cue]:
    """``cues`` with the first (neutral) one ``lead_s`` longer and the others ``lead_s`` later."""
    return [replace(cue, start_s=cue.start_s + lead_s if k else cue.start_s, end_s=cue.end_s + lead_s)
            for k, cue in enumerate(cues)]


def raw_block(deliveries: Sequence[Delivery]) -> dict[int, np.ndarray]:
    """Decode lossless deliveries into per-node raw rows (mag, gyro, acc) in sample order."""
    frames = FrameParser().feed(b"".join(d.stream() for d in deliveries))
    values = np.array([frame.mag + frame.gyro + frame.acc for frame in frames], dtype=np.int64).reshape(-1, 9)
    node_index = np.concatenate([d.node_index for d in deliveries])
    sample_index = np.concatenate([d.sample_index for d in deliveries])
    block = {}
    for node in np.unique(node_index).tolist():
        mine = np.flatnonzero(node_index == node)
        block[node] = values[mine[np.argsort(sample_index[mine], kind="stable")]]
    return block
