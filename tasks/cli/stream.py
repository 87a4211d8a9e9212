"""`bomi emulate`, `bomi capture` and `bomi record`: the live IMU stream on the command line."""
from __future__ import annotations

import argparse
import itertools
import sys
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi.emulator import EmulatorConfig, EmulatorStats, block_chunks, open_sink, play, raw_samples
from bomi.errors import BomiError
from bomi.frames import SAMPLE_RATE_HZ, FrameParser, ImuFrame, RowAssembler, imu_index, imu_node_id
from bomi.fusion import DT, FusedRows, NodeCalibration, fused_recording, mounting_warnings
from bomi.files import check_output
from bomi.gate import Gate, NodeGate
from bomi.model_io import SUFFIXES, save_model
from bomi.protocol import Cue, calibration_schedule
from bomi.recording import RecordingWriter, read_recording
from bomi.serial_source import BASE_STATION_BAUD, RetryPolicy, SerialSource, StreamLost
from tasks.cli import add_command
from tasks.experiments.training import class_listing, fit_and_report, read_all_passes
from tasks.cli.options import (add_force, check_outputs, non_negative_int, non_negative_seconds, positive_float,
                               positive_int, probability, seconds)
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
ROWS_PER_FLUSH = 62  # capture: about one second of samples
COUNTDOWN_S = 3.0
# emulate --participant: after the protocol's last cue the participant stays in that (neutral)
# posture this long, so that `bomi record`, whose schedule starts a little after the participant's
# (--settle-first: when its gate opens, a few samples after the emulator's estimate), still completes
# its last segment before the stream ends.
PROTOCOL_TAIL_S = 5.0

TimedFrame = tuple[float, ImuFrame]


