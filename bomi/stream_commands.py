"""`bomi emulate` and `bomi capture`: the live IMU stream on the command line."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path

from tqdm import tqdm

from bomi.emulator import EmulatorConfig, EmulatorStats, frame_chunks, open_sink, play, raw_samples
from bomi.errors import BomiError
from bomi.frames import ImuFrame, RowAssembler, imu_index, imu_node_id
from bomi.fusion import NodeCalibration, NodeFusion
from bomi.profiles import load_profile
from bomi.recording import NodeSample, RecordingWriter, read_recording
from bomi.serial_source import BASE_STATION_BAUD, RetryPolicy, SerialSource

# After the first IMU frame, how long capture listens to learn which nodes are on the stream.
NODE_DETECTION_S = 0.5
ROWS_PER_FLUSH = 62  # about one second of samples


def register(subparsers: argparse._SubParsersAction) -> None:
    emulate = subparsers.add_parser(
        "emulate", help="play a recording as base-station frames onto a pty, socket or port",
        description="Play a recording's raw samples as base-station frames at the real rate. "
                    "With --to pty the pseudo-terminal's path is printed on stdout.")
    emulate.add_argument("--recording", required=True, type=Path, help="recording (.csv) with whole raw values")
    emulate.add_argument("--to", required=True, metavar="PORT_OR_URL",
                         help="'pty', socket://HOST:PORT (listens for one client), or a port / pyserial URL")
    emulate.add_argument("--rate", type=float, default=62.5, help="samples per second per node (default 62.5)")
    emulate.add_argument("--loss", type=float, default=0.0, help="probability of dropping a frame (real: 0.09)")
    emulate.add_argument("--corrupt", type=float, default=0.0, help="probability of altering a byte")
    emulate.add_argument("--seed", type=int, default=0, help="seed of loss and corruption")
    emulate.add_argument("--duration", type=float, help="stop after this many seconds of recording")
    emulate.add_argument("--linger", type=float, default=5.0,
                         help="pty: after the end, wait up to this many seconds for the reader to close")
    emulate.add_argument("--baud", type=int, default=BASE_STATION_BAUD, help="baud rate of a real port")
    emulate.set_defaults(func=run_emulate)

    capture = subparsers.add_parser(
        "capture", help="record what a base-station stream carries, without prompts",
        description="Record raw frames per node (and their fused angles) into a recording CSV.")
    capture.add_argument("--port", required=True, metavar="PORT_OR_URL",
                         help="serial port, pty path or pyserial URL (socket://, loop://)")
    capture.add_argument("--duration", required=True, type=float, help="seconds to record")
    capture.add_argument("--out", required=True, type=Path, help="recording to write (.csv, must not exist)")
    capture.add_argument("--nodes", type=_node_list, help="IMU node indices, e.g. 1,2,3 (default: those on the stream)")
    capture.add_argument("--profile", help="profile whose node calibrations fuse the angles (default: headset "
                                           "calibration for node 1, none for the others)")
    capture.add_argument("--baud", type=int, default=BASE_STATION_BAUD)
    capture.add_argument("--retries", type=int, default=RetryPolicy.attempts,
                         help="reconnection attempts after the stream is lost")
    capture.set_defaults(func=run_capture)


def _node_list(text: str) -> tuple[int, ...]:
    try:
        nodes = tuple(sorted({int(part) for part in text.split(",")}))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected node indices like 1,2,3, got {text!r}") from None
    if not all(1 <= i <= 6 for i in nodes):
        raise argparse.ArgumentTypeError(f"node indices are 1..6, got {text!r}")
    return nodes


# ------------------------------------------------------------------------------------ emulate
def run_emulate(args: argparse.Namespace) -> int:
    config = EmulatorConfig(rate_hz=args.rate, loss=args.loss, corrupt=args.corrupt, seed=args.seed)
    raw = raw_samples(read_recording(args.recording))
    if args.duration is not None:
        samples = max(1, int(args.duration * config.rate_hz))
        raw = {index: values[:samples] for index, values in raw.items()}
    samples = len(next(iter(raw.values())))
    sink = open_sink(args.to, args.linger)
    print(sink.description, flush=True)
    _note(f"emulate: {args.recording}: {len(raw)} node(s), {samples} samples at {config.rate_hz:g} Hz "
          f"-> {sink.description}; waiting for a reader")
    sink.wait_for_reader()
    stats = EmulatorStats()
    chunks = tqdm(frame_chunks(raw, config, stats), total=samples, unit="sample", disable=None, file=sys.stderr)
    completed = play(iter(chunks), sink)
    chunks.close()
    _note(f"emulate: {'end of recording' if completed else 'the reader went away'}: {stats.samples} samples, "
          f"{stats.frames_sent} frames sent, {stats.frames_dropped} dropped, {stats.bytes_corrupted} bytes corrupted")
    sink.finish()
    return 0


def _note(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------ capture
def _calibrations(profile_name: str | None, indices: tuple[int, ...]) -> dict[int, NodeCalibration]:
    if profile_name is None:
        return {i: NodeCalibration() if i == 1 else NodeCalibration.uncalibrated() for i in indices}
    profile = load_profile(profile_name)
    by_index = {node.index: node.calibration for node in profile.nodes}
    missing = [i for i in indices if i not in by_index]
    if missing:
        raise BomiError(f"{profile.source}: no calibration for node(s) {missing} on the stream")
    return {i: by_index[i] for i in indices}


def _detect_nodes(batches: Iterator[tuple[float, list[ImuFrame]]], url: str,
                  backlog: list[tuple[float, ImuFrame]]) -> tuple[int, ...]:
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


def run_capture(args: argparse.Namespace) -> int:
    if args.out.exists():
        raise BomiError(f"{args.out}: file exists, not overwriting it")
    source = SerialSource(args.port, baudrate=args.baud, retry=RetryPolicy(attempts=args.retries))
    with source, tqdm(total=args.duration, unit="s", disable=None, file=sys.stderr,
                      bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s {postfix}") as progress:
        batches = source.batches(args.duration)
        backlog: list[tuple[float, ImuFrame]] = []
        indices = args.nodes or _detect_nodes(batches, args.port, backlog)
        calibrations = _calibrations(args.profile, indices)
        fusion = {imu_node_id(i): NodeFusion(calibrations[i]) for i in indices}
        assembler = RowAssembler(tuple(fusion))
        last_fused: dict[int, tuple[ImuFrame, tuple[float, float, float]]] = {}

        def fused(frame: ImuFrame) -> tuple[float, float, float]:
            cached = last_fused.get(frame.node_id)
            if cached is None or cached[0] is not frame:
                cached = last_fused[frame.node_id] = (frame, fusion[frame.node_id].update(frame.acc, frame.gyro, frame.mag))
            return cached[1]

        def timed_frames() -> Iterator[tuple[float, ImuFrame]]:
            yield from backlog
            for elapsed, frames in batches:
                progress.update(elapsed - progress.n)
                progress.set_postfix_str(source.parser.summary(), refresh=False)
                yield from ((elapsed, frame) for frame in frames)

        with RecordingWriter(args.out, indices, labelled=False, segment_rows=ROWS_PER_FLUSH) as writer:
            for elapsed, frame in timed_frames():
                row = assembler.push(frame)
                if row is not None:
                    writer.append(elapsed, {imu_index(node_id): NodeSample(f.acc, f.gyro, f.mag, fused(f))
                                            for node_id, f in row.items()})
    print(f"{args.out}: {writer.rows_written} rows of node(s) {list(indices)} in {args.duration:g} s "
          f"({assembler.held} values held over lost frames); {source.parser.summary()}")
    return 0
