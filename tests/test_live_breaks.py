"""No calibration is trusted across a break in the stream (issue 40 item 1): after a reconnection, a
silence of 1 s or a packet-counter jump, the node's filter starts again, its warm-up is rerun and the
neutral is retaken, the arm at rest until then. The loop on an injected clock (``LiveLoop.tick``)."""
from __future__ import annotations

import math

from bomi.classifier import NEUTRAL_LABEL
from bomi.fusion import DT
from bomi.gate import GateConfig
from bomi.protocol import Cue
from tasks.trials.live import LiveLoop
from tests.test_live import QUICK_GATE, SETTLE, ScriptedChain, StickArm, decision, still_frame

TICK = 1 / 60


def sitting_ticks(profile, heading_deg: float, cues: list[Cue], end_s: float, parser, start_s: float) -> list:
    """The frames each control tick reads of P1 sitting facing ``heading_deg`` (its stream from its
    start: counters from 0, the receiver's filter from its zero state), tick times from ``start_s``."""
    from bomi.emulator import EmulatorConfig, EmulatorStats, block_chunks
    from tasks.participants.participant import load_participant
    from tasks.participants.wire import participant_blocks

    chunks = list(block_chunks(participant_blocks(load_participant("P1"), profile, 3, cues, end_s,
                                                  heading_deg=heading_deg), EmulatorConfig(), EmulatorStats()))
    per_tick, i = [], 0
    for k in range(round(end_s / TICK)):
        data = b""
        while i < len(chunks) and chunks[i][0] <= k * TICK:
            data += chunks[i][1]
            i += 1
        per_tick.append((start_s + k * TICK, parser.feed(data, start_s + k * TICK)))
    return per_tick


def test_back_from_another_sitting_the_arm_rests_until_the_new_neutral_then_follows_it(p1_model_file):
    """P1 facing -40 deg (neutral taken, then F), the stream gone for 2 s, then back from another sitting
    facing +50 deg from its start. Without a new neutral every decision of the second sitting would be
    off by 90 deg of yaw; with it the arm rests through the warm-up and the new neutral, then F drives."""
    from bomi.chain import OnlineChain
    from bomi.frames import FrameParser
    from bomi.model_io import load_model
    from bomi.profiles import load_profile

    profile = load_profile("P1")
    f_label = next(cls.label for cls in profile.classes if cls.function == "F")
    cues = [Cue(NEUTRAL_LABEL, "neutral", 0.0, 15.0), Cue(f_label, "F", 15.0, 20.0)]
    parser = FrameParser()                                   # one receiver throughout, as `bomi live` has
    first = sitting_ticks(profile, -40.0, cues, 17.0, parser, 0.0)
    second = sitting_ticks(profile, 50.0, cues, 19.0, parser, 19.0)   # 2 s of silence before it
    ticks = []
    loop = LiveLoop(OnlineChain(load_model(p1_model_file), profile), StickArm(), observers=[ticks.append])
    for t, frames in first:
        loop.tick(t, frames)
    for k in range(round(2.0 / TICK)):
        loop.tick(17.0 + k * TICK, [])
    for k, (t, frames) in enumerate(second):
        loop.tick(t, frames, reconnected=k == 0)

    neutrals = [(tick.t, tick.neutral) for tick in ticks if tick.neutral is not None]
    assert len(neutrals) == 2
    (t1, old), (t2, new) = neutrals
    assert 12.0 <= t1 < 15.0 and 12.0 <= t2 - 19.0 < 15.0               # each after a whole warm-up (12 s floor)
    for node in old:                                                   # the heading moved every node's yaw
        assert abs((new[node][2] - old[node][2]) - 90.0) < 3.0
    moving = [bool(tick.command.linear.any()) for tick in ticks]
    f_ticks = [tick for tick in ticks if 16.2 <= tick.t < 17.0]   # F from ~1 s after its cue
    assert sum(bool(tick.state.deflection.get("F")) for tick in f_ticks) > 0.8 * len(f_ticks)   # F before the break
    back = next(k for k, tick in enumerate(ticks) if tick.reconnected)
    retaking = ticks[back:next(k for k, tick in enumerate(ticks) if tick.t == t2) + 1]
    assert not any(moving[back:back + len(retaking)])                  # at rest through warm-up and neutral
    message = "node 1 untrusted after reconnect: retaking warm-up and neutral"
    assert {tick.hold for tick in retaking[:-1]} == {"no frames", message}        # until the frames flow again
    assert sum(tick.hold == message for tick in retaking) > 12.0 / TICK
    rest = [tick for tick in ticks if t2 < tick.t < 19.0 + 15.9]       # still, after the new neutral
    assert not any(tick.command.linear.any() for tick in rest)
    f_again = [tick for tick in ticks if tick.t >= 19.0 + 16.2]
    assert sum(bool(tick.state.deflection.get("F")) for tick in f_again) > 0.8 * len(f_again)


class CalibratingChain(ScriptedChain):
    """A scripted chain that takes its neutral from ``samples`` pushed samples, as the real one does."""

    def __init__(self, decisions, samples: int = 3):
        super().__init__(decisions)
        self.samples, self._left, self.calibrations = samples, 0, 0

    @property
    def calibrating(self) -> bool:
        return self._left > 0

    @calibrating.setter
    def calibrating(self, value) -> None:
        """ScriptedChain's own flag: unused."""

    def begin_neutral_calibration(self) -> None:
        self._left, self.calibrations = self.samples, self.calibrations + 1

    def forget_decisions(self) -> None:
        self.forgotten = getattr(self, "forgotten", 0) + 1

    def push_angles(self, node, angles, gyro):
        if self._left:
            self._left -= 1
            return None
        return super().push_angles(node, angles, gyro)


