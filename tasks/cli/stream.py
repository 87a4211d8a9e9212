"""`bomi emulate`, `bomi capture` and `bomi record`: the live IMU stream on the command line."""
from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi.emulator import EmulatorConfig, EmulatorStats, block_chunks, open_sink, play, raw_samples
from bomi.errors import BomiError
from bomi.frames import SAMPLE_RATE_HZ, RowAssembler, imu_node_id
from bomi.fusion import DT, FusedRows, NodeCalibration, fused_recording, mounting_warnings
from bomi.files import check_output
from bomi.gate import Gate
from bomi.model_io import SUFFIXES, save_model
from bomi.protocol import calibration_schedule
from bomi.recording import RecordingWriter, read_recording
from bomi.serial_source import BASE_STATION_BAUD, RetryPolicy, SerialSource, StreamLost
from tasks.cli import add_command
from tasks.experiments.streams import (SETTLE_WAIT_S, TimedFrame, capture_calibrations, detect_nodes, record_segments,
                                      timed_frames, timed_rows, unfinished, wait_until_settled)
from tasks.experiments.training import class_listing, fit_and_report, read_all_passes
from tasks.cli.options import (add_force, check_outputs, non_negative_int, non_negative_seconds, positive_float,
                               positive_int, probability, seconds)
from tasks.operators.stick import arm_profile

ROWS_PER_FLUSH = 62  # capture: about one second of samples
# emulate --participant: after the protocol's last cue the participant stays in that (neutral)
# posture this long, so that `bomi record`, whose schedule starts a little after the participant's
# (--settle-first: when its gate opens, a few samples after the emulator's estimate), still completes
# its last segment before the stream ends.
PROTOCOL_TAIL_S = 5.0


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


# ------------------------------------------------------------------------------------ capture
def run_capture(args: argparse.Namespace) -> int:
    check_output(args.out, suffixes=(".csv",), what="--out", forceable=False)
    calibrations = None if args.nodes is None else capture_calibrations(args.profile, args.nodes)
    source = SerialSource(args.port, baudrate=args.baud, retry=RetryPolicy(attempts=args.retries))
    with source, tqdm(total=round(args.duration, 1), unit="s", disable=None, file=sys.stderr,
                      bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s {postfix}") as progress:
        batches = source.batches(args.duration)
        backlog: list[TimedFrame] = []
        indices = args.nodes or detect_nodes(batches, args.port, backlog)
        rows = FusedRows(calibrations or capture_calibrations(args.profile, indices))
        assembler = RowAssembler(rows.node_ids)
        with RecordingWriter(args.out, indices, labelled=False, segment_rows=ROWS_PER_FLUSH) as writer:
            try:
                for elapsed, frame in timed_frames(batches, backlog, progress, source.parser):
                    progress.update(round(elapsed - progress.n, 1))
                    row = assembler.push(frame)
                    if row is not None:
                        writer.append(elapsed, rows.samples(row))
            except StreamLost as exc:
                writer.close()
                raise unfinished(exc, writer) from None
    if writer.rows_written == 0:
        args.out.unlink(missing_ok=True)
        raise BomiError(f"{args.port}: no complete row of node(s) {list(indices)} in {args.duration:g} s, nothing "
                        f"recorded, {args.out} not written; {source.parser.summary()}")
    print(f"{args.out}: {writer.rows_written} rows of node(s) {list(indices)} in {args.duration:g} s "
          f"({assembler.held} values held over lost frames); {source.parser.summary()}")
    return 0


# ------------------------------------------------------------------------------------ record
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
        settled = wait_until_settled(batches, Gate(profile.node_indices), rows, assembler, source, progress,
                                     SETTLE_WAIT_S)
        tqdm.write(f"record: every node settled after {settled:.1f} s; the protocol starts", file=sys.stderr)
        rows_in_time = timed_rows(batches, assembler, source, progress)
        start, first_row = next(rows_in_time)
        with RecordingWriter(args.out, profile.node_indices) as writer:
            try:
                record_segments(writer, itertools.chain([(start, first_row)], rows_in_time), segments, rows,
                                start, progress)
            except StreamLost as exc:
                writer.close()
                raise unfinished(exc, writer) from None
    print(f"{args.out}: {writer.rows_written} labelled rows, {len(segments)} segments; {source.parser.summary()}")
    if args.train is not None:
        model = fit_and_report(read_all_passes([args.out], verbose=False), profile, profile.spec)
        save_model(args.train, model, overwrite=args.force)
        print(f"{args.train}: model of profile {profile.name}; {class_listing(profile, model.classes.tolist())}")
    return 0
