"""Frame parser throughput, a fuzz run over a corrupted base-station stream, and the phantom-frame guard.

    python benchmarks/parser_fuzz.py [--fuzz-bytes 1000000] [--noise-bytes 16000000] [--seed 0]

Throughput: frames/s of ``FrameParser.feed`` on clean 3-node streams, fed in 4096-byte chunks
(what a serial read returns under load) and one frame at a time (the live per-sample path).
Fuzz: ~10^6 bytes of interleaved frames (3 IMU nodes, an EMG node, the safety key) with 9 %
frame loss, truncated frames, garbage bursts, stray start bytes and random byte flips, fed in
random chunks of 1..4096 bytes. Counts exceptions (must be 0) and the intact frames recovered
(must be all, except any a false start shadows: a stray 0x33 whose byte 31 happens to be 0x34
passes hardware.md's check, the format having no checksum; they are counted separately).
Phantom-frame guard (bomi.frames): the same fuzz stream parsed with the guard and with the framing
rule alone (``confirm_frames=1``); a delivered IMU frame is a phantom when no transmitted frame of
the same node and counter lies within 4 bytes of it (a real frame with a flipped data byte is not
a phantom: no parser can tell it without a checksum). And uniform random bytes (``--noise-bytes``):
every frame delivered from them is a phantom; false accepts per MB, with and without the guard.
Safety-key guard (bomi.frames): for each of five possible key frame patterns (hardware.md does not
document it), ``--key-presses`` random presses (STANDBY, CONTROL, CALIBRATION, 40..99 periods apart)
with 9 % frame loss: how many presses of an event that lets the arm move act, and after how many
periods; then the same stream with ``--key-phantoms`` well-formed phantom key frames (id 40, CONTROL
or CALIBRATION, every other byte random) at random places: how many act, with and without the guard.
Writes benchmarks/results/parser_fuzz.{md,json}.
"""
from __future__ import annotations

import argparse
import json
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi.frames import (
    FRAME_SIZE, SAFETY_EVENT_BYTE, SAFETY_KEY_NODE_ID, START_BYTE, END_BYTE, FrameParser, ImuFrame, SafetyKey,
    encode_imu_frame, encode_safety_key_frame,
)

RESULTS = Path(__file__).resolve().parent / "results"
IMU_IDS = (10, 11, 12)
EMG_ID = 30
CHUNK = 4096


