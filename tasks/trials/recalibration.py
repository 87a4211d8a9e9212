"""Recalibration in the live loop: the person performs the calibration protocol once, the arm at rest,
and the classifier is retrained on it (``tasks.trials.person.LivePerson``).

Asked by the person (``bomi.gate.LongPressGesture``): a button class held for the profile's
``recalibrate_hold_s`` (8 s), then rest. From that tick the protocol of ``bomi record`` runs once
(``bomi.protocol.calibration_schedule``, one repetition: neutral, then every motion class held
``HOLD_S`` with ``NEUTRAL_S`` of neutral after it), its cue shown as what holds the arm. The rows are
recorded as ``bomi record`` records them (``RowAssembler`` pairs the nodes' frames, each frame's
angles those the live loop's own settled filters gave it; each row labelled by the cue on screen when
its sample arrived: ``bomi.fusion.sample_times``). Once the last cue ends the model is trained with the
``bomi train`` code (``bomi.chain.train``: the current model's features and post-processing, the
moves told from the holds as for any continuous recording) and takes the chain's place, with the
recording's neutral. A recording that cannot be trained on (a class never held, a dead sensor)
leaves the old model in place, and says why.

Everything is a function of the ticks' inputs: a replay of the session's bytes asks for the same
recalibration on the same tick, records the same rows and trains the same model.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from bomi.chain import OnlineChain, recording_neutral, train
from bomi.classifier import Model
from bomi.errors import BomiError
from bomi.frames import ImuFrame, RowAssembler
from bomi.fusion import sample_times
from bomi.profiles import Profile
from bomi.protocol import Cue, calibration_schedule
from bomi.recording import NodeData, NodeSample, Recording

HOLD_S = 5.0      # each motion class held (bomi record's default)
NEUTRAL_S = 5.0   # neutral after each (bomi record's default)


@dataclass(eq=False)
class FusedFrame:
    """A frame and the angles the live loop's filter gave it (``RowAssembler`` pairs them by node)."""

    frame: ImuFrame
    angles: tuple[float, float, float]

    @property
    def node_id(self) -> int:
        return self.frame.node_id

    def sample(self) -> NodeSample:
        return NodeSample(self.frame.acc, self.frame.gyro, self.frame.mag, self.angles)


@dataclass
class Recalibration:
    """One calibration protocol performed during a live session, started at loop time ``start``."""

    profile: Profile
    model: Model            # the model it replaces (its features and post-processing are kept)
    start: float
    cues: tuple[Cue, ...]
    _index: dict[int, int] = field(init=False, repr=False)   # base-station node id -> index, the model's nodes
    _assembler: RowAssembler = field(init=False, repr=False)
    _fused: list[FusedFrame] = field(default_factory=list, repr=False)   # this tick's, not yet in rows
    _times: list[float] = field(default_factory=list, repr=False)
    _samples: list[dict[int, NodeSample]] = field(default_factory=list, repr=False)

    def __post_init__(self) -> None:   # the model's nodes: those the live loop fuses
        ids = {node.index: node.node_id for node in self.profile.nodes}
        self._index = {ids[index]: index for index in self.model.spec.nodes}
        self._assembler = RowAssembler(tuple(self._index))

    @classmethod
    def begin(cls, profile: Profile, model: Model, start: float) -> Recalibration:
        cues = calibration_schedule(profile, repetitions=1, hold_s=HOLD_S, neutral_s=NEUTRAL_S)
        return cls(profile, model, start, tuple(cues))

    @property
    def end(self) -> float:
        return self.start + self.cues[-1].end_s

    def over(self, now: float) -> bool:
        return now >= self.end - 1e-9

    def cue(self, now: float) -> Cue:
        """The cue on screen at loop time ``now`` (the last one once the protocol is over)."""
        t = now - self.start
        return next((cue for cue in self.cues if t < cue.end_s), self.cues[-1])

    def hold_text(self, now: float) -> str:
        """What holds the arm meanwhile: the cue, and how long it lasts."""
        cue = self.cue(now)
        return f"recalibrating ({cue.prompt}, {max(0.0, self.start + cue.end_s - now):.0f} s left)"

    def fused(self, frame: ImuFrame, angles: Sequence[float]) -> None:
        """A frame the live loop fused (arrival order), with its angles."""
        self._fused.append(FusedFrame(frame, tuple(float(a) for a in angles)))

    def take(self, now: float) -> None:
        """The tick's fused frames at ``now``: their complete rows, each timed."""
        rows = [row for row in map(self._assembler.push, self._fused) if row is not None]
        self._fused.clear()
        previous = self._times[-1] if self._times else now
        for t, row in zip(sample_times(now, len(rows), previous), rows):
            self._times.append(t)
            self._samples.append({self._index[node_id]: fused.sample() for node_id, fused in row.items()})

    def recording(self) -> Recording:
        """The protocol's rows, each labelled with the cue of its time (``bomi record``'s layout: the moves
        kept, neutral between two motions)."""
        time = np.asarray(self._times) - self.start
        keep = (time >= 0.0) & (time < self.cues[-1].end_s)
        starts = np.array([cue.start_s for cue in self.cues])
        labels = np.array([cue.label for cue in self.cues])[np.searchsorted(starts, time[keep], side="right") - 1]
        rows = [sample for sample, kept in zip(self._samples, keep) if kept]
        nodes = {index: NodeData(*(np.array([getattr(row[index], name) for row in rows], dtype=float).reshape(-1, 3)
                                   for name in ("acc", "gyro", "mag", "angles")))
                 for index in self.model.spec.nodes}
        return Recording(nodes=nodes, labels=labels, time=time[keep], source=f"recalibration at {self.start:.2f} s")

    def retrained(self) -> OnlineChain:
        """A chain of the model trained on the recording, its neutral the recording's (BomiError: no usable
        model could be trained on it)."""
        recording = self.recording()
        if not len(recording):
            raise BomiError(f"{recording.source}: no complete row of nodes {list(self.model.spec.nodes)}")
        model = train([recording], self.profile, spec=self.model.spec, post=self.model.post)
        chain = OnlineChain(model, self.profile)
        nodes = model.spec.nodes
        chain.set_neutral(dict(zip(nodes, recording_neutral(recording, nodes, self.profile.neutral_samples))))
        return chain
