"""Recording from a base-station stream: which nodes are on it, waiting until every node's filter
has settled (bomi.gate), timing rows read in a bunch, and labelling them by the protocol's segments
as the person is prompted (`bomi capture`, `bomi record`). Progress goes to a tqdm bar the caller owns."""
from __future__ import annotations

import sys
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence

import numpy as np
from tqdm import tqdm

from bomi.errors import BomiError
from bomi.frames import FrameParser, ImuFrame, RowAssembler, imu_index
from bomi.fusion import DT, FusedRows, NodeCalibration, sample_times
from bomi.gate import Gate, NodeGate
from bomi.protocol import Cue
from bomi.recording import RecordingWriter
from bomi.serial_source import SerialSource, StreamLost
from tasks.operators.stick import arm_profile

# After the first IMU frame, how long capture listens to learn which nodes are on the stream.
NODE_DETECTION_S = 0.5
# How long record waits for frames of every node of the profile before giving up.
NODE_WAIT_S = 5.0
# How long record waits for every node's orientation filter to settle (bomi.gate) before giving up.
# The gate trusts no node before its filter has run the 12 s warm-up (bomi.gate: the worst start's
# error is below 0.5 deg by then), so a person holding still is recorded about 12-14 s after the
# stream starts. 60 s leaves four times that to
# sit still (adjust the headset, stop talking); a node not settled by then has a fault that waiting does
# not cure (a sensor reading zeros or saturated, a person who cannot hold still, motion nearby).
SETTLE_WAIT_S = 60.0
COUNTDOWN_S = 3.0

TimedFrame = tuple[float, ImuFrame]


def timed_frames(batches: Iterator[tuple[float, list[ImuFrame]]], backlog: Sequence[TimedFrame],
                  progress: tqdm, parser: FrameParser) -> Iterator[TimedFrame]:
    yield from backlog
    for elapsed, frames in batches:
        progress.set_postfix_str(quality(parser), refresh=False)
        yield from ((elapsed, frame) for frame in frames)


def quality(parser: FrameParser) -> str:
    """Live signal quality, short: per node rate and lost share."""
    return " ".join(f"IMU{imu_index(n)} {s.rate_hz:.0f}Hz {100 * s.loss_fraction:.0f}%lost"
                    for n, s in sorted(parser.nodes.items()))


def unfinished(exc: StreamLost, writer: RecordingWriter) -> BomiError:
    """The one-line error of a lost stream, saying what became of the recording."""
    if writer.rows_written == 0:
        writer.path.unlink(missing_ok=True)
        return BomiError(f"{exc}; nothing recorded, {writer.path} not written")
    return BomiError(f"{exc}; {writer.path} is partial: it keeps the {writer.rows_written} rows recorded before")



def detect_nodes(batches: Iterator[tuple[float, list[ImuFrame]]], url: str,
                  backlog: list[TimedFrame]) -> tuple[int, ...]:
    """IMU nodes seen within NODE_DETECTION_S of the first IMU frame; frames read go to ``backlog``."""
    first = None
    for elapsed, frames in batches:
        backlog += [(elapsed, frame) for frame in frames]
        if backlog and first is None:
            first = elapsed
        if first is not None and elapsed - first >= NODE_DETECTION_S:
            break
    if not backlog:
        raise BomiError(f"{url}: no IMU frames received; nothing recorded")
    return tuple(sorted({imu_index(frame.node_id) for _, frame in backlog}))


def capture_calibrations(profile_name: str | None, indices: tuple[int, ...]) -> dict[int, NodeCalibration]:
    if profile_name is None:
        return {i: NodeCalibration.default_for(i) for i in indices}
    profile = arm_profile(profile_name)
    by_index = {node.index: node.calibration for node in profile.nodes}
    missing = [i for i in indices if i not in by_index]
    if missing:
        raise BomiError(f"{profile.source}: no calibration for node(s) {missing} on the stream")
    return {i: by_index[i] for i in indices}



def cue_text(segments: list[Cue], k: int, t: float) -> str:
    """What the terminal shows at time t of segment k: the cue, time left, a countdown to the next."""
    segment = segments[k]
    left = segment.end_s - t
    text = f"[{k + 1}/{len(segments)}] {segment.prompt} ({left:.0f} s)"
    if k + 1 < len(segments) and segments[k + 1].label != segment.label and left <= COUNTDOWN_S:
        text += f" - next: {segments[k + 1].prompt.removeprefix('HOLD ')} in {left:.0f}"
    return text


