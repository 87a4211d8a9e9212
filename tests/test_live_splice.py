"""Another sitting spliced onto the same live connection with the packet counters continuing in step
(issue 55 item 4): the sensor's turn between two frames, faster than any body turns, is a break
(bomi/gate.py), so the arm rests until the new sitting's warm-up and neutral, as after a counter restart."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from bomi.classifier import NEUTRAL_LABEL
from bomi.gate import GateConfig, NodeGate, sensor_turn
from bomi.protocol import Cue
from tasks.trials.live import LiveLoop
from tests.test_live import StickArm

TICK = 1 / 60
DOWN = (0.0, 0.0, -16000.0)        # gravity along -z (LSB)
FIELD = (3000.0, 0.0, -5000.0)     # a field dipping 59 deg


def turned(vector, deg: float):
    """``vector`` turned ``deg`` about the vertical (z)."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return (c * vector[0] - s * vector[1], s * vector[0] + c * vector[1], vector[2])


def test_the_sensor_turn_by_hand():
    assert sensor_turn((DOWN, FIELD), (DOWN, turned(FIELD, 46.0))) == pytest.approx(46.0)      # heading
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    nod = lambda v: (v[0], c * v[1] - s * v[2], s * v[1] + c * v[2])   # noqa: E731  (30 deg about x: a tilt)
    assert sensor_turn((DOWN, FIELD), (nod(DOWN), nod(FIELD))) == pytest.approx(30.0)
    assert sensor_turn((DOWN, (0.0, 0.0, -5000.0)), (DOWN, (0.0, 0.0, -4000.0))) == 0.0       # field along gravity
    assert GateConfig().max_turn_deg == pytest.approx(32.0)                                    # 2000 deg/s x 16 ms


def test_a_turn_faster_than_the_bound_is_a_break_returned_with_the_next_counter():
    gate = NodeGate(1)
    zero = (0.0, 0.0, 0.0)
    for counter, heading in enumerate([0.0, 31.0, 31.0]):             # 31 deg in one sample: a body can't, but under the bound
        assert gate.count(counter) is None and gate.check_raw(turned(FIELD, heading), zero, DOWN)
    assert gate.count(4) is None                                       # a sample lost: 64 deg allowed over 2
    assert gate.check_raw(turned(FIELD, 31.0 + 60.0), zero, DOWN)
    assert gate.count(5) is None
    assert not gate.check_raw(turned(FIELD, 91.0 + 46.0), zero, DOWN)  # the splice: held, not fused
    assert gate.defect == "node 1: a turn of 46 deg in 1 sample(s) (faster than 2000 deg/s: no body turns so fast)"
    assert gate.count(6) == "a turn of 46 deg in 1 sample(s) (faster than 2000 deg/s: no body turns so fast)"
    gate.restart(6)
    assert gate.check_raw(turned(FIELD, 137.0), zero, DOWN) and gate.count(7) is None    # the new sitting goes on


def test_p1s_recorded_head_never_turns_that_fast(p1_days):
    """The published days' head node (acc and mag as recorded), frame to frame inside each stitched
    301-row block: every turn well under the bound (the largest, 22 deg, is 0.69 of it)."""
    largest = 0.0
    for rec in p1_days.values():
        acc, mag = rec.nodes[1].acc.tolist(), rec.nodes[1].mag.tolist()
        for k in range(1, len(acc)):
            if k % 301:
                largest = max(largest, sensor_turn((acc[k - 1], mag[k - 1]), (acc[k], mag[k])))
    assert 20.0 < largest < 0.7 * GateConfig().max_turn_deg