def register(subparsers: argparse._SubParsersAction) -> None:
    emulate = add_command(
        subparsers, "emulate",
        description="Play a recording's raw samples, or a virtual participant performing the calibration "
                    "protocol of `bomi record` (neutral, then each class held --hold s with --neutral s of "
                    "neutral between, 3 times, then 5 s more of neutral), as base-station frames at the real "
                    "rate. "
                    "With --to pty the pseudo-terminal's path is printed on stdout.")
    what = emulate.add_mutually_exclusive_group(required=True)
    what.add_argument("--recording", type=Path, help="recording (.csv) with whole raw values")
    what.add_argument("--participant", help="virtual participant (P1, P4, P5 or a TOML file)")
    emulate.add_argument("--to", required=True, metavar="PORT_OR_URL",
                         help="'pty', socket://HOST:PORT (listens for one client), or a port / pyserial URL")
    emulate.add_argument("--rate", type=positive_float, default=SAMPLE_RATE_HZ,
                         help="samples per second per node (default %(default)s)")
    emulate.add_argument("--loss", type=probability, default=0.0,
                         help="probability of dropping a frame (default %(default)s; the real link: 0.09)")
    emulate.add_argument("--corrupt", type=probability, default=0.0,
                         help="probability of altering a byte (default %(default)s)")
    emulate.add_argument("--seed", type=non_negative_int, default=0,
                         help="seed of loss, corruption and the participant's session (default %(default)s)")
    emulate.add_argument("--duration", type=seconds,
                         help="stop after this many seconds of recording (default: all of it)")
    emulate.add_argument("--hold", type=seconds, default=5.0,
                         help="--participant: seconds each motion is held (default %(default)s)")
    emulate.add_argument("--neutral", type=seconds, default=5.0,
                         help="--participant: seconds of neutral posture between motions (default %(default)s)")
    emulate.add_argument("--settle-first", action="store_true",
                         help="--participant: hold still first, until a receiver's orientation filters have "
                              "settled (judged on this stream by the gate of `bomi record`), then the protocol: "
                              "what a person does while `bomi record` says 'hold still'. Use it with record")
    emulate.add_argument("--linger", type=non_negative_seconds, default=5.0,
                         help="pty: after the end, wait up to this many seconds for the reader to close "
                              "(default %(default)s)")
    emulate.add_argument("--baud", type=positive_int, default=BASE_STATION_BAUD,
                         help="baud rate of a real port (default %(default)s)")
    emulate.set_defaults(func=run_emulate)

    capture = add_command(
        subparsers, "capture",
        description="Record raw frames per node (and their fused angles) into a recording CSV, as the stream "
                    "carries them from the first frame: no prompts, and unlike `bomi record` no wait for the "
                    "orientation filters to settle (the first ~10 s of angles are the filter's warm-up).")
    _add_stream_arguments(capture)
    capture.add_argument("--duration", required=True, type=seconds, help="seconds to record")
    capture.add_argument("--nodes", type=_node_list, help="IMU node indices, e.g. 1,2,3 (default: those on the stream)")
    capture.add_argument("--profile", help="profile whose node calibrations fuse the angles (default: headset "
                                           "calibration for node 1, none for the others)")
    capture.set_defaults(func=run_capture)

    record = add_command(
        subparsers, "record",
        description="The paper's calibration protocol: neutral, then each class held --hold s with --neutral s "
                    "of neutral between, the whole sequence --repetitions times; --session does 3 sequences. "
                    f"It starts once every node's orientation filter has settled (hold still; about 10 s, at "
                    f"most {SETTLE_WAIT_S:g} s) and its samples are plausible, as `bomi live` does.")
    _add_stream_arguments(record)
    record.add_argument("--profile", required=True, help="profile (name of a shipped one, or a TOML file)")
    record.add_argument("--session", action="store_true", help="a Session of 3 sequences instead of one Sequence")
    record.add_argument("--repetitions", type=positive_int, default=3,
                        help="repetitions of every class in a sequence (default %(default)s)")
    record.add_argument("--amplitudes", type=_amplitude_list, default=(1.0,),
                        help="fractions of the full motion to hold, e.g. 1,0.5 (multi-amplitude; default 1)")
    record.add_argument("--hold", type=seconds, default=5.0, help="seconds each motion is held (default %(default)s)")
    record.add_argument("--neutral", type=seconds, default=5.0,
                        help="seconds of neutral posture between motions (default %(default)s)")
    record.add_argument("--train", type=Path, metavar="MODEL", help="then train the model and write it (.json/.npz)")
    add_force(record)  # --force applies to the --train model; recordings are never replaced
    record.set_defaults(func=run_record)


def _add_stream_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", required=True, metavar="PORT_OR_URL",
                        help="serial port, pty path or pyserial URL (socket://, loop://)")
    parser.add_argument("--out", required=True, type=Path, help="recording to write (.csv, must not exist)")
    parser.add_argument("--baud", type=positive_int, default=BASE_STATION_BAUD,
                        help="baud rate of a real port (default %(default)s)")
    parser.add_argument("--retries", type=non_negative_int, default=RetryPolicy.attempts,
                        help="reconnection attempts after the stream is lost (default %(default)s)")


def _node_list(text: str) -> tuple[int, ...]:
    try:
        nodes = tuple(sorted({int(part) for part in text.split(",")}))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected node indices like 1,2,3, got {text!r}") from None
    if not all(1 <= i <= 6 for i in nodes):
        raise argparse.ArgumentTypeError(f"node indices are 1..6, got {text!r}")
    return nodes


def _amplitude_list(text: str) -> tuple[float, ...]:
    try:
        amplitudes = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected fractions like 1,0.5, got {text!r}") from None
    if not all(0 < a <= 1 for a in amplitudes):
        raise argparse.ArgumentTypeError(f"amplitudes are fractions in (0, 1], got {text!r}")
    return amplitudes