def unsettled(gate: NodeGate, now: float) -> str:
    """Why a node is not trusted yet, for the person at the keyboard: the gate's reason, and for a filter
    still warming up how far its last window is from the settle test."""
    reason = (gate.verdict(now) or "").removeprefix(f"node {gate.index}: ")
    change = gate.change
    if not gate.settled and gate.defect is None and gate.fused_samples < gate.config.filter_age_samples:
        reason = (f"still warming up: its filter has run {gate.fused_samples * DT:.1f} s of the "
                  f"{gate.config.filter_age_samples * DT:g} s it needs from its zero state")
    elif not gate.settled and gate.defect is None and change is not None:
        reason = (f"still warming up: its angles changed by {change:.2f} deg between the halves of the last "
                  f"{gate.config.resume_s:g} s, settled is below {gate.config.settle_change_deg:.2f}")
    return reason


def wait_until_settled(batches: Iterator[tuple[float, list[ImuFrame]]], gate: Gate, rows: FusedRows,
                        assembler: RowAssembler, source: SerialSource, progress: tqdm, timeout_s: float) -> float:
    """Fuse the profile's nodes' frames one by one through ``gate`` (``bomi.gate``: an implausible frame is
    not fused, as in `bomi live`) until every node is settled, plausible and fresh; return that time.
    Nothing read here is recorded: the filters' warm-up never reaches the protocol. BomiError (one line,
    nothing written) if a node sends nothing within NODE_WAIT_S or is not trusted within ``timeout_s``."""
    shown = None
    try:
        while True:
            elapsed, frames = next(batches)    # the stream's batches end only by StreamLost
            nodes = [imu_index(frame.node_id) for frame in frames]
            for node in gate.arrivals(elapsed, Counter(nodes)):   # a break: its warm-up from scratch
                gate.node[node].restart()
                rows.restart(node)
            for frame, node in zip(frames, nodes):
                node_gate = gate.node.get(node)
                if node_gate is None:
                    continue
                if node_gate.count(frame.counter) is not None:
                    node_gate.restart(frame.counter)
                    rows.restart(node)
                if node_gate.check_raw(frame.mag, frame.gyro, frame.acc):
                    node_gate.fused(rows.angles(frame))
                    assembler.push(frame)
            reason = gate.verdict(elapsed)
            if reason is None:
                return elapsed
            if reason != shown:
                tqdm.write(f"hold still: {reason}", file=sys.stderr)
                shown = reason
            progress.set_description_str(f"hold still: {reason}", refresh=False)
            progress.set_postfix_str(quality(source.parser), refresh=False)
            if elapsed > NODE_WAIT_S and not set(assembler.node_ids) <= set(source.parser.nodes):
                raise BomiError(f"{source.url}: no frames from every node id {list(assembler.node_ids)} within "
                                f"{NODE_WAIT_S:g} s (frames came from {sorted(source.parser.nodes) or 'none'}); "
                                "nothing recorded")
            if elapsed > timeout_s:
                index, node_gate = next((i, g) for i, g in gate.node.items() if g.verdict(elapsed) is not None)
                raise BomiError(f"{source.url}: node {index} did not settle in {timeout_s:g} s "
                                f"({unsettled(node_gate, elapsed)}); nothing recorded")
    except StreamLost as exc:
        raise BomiError(f"{exc}; nothing recorded") from None


def timed_rows(batches: Iterator[tuple[float, list[ImuFrame]]], assembler: RowAssembler, source: SerialSource,
                progress: tqdm) -> Iterator[tuple[float, dict[int, ImuFrame]]]:
    """(sample time, complete row), see :func:`sample_times`. The rows of the first batch are all timed at
    its arrival: the protocol's first prompt is shown then, and the recording's clock never runs ahead of
    the one the prompts are shown by."""
    started, last = False, -np.inf
    for elapsed, frames in batches:
        complete = [row for row in map(assembler.push, frames) if row is not None]
        times = sample_times(elapsed, len(complete), last if started else elapsed)
        for t, row in zip(times, complete):
            started, last = True, t
            yield t, row
        progress.set_postfix_str(quality(source.parser), refresh=False)


def record_segments(writer: RecordingWriter, timed_rows: Iterable[tuple[float, dict[int, ImuFrame]]],
                     segments: list[Cue], rows: FusedRows, start: float, progress: tqdm) -> None:
    """Label the rows by the segment they fall in; a segment is written once complete."""
    k, pending = 0, []
    tqdm.write(segments[0].prompt, file=sys.stderr)
    for elapsed, row in timed_rows:
        t = elapsed - start
        while k < len(segments) and t >= segments[k].end_s:
            for sample_time, samples in pending:
                writer.append(sample_time, samples, segments[k].label)
            writer.flush()
            pending, k = [], k + 1
            if k < len(segments):
                tqdm.write(segments[k].prompt, file=sys.stderr)
        if k == len(segments):
            return
        pending.append((t, rows.samples(row)))
        progress.set_description_str(cue_text(segments, k, t), refresh=False)
        progress.update(int(t) - progress.n)