def spliced_ticks(profile, sittings, parser) -> list:
    """The frames each control tick reads of P1 in the ``sittings`` (heading_deg, cues, end_s), one after
    the other on one stream: each sitting from its start (its filter's zero state), the packet counters
    continuing in step across the splice; and the samples of each sitting."""
    from bomi.emulator import EmulatorConfig, EmulatorStats, block_chunks
    from tasks.participants.participant import load_participant
    from tasks.participants.wire import participant_blocks

    params = load_participant("P1")
    sittings_blocks = [list(participant_blocks(params, profile, 3, cues, end_s, heading_deg=heading))
                       for heading, cues, end_s in sittings]
    samples = [sum(len(block[1]) for block in blocks) for blocks in sittings_blocks]
    chunks = list(block_chunks(itertools.chain.from_iterable(sittings_blocks), EmulatorConfig(), EmulatorStats()))
    end_s = sum(end for _, _, end in sittings)
    per_tick, i = [], 0
    for k in range(round(end_s / TICK)):
        data = b""
        while i < len(chunks) and chunks[i][0] <= k * TICK:
            data += chunks[i][1]
            i += 1
        per_tick.append((k * TICK, parser.feed(data, k * TICK)))
    return per_tick, samples


def test_a_sitting_spliced_with_counters_in_step_rests_the_arm_until_its_new_neutral(p1_model_file):
    """P1 facing -40 deg (neutral, then F from 15 s), at 17 s another sitting facing +6 deg (a 46 deg turn
    between two frames) spliced on from its start, the counters in step: the arm rests from the splice
    through the new warm-up and neutral, then F drives again."""
    from bomi.chain import OnlineChain
    from bomi.frames import FrameParser
    from bomi.model_io import load_model
    from bomi.profiles import load_profile

    profile = load_profile("P1")
    f_label = next(cls.label for cls in profile.classes if cls.function == "F")
    cues = [Cue(NEUTRAL_LABEL, "neutral", 0.0, 15.0), Cue(f_label, "F", 15.0, 20.0)]
    ticks = []
    loop = LiveLoop(OnlineChain(load_model(p1_model_file), profile), StickArm(), observers=[ticks.append])
    stream, samples = spliced_ticks(profile, [(-40.0, cues, 17.0), (6.0, cues, 19.0)], FrameParser())
    for t, frames in stream:
        loop.tick(t, frames)
    assert not any(tick.reconnected for tick in ticks)
    counters = [frame.counter for _, frames in stream for frame in frames if frame.node_id == 10]
    assert all((b - a) % 256 == 1 for a, b in zip(counters, counters[1:]))        # in step across the splice

    neutrals = [(tick.t, tick.neutral) for tick in ticks if tick.neutral is not None]
    assert len(neutrals) == 2
    (t1, old), (t2, new) = neutrals
    assert 12.0 <= t1 < 15.0 and 12.0 <= t2 - 17.0 < 15.0                 # each after a whole warm-up
    assert abs((new[1][2] - old[1][2]) - 46.0) < 3.0                        # the head's yaw: the new heading
    f_before = [tick for tick in ticks if 16.2 <= tick.t < 17.0]
    assert sum(bool(tick.state.deflection.get("F")) for tick in f_before) > 0.8 * len(f_before)
    # the tick that reads the new sitting's first frame holds the arm (the turn found), the next says the break
    read = np.cumsum([sum(frame.node_id == 10 for frame in frames) for _, frames in stream])
    splice = int(np.searchsorted(read, samples[0] + 1))
    assert ticks[splice].hold.startswith("node 1: a turn of ") and "deg in 1 sample(s) (faster than 2000 deg/s" in ticks[splice].hold
    assert ticks[splice + 1].hold.startswith("node 1 untrusted after a turn of ")
    retaking = [tick for tick in ticks[splice:] if tick.t <= t2]
    assert not any(tick.command.linear.any() for tick in retaking)          # at rest through warm-up and neutral
    still = [tick for tick in ticks if t2 < tick.t < 17.0 + 15.9]           # the new neutral: still
    assert not any(tick.command.linear.any() for tick in still)
    f_again = [tick for tick in ticks if tick.t >= 17.0 + 16.2]
    assert sum(bool(tick.state.deflection.get("F")) for tick in f_again) > 0.8 * len(f_again)