def _run(loop, frames_per_tick, counters) -> list:
    out = []
    for k, (n, counter) in enumerate(zip(frames_per_tick, counters)):
        out.append(loop.tick(k * DT, [still_frame(counter + j) for j in range(n)]))
    return out


def test_a_gap_and_a_counter_jump_each_untrust_the_node_even_with_fixed_neutral_offsets():
    """Fixed offsets given (``--neutral-from``) hold for the first sitting only: after a 1.2 s gap, and
    again after a counter jump, the filter restarts, the warm-up reruns and the neutral is retaken."""
    chain = CalibratingChain([decision(nu=0.5)] * 200)
    loop = LiveLoop(chain, StickArm(), neutral={1: (0.0, 0.0, 0.0)}, gate=QUICK_GATE)
    gap = round(1.2 / DT)
    script = [1] * 10 + [0] * gap + [1] * 10
    counters = list(range(10)) + [0] * gap + list(range(10, 20))         # counters in step across the gap
    ticks = _run(loop, script, counters)
    assert ticks[9].command.linear.any() and ticks[9].neutral is None and ticks[3].neutral == {1: (0.0, 0.0, 0.0)}
    back = ticks[10 + gap:]
    assert back[0].hold == "node 1 untrusted after a 1.2 s gap in its frames: retaking warm-up and neutral"
    # warm-up (SETTLE samples) then the neutral (3 samples) before anything moves
    assert [t.command.linear.any() for t in back] == [False] * (SETTLE + 3 - 1) + [True] * (10 - SETTLE - 3 + 1)
    assert chain.calibrations == 1 and back[SETTLE + 1].neutral is not None and back[SETTLE + 2].hold is None
    assert chain.forgotten == 1          # no label of the first sitting votes in the second
    after = loop.tick(len(ticks) * DT, [still_frame(100)])                 # 80 counters on: another stream
    assert after.hold == "node 1 untrusted after a packet-counter jump (a step of 81): retaking warm-up and neutral"
    assert not after.command.linear.any() and loop.gate.node[1].fused_samples == 1


def test_a_reconnection_restarts_the_filter_and_the_warm_up_floor():
    loop = LiveLoop(CalibratingChain([decision(nu=0.5)] * 100), StickArm(), neutral={1: (0.0, 0.0, 0.0)},
                    gate=GateConfig(settle_samples=SETTLE, filter_age_samples=20))
    _run(loop, [1] * 25, range(25))
    fusion = loop.fusion[1]
    assert loop.gate.node[1].settled and loop.gate.node[1].fused_samples == 25
    tick = loop.tick(25 * DT, [still_frame(25)], reconnected=True)
    assert loop.fusion[1] is not fusion and loop.gate.node[1].fused_samples == 1
    assert tick.reconnected and tick.record()["reconnected"] and "untrusted after reconnect" in tick.hold
    later = [loop.tick((26 + k) * DT, [still_frame(26 + k)]) for k in range(30)]
    # the filter 20 samples old again (k = 18: its 20th), then 3 samples of neutral (k = 18, 19, 20): the
    # neutral holds from the end of tick 20 on
    assert [t.hold is None for t in later].index(True) == 21 and later[20].neutral is not None


# ------------------------------------------------------------------------- re-zero by the person (issue 42)
def test_a_button_held_for_the_rezero_hold_then_rest_retakes_the_neutral_with_the_arm_at_rest():
    """B1 held for the profile's rezero_hold_s (a long press: its mode change acts once, as a press),
    then the neutral class: the neutral is retaken from the next samples (the rest, not the press),
    the arm at rest until it holds, then F drives again. A press held just short of it changes the
    mode and nothing else."""
    profile = ScriptedChain([]).profile
    b1 = next(cls.label for cls in profile.classes if cls.function == "B1")
    hold = math.ceil(profile.rezero_hold_s / DT - 1e-9)
    rest, f = decision(label=NEUTRAL_LABEL, function="neutral", nu=0.0), decision(nu=0.5)
    press = decision(label=b1, function="B1", nu=0.0)
    script = [rest] * 5 + [press] * (hold - 1) + [rest] * 5 + [f] * 5 + [press] * hold + [rest] * 8 + [f] * 5
    chain = CalibratingChain(script)
    loop = LiveLoop(chain, StickArm(), neutral={1: (0.0, 0.0, 0.0)}, gate=QUICK_GATE)
    ticks = _run(loop, [1] * (SETTLE - 1 + len(script) + 3), range(SETTLE - 1 + len(script) + 3))[SETTLE - 1:]
    assert [k for k, t in enumerate(ticks) if t.rezero] == [5 + hold - 1 + 10 + hold]   # the first rest after it
    asked = 5 + hold - 1 + 10 + hold
    assert chain.calibrations == 1 and loop.summary.rezeros == 1 and ticks[asked].record()["rezero"] is True
    assert sum(bool(t.state.pressed) for t in ticks) == 2                          # each long press is one press too
    # the neutral is taken from the 3 samples after the gesture's rest (the stick at rest), then the
    # 7 rests left and F, which reaches the stick again
    assert ticks[asked].calibrating and ticks[asked + 3].neutral == chain.neutral
    assert [t.state.deflection for t in ticks[asked:]] == [{}] * 11 + [{"F": 0.5}] * 5