def random_frames(count: int, rng: np.random.Generator) -> list[bytes]:
    """``count`` IMU frames of nodes 10, 11, 12 interleaved, counters advancing per sample."""
    values = rng.normal(0, 3000, (count, 9)).clip(-32768, 32767).astype(int).tolist()
    return [encode_imu_frame(ImuFrame(IMU_IDS[k % 3], 16, (k // 3) % 256,
                                      tuple(v[0:3]), tuple(v[3:6]), tuple(v[6:9])))
            for k, v in enumerate(values)]


def best_rate(frames: list[bytes], chunk: int, repeats: int = 3) -> float:
    """Best of ``repeats`` runs: frames parsed per second."""
    stream = b"".join(frames)
    pieces = [stream[i:i + chunk] for i in range(0, len(stream), chunk)]
    best = float("inf")
    for _ in range(repeats):
        parser = FrameParser()
        start = time.perf_counter()
        parsed = sum(len(parser.feed(piece)) for piece in pieces)
        best = min(best, time.perf_counter() - start)
        assert parsed == len(frames)
    return len(frames) / best


@dataclass
class FuzzStream:
    data: bytes
    intact: dict[int, bytes]  # offset -> IMU frame that reaches the parser unaltered
    frames_generated: int     # IMU frames generated (sent or lost)
    sent: list[bytes]         # every whole IMU frame put on the wire (before byte flips)


def fuzz_stream(size: int, rng: np.random.Generator) -> FuzzStream:
    """About ``size`` bytes of the base-station stream with every kind of damage."""
    pieces: list[tuple[bytes, bool]] = []  # (bytes, is a whole IMU frame before byte flips)
    total = generated = sample = 0
    while total < size:
        for node_id in (*IMU_IDS, EMG_ID):
            values = rng.normal(0, 3000, 9).astype(int).clip(-32768, 32767).tolist()
            frame = encode_imu_frame(ImuFrame(node_id, 16, sample % 256, tuple(values[0:3]),
                                              tuple(values[3:6]), tuple(values[6:9])))
            generated += node_id != EMG_ID
            fate = rng.random()
            if fate < 0.09:
                continue                                                        # lost on the radio link
            if fate < 0.10:
                frame = frame[:rng.integers(1, FRAME_SIZE)]                     # truncated
            elif fate < 0.11:
                pieces.append((rng.bytes(int(rng.integers(1, 64))), False))     # garbage burst
            elif fate < 0.12:
                pieces.append((b"\x33" + rng.bytes(int(rng.integers(0, 8))), False))  # stray start byte
            pieces.append((frame, node_id != EMG_ID and len(frame) == FRAME_SIZE))
            total += len(frame)
        if rng.random() < 0.01:
            pieces.append((encode_safety_key_frame(SafetyKey.STANDBY, sample % 256), False))
        sample += 1
    data = bytearray(b"".join(p for p, _ in pieces))
    flips = np.flatnonzero(rng.random(len(data)) < 0.001)
    for i, x in zip(flips.tolist(), rng.integers(1, 256, flips.size).tolist()):
        data[i] ^= x
    flipped = np.zeros(len(data) + 1, dtype=int)
    flipped[flips + 1] = 1
    flipped = np.cumsum(flipped)  # flipped[j] - flipped[i]: flips within [i, j)
    intact, offset = {}, 0
    for piece, is_imu in pieces:
        if is_imu and flipped[offset + FRAME_SIZE] == flipped[offset]:
            intact[offset] = piece
        offset += len(piece)
    sent = [piece for piece, is_imu in pieces if is_imu]
    return FuzzStream(bytes(data), intact, generated, sent)


def accepted_offsets(stream: bytes) -> list[int]:
    """Where hardware.md's rule accepts a frame, applied naively to the whole stream."""
    offsets, i = [], 0
    while (i := stream.find(b"\x33", i)) >= 0 and i + FRAME_SIZE <= len(stream):
        if stream[i + FRAME_SIZE - 1] == 0x34:
            offsets.append(i)
            i += FRAME_SIZE
        else:
            i += 1
    return offsets


def phantoms(delivered: list[bytes], sent: list[bytes], max_differing: int = 4) -> int:
    """Delivered frames that are no transmitted frame of the same node and counter (up to a few flipped bytes)."""
    by_key: dict[tuple[int, int], list[bytes]] = {}
    for frame in sent:
        by_key.setdefault((frame[1], frame[3]), []).append(frame)
    exact = set(sent)
    count = 0
    for frame in delivered:
        if frame in exact:
            continue
        near = by_key.get((frame[1], frame[3]), [])
        if not near or min(np.count_nonzero(np.frombuffer(frame, np.uint8) != np.frombuffer(f, np.uint8))
                           for f in near) > max_differing:
            count += 1
    return count


def noise_false_accepts(size: int, rng: np.random.Generator) -> dict:
    """Frames delivered from ``size`` uniform random bytes (all phantoms), framing rule alone vs guard."""
    data = rng.bytes(size)
    counts, key_frames, key_events = {}, {}, {}
    for name, parser in (("framing rule alone", FrameParser(confirm_frames=1)), ("with the guard", FrameParser())):
        counts[name] = sum(len(parser.feed(data[i:i + CHUNK])) for i in range(0, size, CHUNK))
        key_frames[name] = parser.skipped[SAFETY_KEY_NODE_ID]
        key_events[name] = sum(e.event in MOVING_EVENTS for e in parser.safety_events)
    return {"bytes": size, "phantom_frames": counts,
            "phantom_frames_per_mb": {k: v / (size / 1e6) for k, v in counts.items()},
            "phantom_key_frames": key_frames, "phantom_moving_key_events": key_events}


@dataclass(frozen=True)
class KeyPattern:
    """One way the real safety key might send its frames."""

    name: str
    idle_frames: bool             # sends an event-0 frame every period between presses
    frames_per_press: int         # frames carrying the event per press, one per period
    counter_per_sent_frame: bool  # else the counter counts periods, sent or not
    presses_per_event: int = 1    # 2: the user presses twice, DOUBLE_PRESS_PERIODS apart


DOUBLE_PRESS_PERIODS = 8
KEY_PATTERNS = (
    KeyPattern("streams every period, the event in one frame", True, 1, False),
    KeyPattern("sends only while held, the event in 5 frames", False, 5, False),
    KeyPattern("one frame per press, counter counts sent frames", False, 1, True),
    KeyPattern("one frame per press, counter counts periods", False, 1, False),
    KeyPattern("one frame per press, counter counts periods, pressed twice", False, 1, False, 2),
)
MOVING_EVENTS = (SafetyKey.CONTROL, SafetyKey.CALIBRATION)
PHANTOM = -1


@dataclass
class KeyStream:
    frames: list[bytes]   # every one well-formed, so a parser's frame_number is its index here
    press: list[int]      # per frame: the press it belongs to, PHANTOM, or None (idle)
    period: list[int]     # per frame: the period it was sent in (phantoms: their predecessor's)
    events: list[int]     # per press: its event


def key_stream(pattern: KeyPattern, presses: int, rng: np.random.Generator) -> KeyStream:
    """``presses`` random presses sent as ``pattern``, each frame lost with probability 0.09."""
    stream, period, sent = KeyStream([], [], [], []), 0, 0

    def send(event: int, press: int | None) -> None:
        nonlocal sent
        counter = (sent if pattern.counter_per_sent_frame else period) % 256
        sent += 1
        if rng.random() >= 0.09:
            stream.frames.append(encode_safety_key_frame(event, counter))
            stream.press.append(press)
            stream.period.append(period)

    for press in range(presses):
        event = int(rng.choice(list(SafetyKey)[1:]))
        stream.events.append(event)
        for _ in range(int(rng.integers(40, 100))):
            if pattern.idle_frames:
                send(SafetyKey.NONE, None)
            period += 1
        for repeat in range(pattern.presses_per_event):
            for _ in range(pattern.frames_per_press):
                send(event, press)
                period += 1
            if repeat + 1 < pattern.presses_per_event:
                period += DOUBLE_PRESS_PERIODS - pattern.frames_per_press
    return stream


def with_phantoms(stream: KeyStream, count: int, rng: np.random.Generator) -> KeyStream:
    """``stream`` with ``count`` phantom key frames at random places: 0x33, id 40, a moving event in
    byte 14, 0x34, every other byte uniform random (as noise or a shifted real frame's data bytes)."""
    places = np.sort(rng.integers(0, len(stream.frames) + 1, count)).tolist()
    out, k = KeyStream([], [], [], stream.events), 0
    for i in range(len(stream.frames) + 1):
        while k < count and places[k] == i:
            phantom = bytearray(rng.bytes(FRAME_SIZE))
            phantom[0], phantom[1], phantom[-1] = START_BYTE, SAFETY_KEY_NODE_ID, END_BYTE
            phantom[SAFETY_EVENT_BYTE] = MOVING_EVENTS[int(rng.integers(2))]
            out.frames.append(bytes(phantom))
            out.press.append(PHANTOM)
            out.period.append(out.period[-1] if out.period else 0)
            k += 1
        if i < len(stream.frames):
            out.frames.append(stream.frames[i])
            out.press.append(stream.press[i])
            out.period.append(stream.period[i])
    return out


def key_guard_run(stream: KeyStream, parser: FrameParser) -> dict:
    """Presses of a moving event that act (latency in periods from the press's first received frame)
    and phantom frames that act."""
    parser.feed(b"".join(stream.frames))
    first_received: dict[int, int] = {}
    for press, period in zip(stream.press, stream.period):
        if press is not None and press != PHANTOM and stream.events[press] in MOVING_EVENTS:
            first_received.setdefault(press, period)
    acted: dict[int, int] = {}
    phantoms_acted = 0
    for event in parser.safety_events:
        press = stream.press[event.frame_number]
        if press == PHANTOM:
            phantoms_acted += event.event in MOVING_EVENTS
        elif press in first_received:
            acted.setdefault(press, stream.period[event.frame_number] - first_received[press])
    latency = list(acted.values()) or [0]
    return {"moving_presses_received": len(first_received), "moving_presses_acted": len(acted),
            "latency_periods_median": float(np.median(latency)), "latency_periods_max": max(latency),
            "phantoms": stream.press.count(PHANTOM), "phantoms_acted": phantoms_acted,
            "key_events_dropped": parser.key_events_unconfirmed}


def key_guard(presses: int, phantoms: int, rng: np.random.Generator) -> dict:
    """Every pattern, clean and with phantoms, parsed with the guard and with the framing rule alone."""
    out = {}
    for pattern in KEY_PATTERNS:
        clean = key_stream(pattern, presses, rng)
        flooded = with_phantoms(clean, phantoms, rng)
        out[pattern.name] = {
            f"{stream_name}, {parser_name}": key_guard_run(stream, parser())
            for stream_name, stream in (("clean", clean), ("with phantoms", flooded))
            for parser_name, parser in (("framing rule alone", lambda: FrameParser(confirm_frames=1)),
                                        ("with the guard", FrameParser))}
    return out


def run_fuzz(stream: FuzzStream, rng: np.random.Generator, parser: FrameParser | None = None) -> dict:
    parser = parser or FrameParser()
    recovered: list[bytes] = []
    exceptions = 0
    position = 0
    start = time.perf_counter()
    with tqdm(total=len(stream.data), unit="B", unit_scale=True, desc="fuzz") as progress:
        while position < len(stream.data):
            size = int(rng.integers(1, CHUNK + 1))
            try:
                recovered += [encode_imu_frame(f) for f in parser.feed(stream.data[position:position + size])]
            except Exception:  # noqa: BLE001 - counting is the point
                exceptions += 1
            position += size
            progress.update(size)
    seconds = time.perf_counter() - start
    found = set(recovered)
    missed = [offset for offset, frame in stream.intact.items() if frame not in found]
    accepted = accepted_offsets(stream.data)
    starts = np.array(accepted)
    # a missed frame is shadowed when an accepted false start begins within its first 31 bytes' reach
    shadowed = sum(bool(np.any((starts < offset) & (starts > offset - FRAME_SIZE))) for offset in missed)
    return {
        "bytes": len(stream.data),
        "imu_frames_generated": stream.frames_generated,
        "intact_imu_frames": len(stream.intact),
        "intact_frames_recovered": len(stream.intact) - len(missed),
        "intact_frames_missed": len(missed),
        "missed_and_shadowed_by_a_false_start": shadowed,
        "missed_otherwise": len(missed) - shadowed,
        "exceptions": exceptions,
        "frames_accepted_by_parser": parser.frames_accepted,
        "frames_accepted_by_naive_reference": len(accepted),
        "imu_frames_not_delivered_intact": stream.frames_generated - len(stream.intact),
        "lost_packets_counted": parser.total_lost,
        "skipped_frames_by_node": ", ".join(f"{k}: {v}" for k, v in sorted(parser.skipped.items())),
        "safety_key_events": len(parser.safety_events),
        "garbage_bytes": parser.discarded_bytes,
        "imu_frames_delivered": len(recovered),
        "phantom_frames_delivered": phantoms(recovered, stream.sent),
        "frames_dropped_by_the_guard": parser.unconfirmed,
        "imu_frames_per_s": len(recovered) / seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fuzz-bytes", type=int, default=1_000_000)
    parser.add_argument("--noise-bytes", type=int, default=16_000_000)
    parser.add_argument("--key-presses", type=int, default=2000)
    parser.add_argument("--key-phantoms", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)

    clean = random_frames(300_000, rng)
    throughput = {
        f"clean stream, {CHUNK}-byte chunks": best_rate(clean, CHUNK),
        "clean stream, one frame per feed": best_rate(clean[:100_000], FRAME_SIZE),
    }
    stream = fuzz_stream(args.fuzz_bytes, rng)
    chunk_seed = int(rng.integers(2**32))
    fuzz = run_fuzz(stream, np.random.default_rng(chunk_seed))
    unguarded = run_fuzz(stream, np.random.default_rng(chunk_seed), FrameParser(confirm_frames=1))
    throughput["fuzz stream, random 1..4096-byte chunks"] = fuzz.pop("imu_frames_per_s")
    unguarded.pop("imu_frames_per_s")
    guard = {
        "fuzz stream": {name: {k: run[k] for k in ("intact_frames_recovered", "imu_frames_delivered",
                                                    "phantom_frames_delivered", "frames_dropped_by_the_guard")}
                        for name, run in (("framing rule alone", unguarded), ("with the guard", fuzz))},
        "random bytes": noise_false_accepts(args.noise_bytes, rng),
    }
    keys = key_guard(args.key_presses, args.key_phantoms, rng)

    record = {
        "benchmark": "parser_fuzz", "seed": args.seed, "python": platform.python_version(),
        "machine": platform.machine(), "throughput_frames_per_s": throughput, "fuzz": fuzz, "phantom_guard": guard,
        "safety_key_guard": keys,
        "needed_frames_per_s": 6 * 62.5,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "parser_fuzz.json").write_text(json.dumps(record, indent=2) + "\n")
    lines = ["# Frame parser: throughput and fuzz", "",
             f"Python {record['python']} on {record['machine']}, seed {args.seed}. "
             f"A full network needs {record['needed_frames_per_s']:g} frames/s (6 nodes x 62.5 Hz).", "",
             "| feed | frames/s |", "|---|---:|"]
    lines += [f"| {name} | {rate:,.0f} |" for name, rate in throughput.items()]
    lines += ["", "| fuzz run | value |", "|---|---:|"]
    lines += [f"| {name.replace('_', ' ')} | {value} |" for name, value in fuzz.items()]
    lines += ["", "Lost packets are counted from the counters (hardware.md): a flipped counter byte or a false "
              "frame with an IMU node id makes a jump of up to 255, so under byte corruption the count "
              "exceeds the frames actually not delivered."]
    noise = guard["random bytes"]
    lines += ["", "## Phantom-frame guard", "",
              "A phantom: a delivered IMU frame that is no transmitted frame of its node and counter (a real frame "
              "with up to 4 flipped bytes is not one).", "",
              "| input | parser | intact frames recovered | IMU frames delivered | phantoms delivered | "
              "false-accept rate | dropped by the guard |", "|---|---|---:|---:|---:|---:|---:|"]
    for name, run in guard["fuzz stream"].items():
        rate = run["phantom_frames_delivered"] / run["imu_frames_delivered"]
        lines.append(f"| fuzz stream ({fuzz['bytes']:,} B, {fuzz['intact_imu_frames']} intact frames) | {name} "
                     f"| {run['intact_frames_recovered']} | {run['imu_frames_delivered']} "
                     f"| {run['phantom_frames_delivered']} | {100 * rate:.3f} % of delivered "
                     f"| {run['frames_dropped_by_the_guard']} |")
    for name, count in noise["phantom_frames"].items():
        lines.append(f"| uniform random bytes ({noise['bytes']:,} B) | {name} | - | {count} | {count} "
                     f"| {noise['phantom_frames_per_mb'][name]:.3f} per MB | - |")
    lines += [f"| uniform random bytes ({noise['bytes']:,} B) | {name}, safety key | - | "
              f"{noise['phantom_key_frames'][name]} key frames | {noise['phantom_moving_key_events'][name]} "
              f"CONTROL/CALIBRATION events | - | - |" for name in noise["phantom_frames"]]
    lines += ["", "## Safety-key guard", "",
              f"{args.key_presses} presses per pattern (STANDBY, CONTROL, CALIBRATION at random, 40..99 periods "
              f"apart, 9 % of key frames lost); 'moving': CONTROL or CALIBRATION. Then the same stream with "
              f"{args.key_phantoms:,} phantom key frames (id 40, CONTROL or CALIBRATION, other bytes random) at "
              "random places. Latency: periods from a press's first received frame to the frame that acts.", "",
              "| key pattern | parser | moving presses acted (clean) | latency median / max (periods) | "
              "moving presses acted (with phantoms) | phantoms acted | phantom acceptance |",
              "|---|---|---:|---:|---:|---:|---:|"]
    for pattern, runs in keys.items():
        for name in ("framing rule alone", "with the guard"):
            clean, flooded = runs[f"clean, {name}"], runs[f"with phantoms, {name}"]
            lines.append(
                f"| {pattern} | {name} | {clean['moving_presses_acted']} / {clean['moving_presses_received']} "
                f"| {clean['latency_periods_median']:g} / {clean['latency_periods_max']} "
                f"| {flooded['moving_presses_acted']} / {flooded['moving_presses_received']} "
                f"| {flooded['phantoms_acted']} / {flooded['phantoms']} "
                f"| {100 * flooded['phantoms_acted'] / flooded['phantoms']:.4f} % |")
    (RESULTS / "parser_fuzz.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