def _note(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------ emulate
def run_emulate(args: argparse.Namespace) -> int:
    if args.settle_first and args.participant is None:
        raise BomiError("--settle-first: only with --participant (a recording is played as it is)")
    config = EmulatorConfig(rate_hz=args.rate, loss=args.loss, corrupt=args.corrupt, seed=args.seed)
    what, nodes, samples, blocks, notes = (_recording_blocks if args.participant is None else _participant_blocks)(args)
    sink = open_sink(args.to, args.linger, args.baud)
    print(sink.description, flush=True)
    for line in notes:   # after the sink opened: a bad --to is the only line then
        _note(f"emulate: {line}")
    _note(f"emulate: {what}: {nodes} node(s), {samples} samples at {config.rate_hz:g} Hz "
          f"-> {sink.description}; waiting for a reader")
    sink.wait_for_reader()
    stats = EmulatorStats()
    chunks = tqdm(block_chunks(blocks, config, stats), total=samples, unit="sample", disable=None, file=sys.stderr)
    completed = play(iter(chunks), sink)
    chunks.close()
    _note(f"emulate: {'end of recording' if completed else 'the reader went away'}: {stats.samples} samples, "
          f"{stats.frames_sent} frames sent, {stats.frames_dropped} dropped, {stats.bytes_corrupted} bytes corrupted")
    sink.finish()
    return 0


RawBlocks = tuple[str, int, int, Iterable[dict[int, np.ndarray]], list[str]]  # what, nodes, samples, blocks, notes


def _recording_blocks(args: argparse.Namespace) -> RawBlocks:
    rec = read_recording(args.recording)
    raw = raw_samples(rec)
    # the receiver fuses these frames with its profile's mounting: say when the default one (a
    # derived profile's without the file's raw signals) gives angles other than the file's own
    defaults = {i: NodeCalibration.default_for(i) for i in rec.node_indices}
    notes = mounting_warnings(rec, fused_recording(rec, defaults), defaults)
    if args.duration is not None:
        samples = max(1, int(args.duration * args.rate))
        raw = {index: values[:samples] for index, values in raw.items()}
    return str(args.recording), len(raw), len(next(iter(raw.values()))), [raw], notes


def _participant_blocks(args: argparse.Namespace) -> RawBlocks:
    """The participant performs the calibration protocol; samples are made while they are played."""
    # here, not at load: capture and record need no participant
    from tasks.participants.wire import delayed, participant_blocks, settled_after
    from tasks.participants.participant import load_participant
    params = load_participant(args.participant)
    profile = arm_profile(params.profile)
    cues = calibration_schedule(profile, hold_s=args.hold, neutral_s=args.neutral)
    what = f"virtual participant {params.name} (seed {args.seed}), calibration protocol"
    if args.settle_first:
        # the receiver's filter decays per sample it gets: with --loss it needs 1 / (1 - loss) as long
        lead_s = settled_after(params, profile, args.seed) / (1.0 - args.loss)
        cues = delayed(cues, lead_s)
        what += f" after {lead_s:.1f} s holding still"
    protocol_s = cues[-1].end_s + PROTOCOL_TAIL_S
    end_s = protocol_s if args.duration is None else min(args.duration, protocol_s)
    what += f", {end_s:g} s"
    return (what, len(profile.nodes), int(end_s / DT) + 1,
            participant_blocks(params, profile, args.seed, cues, end_s), [])


def _timed_frames(batches: Iterator[tuple[float, list[ImuFrame]]], backlog: Sequence[TimedFrame],
                  progress: tqdm, parser: FrameParser) -> Iterator[TimedFrame]:
    yield from backlog
    for elapsed, frames in batches:
        progress.set_postfix_str(_quality(parser), refresh=False)
        yield from ((elapsed, frame) for frame in frames)


def _quality(parser: FrameParser) -> str:
    """Live signal quality, short: per node rate and lost share."""
    return " ".join(f"IMU{imu_index(n)} {s.rate_hz:.0f}Hz {100 * s.loss_fraction:.0f}%lost"
                    for n, s in sorted(parser.nodes.items()))


def _unfinished(exc: StreamLost, writer: RecordingWriter) -> BomiError:
    """The one-line error of a lost stream, saying what became of the recording."""
    if writer.rows_written == 0:
        writer.path.unlink(missing_ok=True)
        return BomiError(f"{exc}; nothing recorded, {writer.path} not written")
    return BomiError(f"{exc}; {writer.path} is partial: it keeps the {writer.rows_written} rows recorded before")


# ------------------------------------------------------------------------------------ capture
def _detect_nodes(batches: Iterator[tuple[float, list[ImuFrame]]], url: str,
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


def _capture_calibrations(profile_name: str | None, indices: tuple[int, ...]) -> dict[int, NodeCalibration]:
    if profile_name is None:
        return {i: NodeCalibration.default_for(i) for i in indices}
    profile = arm_profile(profile_name)
    by_index = {node.index: node.calibration for node in profile.nodes}
    missing = [i for i in indices if i not in by_index]
    if missing:
        raise BomiError(f"{profile.source}: no calibration for node(s) {missing} on the stream")
    return {i: by_index[i] for i in indices}


def run_capture(args: argparse.Namespace) -> int:
    check_output(args.out, suffixes=(".csv",), what="--out", forceable=False)
    calibrations = None if args.nodes is None else _capture_calibrations(args.profile, args.nodes)
    source = SerialSource(args.port, baudrate=args.baud, retry=RetryPolicy(attempts=args.retries))
    with source, tqdm(total=round(args.duration, 1), unit="s", disable=None, file=sys.stderr,
                      bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s {postfix}") as progress:
        batches = source.batches(args.duration)
        backlog: list[TimedFrame] = []
        indices = args.nodes or _detect_nodes(batches, args.port, backlog)
        rows = FusedRows(calibrations or _capture_calibrations(args.profile, indices))
        assembler = RowAssembler(rows.node_ids)
        with RecordingWriter(args.out, indices, labelled=False, segment_rows=ROWS_PER_FLUSH) as writer:
            try:
                for elapsed, frame in _timed_frames(batches, backlog, progress, source.parser):
                    progress.update(round(elapsed - progress.n, 1))
                    row = assembler.push(frame)
                    if row is not None:
                        writer.append(elapsed, rows.samples(row))
            except StreamLost as exc:
                writer.close()
                raise _unfinished(exc, writer) from None
    if writer.rows_written == 0:
        args.out.unlink(missing_ok=True)
        raise BomiError(f"{args.port}: no complete row of node(s) {list(indices)} in {args.duration:g} s, nothing "
                        f"recorded, {args.out} not written; {source.parser.summary()}")
    print(f"{args.out}: {writer.rows_written} rows of node(s) {list(indices)} in {args.duration:g} s "
          f"({assembler.held} values held over lost frames); {source.parser.summary()}")
    return 0


# ------------------------------------------------------------------------------------ record
def _cue(segments: list[Cue], k: int, t: float) -> str:
    """What the terminal shows at time t of segment k: the cue, time left, a countdown to the next."""
    segment = segments[k]
    left = segment.end_s - t
    text = f"[{k + 1}/{len(segments)}] {segment.prompt} ({left:.0f} s)"
    if k + 1 < len(segments) and segments[k + 1].label != segment.label and left <= COUNTDOWN_S:
        text += f" - next: {segments[k + 1].prompt.removeprefix('HOLD ')} in {left:.0f}"
    return text


def sample_times(arrival: float, count: int, previous: float) -> list[float]:
    """Times of ``count`` rows read together at ``arrival``, one sample period apart, the last one at
    ``arrival`` and none before ``previous`` (the last row's time). Rows that come in a bunch because the
    host fell behind (a loaded machine, a pause of the interpreter) were sampled over that stall: timed by
    their arrival, a whole held posture could fall into the next prompt's segment and be labelled with it."""
    return [max(previous, arrival - (count - 1 - i) * DT) for i in range(count)]


def _unsettled(gate: NodeGate, now: float) -> str:
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


def _wait_until_settled(batches: Iterator[tuple[float, list[ImuFrame]]], gate: Gate, rows: FusedRows,
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
            progress.set_postfix_str(_quality(source.parser), refresh=False)
            if elapsed > NODE_WAIT_S and not set(assembler.node_ids) <= set(source.parser.nodes):
                raise BomiError(f"{source.url}: no frames from every node id {list(assembler.node_ids)} within "
                                f"{NODE_WAIT_S:g} s (frames came from {sorted(source.parser.nodes) or 'none'}); "
                                "nothing recorded")
            if elapsed > timeout_s:
                index, node_gate = next((i, g) for i, g in gate.node.items() if g.verdict(elapsed) is not None)
                raise BomiError(f"{source.url}: node {index} did not settle in {timeout_s:g} s "
                                f"({_unsettled(node_gate, elapsed)}); nothing recorded")
    except StreamLost as exc:
        raise BomiError(f"{exc}; nothing recorded") from None


def _timed_rows(batches: Iterator[tuple[float, list[ImuFrame]]], assembler: RowAssembler, source: SerialSource,
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
        progress.set_postfix_str(_quality(source.parser), refresh=False)


def _record_segments(writer: RecordingWriter, timed_rows: Iterable[tuple[float, dict[int, ImuFrame]]],
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
        progress.set_description_str(_cue(segments, k, t), refresh=False)
        progress.update(int(t) - progress.n)


def run_record(args: argparse.Namespace) -> int:
    check_output(args.out, suffixes=(".csv",), what="--out", forceable=False)
    check_outputs({"--train": (args.train, SUFFIXES)}, inputs=[args.out], force=args.force)
    if args.train is not None and args.train.resolve() == args.out.resolve():
        raise BomiError(f"{args.train}: --train and --out name the same file")
    profile = arm_profile(args.profile)
    if any(imu_node_id(node.index) != node.node_id for node in profile.nodes):
        raise BomiError(f"{profile.source}: record expects node_id = 10 + index - 1 (base-station numbering)")
    segments = calibration_schedule(profile, repetitions=args.repetitions, sequences=3 if args.session else 1,
                                    amplitudes=args.amplitudes, hold_s=args.hold, neutral_s=args.neutral)
    rows = FusedRows({node.index: node.calibration for node in profile.nodes})
    source = SerialSource(args.port, baudrate=args.baud, retry=RetryPolicy(attempts=args.retries))
    _note(f"record: {profile.name}: {(len(segments) - 1) // 2} motions, {segments[-1].end_s:.0f} s; "
          "waiting for every node of the profile to settle: hold still")
    with source, tqdm(total=round(segments[-1].end_s), unit="s", disable=None, file=sys.stderr,
                      bar_format="{desc} |{bar}| {postfix}") as progress:
        batches, assembler = source.batches(), RowAssembler(rows.node_ids)
        settled = _wait_until_settled(batches, Gate(profile.node_indices), rows, assembler, source, progress,
                                      SETTLE_WAIT_S)
        tqdm.write(f"record: every node settled after {settled:.1f} s; the protocol starts", file=sys.stderr)
        timed_rows = _timed_rows(batches, assembler, source, progress)
        start, first_row = next(timed_rows)
        with RecordingWriter(args.out, profile.node_indices) as writer:
            try:
                _record_segments(writer, itertools.chain([(start, first_row)], timed_rows), segments, rows,
                                 start, progress)
            except StreamLost as exc:
                writer.close()
                raise _unfinished(exc, writer) from None
    print(f"{args.out}: {writer.rows_written} labelled rows, {len(segments)} segments; {source.parser.summary()}")
    if args.train is not None:
        model = fit_and_report(read_all_passes([args.out], verbose=False), profile, profile.spec)
        save_model(args.train, model, overwrite=args.force)
        print(f"{args.train}: model of profile {profile.name}; {class_listing(profile, model.classes.tolist())}")
    return 0
