"""The host end of a virtual participant's link in a simulated episode: its deliveries of
base-station frames through the parser and the streaming chain, a delivery at a time.

The participant makes its samples a chunk at a time (``tasks.stacking.episode.BomiChannel``: as far ahead
as its reaction time allows), so the frames of a chunk, and their arrival times, are known when it
is made. The chain's output depends only on the sequence of frames it is given, not on when, so a
chunk goes through the parser and the chain at once, by stages over all its frames
(``FrameParser.feed_whole``, ``OnlineChain.push_many``), and each decision is handed out at the
arrival of the frame that released it from the parser: the decisions, and the control ticks they
reach, are those of feeding the frames tick by tick (tests/test_chain_batch.py). Where the parser
would not deliver the rest of a chunk whole at once (the stream's start, before its nodes are
confirmed; a counter gap the phantom-frame guard holds back), its frames go through
``FrameParser.feed`` one by one, which gives each frame's release exactly, until it would.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from bomi.chain import Decision, OnlineChain
from bomi.frames import FIRST_IMU_NODE_ID, FrameParser, SampleIndex
from tasks.participants.imu_synth import Delivery


class Receiver:
    """Deliveries in arrival order -> (sample index of the frame that made it, decision), by arrival time."""

    def __init__(self, chain: OnlineChain) -> None:
        self.chain, self.parser, self._sample_index = chain, FrameParser(), SampleIndex()
        self._due: deque[tuple[float, int, Decision]] = deque()   # (arrival, sample index, decision)

    def take(self, delivery: Delivery) -> None:
        """Every frame of ``delivery`` (later than the ones taken before) through the parser and the chain:
        at once from where the parser would deliver the rest whole, frame by frame before."""
        frames, start, was_idle = delivery.frames, 0, False
        while start < len(frames):
            idle = self.parser.idle
            if idle and not was_idle and self._batch(delivery, start):   # tried once per spell of idleness
                return
            was_idle = idle
            for frame in self.parser.feed(frames[start]):
                sample = self._sample_index(frame)
                decision = self.chain.push_frame(frame)
                if decision is not None:
                    self._due.append((float(delivery.arrival_s[start]), sample, decision))
            start += 1

    def _batch(self, delivery: Delivery, start: int) -> bool:
        """The frames of ``delivery`` from ``start`` on through ``FrameParser.feed_whole`` and
        ``OnlineChain.push_many``, if the parser takes them whole (False: nothing done)."""
        records = self.parser.feed_whole(b"".join(delivery.frames[start:]))
        if records is None:
            return False
        node_ids = records["node_id"].astype(np.int64)
        samples = self._sample_index.many(node_ids, records["counter"])
        made, decisions = self.chain.push_many(node_ids - (FIRST_IMU_NODE_ID - 1), records["acc"], records["gyro"],
                                               records["mag"])
        self._due.extend(zip(delivery.arrival_s[start:][made].tolist(), samples[made].tolist(), decisions))
        return True

    def until(self, t_end: float) -> list[tuple[int, Decision]]:
        """The decisions of the frames arrived by ``t_end`` (not handed out before), with their sample indices."""
        out = []
        while self._due and self._due[0][0] <= t_end:
            _, sample, decision = self._due.popleft()
            out.append((sample, decision))
        return out
