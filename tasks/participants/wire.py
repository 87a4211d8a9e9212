"""A virtual participant on the wire: the raw samples ``bomi emulate --participant`` plays, the
participant following the cues of ``bomi record``'s calibration protocol (no arm, no live loop)."""
from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from bomi.classifier import NEUTRAL_LABEL
from bomi.frames import FrameParser
from bomi.profiles import Profile
from bomi.protocol import Cue
from tasks.participants.imu_synth import Delivery, LinkModel
from tasks.participants.participant import ParticipantParams, VirtualParticipant

LOSSLESS_LINK = LinkModel(loss_fraction=0.0)  # the emulator applies its own --loss


def participant_blocks(params: ParticipantParams, profile: Profile, seed: int, cues: Sequence[Cue],
                       end_s: float, block_s: float = 1.0) -> Iterator[dict[int, np.ndarray]]:
    """Raw samples (per node index, (m, 9) mag, gyro, acc) of a virtual participant following ``cues``,
    made ``block_s`` at a time up to ``end_s``. At each cue's start the participant takes up its class
    (full amplitude; after its reaction time), as someone following ``bomi record``'s prompts."""
    vp = VirtualParticipant(params, profile, seed, link=LOSSLESS_LINK)
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
