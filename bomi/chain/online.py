"""The streaming chain: one sample at a time, the same stages as the batch form, a Decision per tick."""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from operator import itemgetter

import numpy as np

from bomi.chain.windows import NODE_WIDTH
from bomi.classifier import NEUTRAL_LABEL, MajorityVote, Model, posteriors, proportional, sample_amplitude
from bomi.errors import BomiError
from bomi.features import WindowBuffer, features
from bomi.frames import ImuFrame, imu_index
from bomi.fusion import NodeFusion, load_filter, neutral_offsets
from bomi.profiles import Profile


@dataclass(slots=True)
class Decision:
    label: int
    name: str
    function: str            # joystick function (F, B, R, L, Rr, Lr, B1, B2) or "neutral"
    confidence: float        # posterior of the LDA's winning class (before post-processing)
    rejected: bool
    gamma: float             # the class's amplitude (deg) on the node carrying it: sqrt(p^2 + r^2 + y^2), or
                             # the change along the class's direction (profile [proportional]); 0 for neutral
    nu: float                # proportional output in [0, 1]
    sample_index: int        # index of the tick (node-1 sample) that produced it


class OnlineChain:
    """One sample at a time: per-node fusion, then a tick with at most one Decision per node-1 sample.

    The other nodes contribute their latest state; no decision is made until every node has
    reported once and the window is full. Node states are kept as Python floats (the same IEEE
    arithmetic as the batch form's arrays) because per-sample numpy calls dominate the cost.
    ``push_many`` takes many frames at once (a simulated participant's chunk) with the same result.
    """

    def __init__(self, model: Model, profile: Profile):
        missing = set(model.spec.nodes) - set(profile.node_indices)
        if missing:
            raise BomiError(f"{profile.source}: the model needs node(s) {sorted(missing)} the profile does not define")
        self.model = model
        self.profile = profile
        self.nodes = model.spec.nodes
        self._slot = {node: k for k, node in enumerate(self.nodes)}
        calibrations = {n.index: n.calibration for n in profile.nodes}
        self._fusion = {node: NodeFusion(calibrations[node]) for node in self.nodes}
        load_filter()   # before any frame: a stream must not wait for it between two samples
        self._state = [0.0] * (len(self.nodes) * NODE_WIDTH)
        self._components = model.spec.components.tolist()
        self._gather = itemgetter(*self._components)   # the window's components of the node states
        # per class with an amplitude: (its node's slot in the states, its direction or None, its range)
        self._amplitude = {label: (self._slot[r.node] * NODE_WIDTH, r.direction, r)
                           for label, r in model.amplitude.items() if r.node in self._slot}
        self._classes = {cls.label: cls for cls in profile.classes}
        self._labels = model.classes.tolist()   # the LDA's classes (posterior order) as Python ints
        self._seen: set[int] = set()
        self._neutral = [(0.0, 0.0, 0.0)] * len(self.nodes)
        self._window = WindowBuffer(model.spec.window, len(self._components), model.spec.stride)
        self._vote = MajorityVote(model.post.vote_length)
        self._voting = model.post.vote_length > 1   # a vote of one is the label itself: not called per window
        self._calibration: dict[int, list] | None = None
        self.ticks = 0

    # neutral-offset calibration
    @property
    def neutral(self) -> dict[int, tuple[float, float, float]]:
        return {node: self._neutral[k] for node, k in self._slot.items()}

    def set_neutral(self, offsets: Mapping[int, Sequence[float]]) -> None:
        """Neutral (pitch, roll, yaw) per node index; the window restarts."""
        for node, offset in offsets.items():
            self._neutral[self._slot[node]] = tuple(float(v) for v in offset)
        self._window.reset()

    def forget_decisions(self) -> None:
        """The window and the majority vote start empty: after a break in the stream (another sitting,
        perhaps) no sample or label from before it takes part in a decision after it."""
        self._window.reset()
        self._vote.reset()

    def begin_neutral_calibration(self) -> None:
        """Collect the next ``profile.neutral_samples`` fused samples of every node as the neutral posture."""
        self._calibration = {node: [] for node in self.nodes}

    @property
    def calibrating(self) -> bool:
        return self._calibration is not None

    # inputs
    def push_frames(self, frames: Iterable[ImuFrame]) -> list[Decision]:
        """Frames as the parser gives them, in arrival order, through the chain: the decisions they make."""
        return [decision for frame in frames if (decision := self.push_frame(frame)) is not None]

    def push_frame(self, frame: ImuFrame) -> Decision | None:
        """One frame as the parser gives it (``push`` with its node index and raw values)."""
        return self.push(imu_index(frame.node_id), frame.acc, frame.gyro, frame.mag)

    def push(self, node: int, acc, gyro, mag) -> Decision | None:
        """Raw int16 LSB in the sensor's axes -> fusion -> ``push_angles``. Unknown nodes are ignored."""
        fusion = self._fusion.get(node)
        if fusion is None:
            return None
        return self.push_angles(node, fusion.update(acc, gyro, mag), gyro)

    def push_angles(self, node: int, angles: Sequence[float], gyro: Sequence[float]) -> Decision | None:
        """Already-fused (pitch, roll, yaw) and gyro of one node (e.g. replaying a published recording)."""
        slot = self._slot.get(node)
        if slot is None:
            return None
        if self._calibration is not None:
            return self._collect_neutral(node, angles)
        base = slot * NODE_WIDTH
        neutral = self._neutral[slot]
        state = self._state
        state[base] = float(angles[0]) - neutral[0]
        state[base + 1] = float(angles[1]) - neutral[1]
        state[base + 2] = float(angles[2]) - neutral[2]
        state[base + 3], state[base + 4], state[base + 5] = float(gyro[0]), float(gyro[1]), float(gyro[2])
        self._seen.add(node)
        if node != self.nodes[0] or len(self._seen) < len(self.nodes):
            return None
        return self._tick()

    def _collect_neutral(self, node: int, angles: Sequence[float]) -> None:
        samples = self._calibration[node]
        samples.append(tuple(angles))
        if all(len(s) >= self.profile.neutral_samples for s in self._calibration.values()):
            offsets = {n: neutral_offsets(np.array(s)) for n, s in self._calibration.items()}
            self._calibration = None
            self.set_neutral(offsets)

    def push_many(self, node: np.ndarray, acc: np.ndarray, gyro: np.ndarray, mag: np.ndarray
                  ) -> tuple[np.ndarray, list[Decision]]:
        """``push`` of n frames in arrival order ((n,) node indices, (n, 3) raw values each), stage by
        stage over all of them: each node's fusion by ``NodeFusion.update_many``, the node states at
        every tick, the windows (``WindowBuffer.push_many``), features, posteriors and vote of every
        full window at once. Returns the positions of the frames that made a decision and the
        decisions: what n calls of ``push`` return, to the bit (tests/test_chain_batch.py). A neutral
        calibration under way takes its frames one by one, as ``push`` does."""
        n, first = len(node), 0
        while self._calibration is not None and first < n:
            self.push(int(node[first]), acc[first].tolist(), gyro[first].tolist(), mag[first].tolist())
            first += 1
        node, acc, gyro, mag = node[first:], acc[first:], gyro[first:], mag[first:]
        previous = np.array(self._state).reshape(len(self.nodes), NODE_WIDTH)
        per_node, opened = [], -1   # opened: the position from which every node has reported
        for slot, index in enumerate(self.nodes):
            mine = np.flatnonzero(node == index)
            states = np.empty((len(mine) + 1, NODE_WIDTH))   # row 0: the state before these frames
            states[0] = previous[slot]
            if len(mine):
                states[1:, 3:] = gyro_mine = gyro[mine]
                states[1:, :3] = self._fusion[index].update_many(acc[mine], gyro_mine, mag[mine])
                states[1:, :3] -= self._neutral[slot]
                if index not in self._seen:
                    opened = max(opened, int(mine[0]))
                    self._seen.add(index)
            elif index not in self._seen:
                opened = len(node)
            per_node.append((mine, states))
        self._state = np.concatenate([states[-1] for _, states in per_node]).tolist()
        lead = per_node[0][0]
        ticking = lead[lead >= opened]
        states = np.hstack([states[np.searchsorted(mine, ticking, side="right")] for mine, states in per_node])
        indices = self.ticks + np.arange(len(ticking))
        self.ticks += len(ticking)
        vectors, made = self._window.push_many(states[:, self._components], self.model.spec.kind)
        return ticking[made] + first, self._decide_many(vectors, states[made], indices[made].tolist())

    def _tick(self) -> Decision | None:
        index = self.ticks
        self.ticks += 1
        state = self._state
        window = self._window.push(np.array(self._gather(state), dtype=float))
        if window is None:
            return None
        prob = posteriors(self.model, features(self.model.spec.kind, window[None]))[0]
        best = int(prob.argmax())
        return self._decide(best, float(prob[best]), state, index)

    def _decide_many(self, vectors: np.ndarray, states: np.ndarray, indices: Sequence[int]) -> list[Decision]:
        """``_decide`` of w full windows' (w, F) feature ``vectors`` at node states ``states`` (w rows), in
        order. Each window's scores a product of its own ((1, F) x (F, K), stacked as (w, 1, F)), as
        ``_tick``'s: one product over all the windows would sum in another order (other bits). The
        winners and the node states are read out of the arrays once, as Python numbers."""
        prob = posteriors(self.model, vectors[:, None, :])[:, 0]
        best = prob.argmax(axis=1)
        confidence = prob[np.arange(len(best)), best]
        decide = self._decide
        return [decide(*decision) for decision in zip(best.tolist(), confidence.tolist(), states.tolist(), indices)]

    def _decide(self, best: int, confidence: float, state: Sequence[float], index: int) -> Decision:
        """The decision of tick ``index`` from the window's winning class (its position ``best`` among the
        model's classes, its posterior ``confidence``) and the node states then (Python floats)."""
        threshold = self.model.post.rejection_threshold
        is_rejected = threshold is not None and confidence < threshold
        label = NEUTRAL_LABEL if is_rejected else self._labels[best]
        if self._voting:
            label = self._vote.push(label)
        cls = self._classes[label]
        amplitude = self._amplitude.get(label)
        if amplitude is None:
            return Decision(label, cls.name, cls.function, confidence, is_rejected, 0.0, 0.0, index)
        base, direction, calibrated = amplitude
        g = sample_amplitude(state[base], state[base + 1], state[base + 2], direction)
        return Decision(label, cls.name, cls.function, confidence, is_rejected, g, proportional(g, calibrated), index)
