"""The live loop's safety bars end to end (`python benchmarks/faults.py live`): neutral hold, a lost stream,
bad sensors, corrupted bytes, a flood, filming."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bomi.chain import OnlineChain, train
from bomi.classifier import NEUTRAL_LABEL
from bomi.emulator import EmulatorConfig, EmulatorStats, PtySink, block_chunks, play
from bomi.model_io import load_model, save_model
from bomi.protocol import Cue
from bomi.serial_source import SerialSource, StreamReader
from sim.env import ArmSim
from tasks.operators.stick import arm_profile, profile_layout
from tasks.participants.participant import calibration_session, load_participant, session_recording
from tasks.participants.wire import participant_blocks, session_heading
from tasks.trials.live import LiveLoop


# ================================================================================= live
# The live loop's safety bars (issue 27), measured end to end: a virtual participant's raw samples as
# base-station frames on a pseudo-terminal -> StreamReader -> LiveLoop -> the simulated arm.
#
#     python benchmarks/faults.py live --seeds 11000 [--participants P1 P4] [--out benchmarks/results/live_safety.md]
#
# Per seed and participant: the participant is calibrated (a model trained on their own calibration
# session of that seed, as `bomi record --train` would give), then sits facing the seed's heading:
# - neutral: holds the neutral posture 40 s; share of ticks with the arm at rest after warm-up and calibration;
# - lost: holds F (the arm moving) when the emulator process (`bomi emulate`) is killed; ticks after the
#   last frame, time to rest, and the loop's wall time (start to the reader's end) against its duration;
# - zero / saturated: node 1's frames turn all-zero (or +32767, -32768, a saturated gyroscope) while F is
#   held; time from the tick that read the first such frame to the arm at rest;
# - corrupt: the calibration protocol (every class, B1/B2 included) played clean and with
#   `bomi emulate --corrupt 0.002`, same seed; mode switches of each run (the corrupted run's must all be
#   in the clean one: the same mode within 1.5 s);
# - flood: from 6 s into the F hold the samples come as fast as the pty takes them: the loop's rate,
#   what the status says, and the arm (at rest on every tick of the flood, after its first second);
# - video: `bomi live --video` on the neutral hold: the loop's rate (ticks per second after the first 2 s;
#   the bar: >= 59.5 Hz) and missed periods, beside the same run without --video.
WARM_S = 14.0        # neutral hold before the first motion: the filter settles, then the neutral is taken


def cues_neutral_then(label: int, until_s: float, at_s: float = WARM_S) -> list[Cue]:
    cues = [Cue(NEUTRAL_LABEL, "neutral", 0.0, at_s)]
    if label != NEUTRAL_LABEL:
        cues.append(Cue(label, "motion", at_s, until_s))
    return cues


def class_of(profile, function: str) -> int:
    return next(cls.label for cls in profile.classes if cls.function == function)


def model_for(name: str, seed: int, work: Path) -> Path:
    """The participant's own model: trained on their calibration session of ``seed`` (`bomi record --amplitudes 1 0.5`)."""
    path = work / f"{name}-{seed}.json"
    if not path.exists():
        params, profile = load_participant(name), arm_profile(name)
        session = calibration_session(params, profile, seed, repetitions=1, hold_s=2.0, neutral_s=2.0,
                                      amplitudes=(1.0, 0.5))   # full and half motions: nu spans the range
        save_model(path, train([session_recording(session, profile)], profile))
    return path


def at_rest(record: dict) -> bool:
    return not any(record["linear"]) and not any(record["angular"]) and record["finger"] == 0


def run_in_process(name: str, seed: int, model: Path, blocks, duration_s: float,
                   flood_from_s: float | None = None) -> list[dict]:
    """Play ``blocks`` on a pty and run the live loop on it; every tick's record with its frames' raw values.
    ``flood_from_s``: from then on the samples are sent as fast as the pty takes them."""
    sink = PtySink(linger_s=1.0)
    chunks = block_chunks(blocks, EmulatorConfig(seed=seed), EmulatorStats())
    if flood_from_s is not None:
        chunks = ((min(t, flood_from_s), data) for t, data in chunks)
    thread = threading.Thread(target=lambda: (sink.wait_for_reader(), play(chunks, sink), sink.finish()), daemon=True)
    thread.start()
    records, _ = live_on(sink.description, name, model, duration_s)
    thread.join(timeout=5)
    return records


def live_on(port: str, name: str, model: Path, duration_s: float) -> tuple[list[dict], float]:
    """The live loop on ``port`` for ``duration_s``: every tick's record (with its frames' raw values),
    and the wall time from the loop's start to the reader's end."""
    profile = arm_profile(name)
    sim = ArmSim(layout=profile_layout(profile))
    records: list[dict] = []

    def observe(tick) -> None:
        record = tick.record()
        record["raw"] = [list(frame.mag + frame.gyro + frame.acc) for frame in tick.imu]
        records.append(record)

    loop = LiveLoop(OnlineChain(load_model(model), profile), sim, observers=[observe])
    reader = StreamReader(SerialSource(port, log=lambda message: None))
    with reader:
        start = time.monotonic()
        loop.run(reader, duration_s=duration_s)
    wall = time.monotonic() - start
    sim.close()
    return records, wall


def live_cli(port: str, name: str, model: Path, log: Path, duration_s: float, *extra: str) -> float:
    """`bomi live` in a subprocess; its wall time."""
    start = time.monotonic()
    subprocess.run([sys.executable, "-m", "tasks.cli", "live", "--port", port, "--profile", name, "--model",
                    str(model), "--headless", "--duration", f"{duration_s:g}", "--log", str(log), *extra],
                   check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.monotonic() - start


def emulator(name: str, seed: int, *extra: str) -> tuple[subprocess.Popen, str]:
    process = subprocess.Popen([sys.executable, "-m", "tasks.cli", "emulate", "--participant", name, "--to", "pty",
                                "--seed", str(seed), *extra], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               text=True)
    return process, process.stdout.readline().strip()


def read_log(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


# ------------------------------------------------------------------------------------------ bars
def neutral_bar(name: str, seed: int, model: Path) -> dict:
    params, profile = load_participant(name), arm_profile(name)
    blocks = participant_blocks(params, profile, seed, cues_neutral_then(NEUTRAL_LABEL, 0.0, 40.0), 40.0)
    records = run_in_process(name, seed, model, blocks, 38.0)
    calibrated = next(k for k, r in enumerate(records) if "neutral" in r)
    after = records[calibrated + 1:]
    return {"ticks": len(after), "rest": float(np.mean([at_rest(r) for r in after])),
            "warm_s": max(r["t"] for r in records if (r["hold"] or "").startswith("warming")),
            "neutral_s": records[calibrated]["t"]}


def bad_values_bar(name: str, seed: int, model: Path, bad: str, inject_s: float = WARM_S + 6.0) -> dict:
    """Node 1's frames replaced by ``bad`` values from ``inject_s`` (emulator time) while F is held."""
    params, profile = load_participant(name), arm_profile(name)
    values = {"zero": [0] * 9, "+32767": [32767] * 9, "-32768": [-32768] * 9}
    blocks = participant_blocks(params, profile, seed, cues_neutral_then(class_of(profile, "F"), 40.0), 30.0)

    def spoiled():
        t = 0
        for block in blocks:
            rows = len(next(iter(block.values())))
            times = (t + np.arange(rows)) * 0.016
            node1 = block[1].copy()
            hit = times >= inject_s
            if bad == "gyro saturated":
                node1[hit, 3:6] = 32767
            else:
                node1[hit] = values[bad]
            block = {**block, 1: node1}
            t += rows
            yield block

    records = run_in_process(name, seed, model, spoiled(), 27.0)
    first = next(k for k, r in enumerate(records) if any(
        (raw[3:6] == [32767] * 3) if bad == "gyro saturated" else raw == values[bad] for raw in r["raw"]))
    moving = not at_rest(records[first - 1])
    rest = next(k for k in range(first, len(records)) if at_rest(records[k]))
    still = all(at_rest(r) for r in records[rest:])
    return {"moving_before": moving, "rest_after_s": records[rest]["t"] - records[first]["t"],
            "held_to_end": still, "hold": records[rest]["hold"]}


def lost_bar(name: str, seed: int, model: Path, duration_s: float = 26.0) -> dict:
    process, port = emulator(name, seed, "--neutral", f"{WARM_S:g}", "--hold", "30")   # F from WARM_S on
    killer = threading.Timer(WARM_S + 8.0, process.kill)
    killer.start()
    ticks, wall = live_on(port, name, model, duration_s)
    killer.cancel()
    process.kill()
    last = max(k for k, r in enumerate(ticks) if r["frames"])
    moving = not at_rest(ticks[last])
    rest = next(k for k in range(last, len(ticks)) if at_rest(ticks[k]))
    gaps = np.diff([r["t"] for r in ticks[last:]])
    return {"moving_at_loss": moving, "rest_after_s": ticks[rest]["t"] - ticks[last]["t"],
            "ticks_after": len(ticks) - last - 1, "max_tick_gap_s": float(gaps.max()) if len(gaps) else 0.0,
            "all_rest_after": all(at_rest(r) for r in ticks[rest:]), "wall_s": wall, "duration_s": duration_s}


def flood_bar(name: str, seed: int, model: Path, flood_s: float = WARM_S + 6.0) -> dict:
    """From ``flood_s`` on (F held) the participant's samples arrive as fast as the pty takes them."""
    params, profile = load_participant(name), arm_profile(name)
    blocks = participant_blocks(params, profile, seed, cues_neutral_then(class_of(profile, "F"), 3000.0), 3000.0)
    records = run_in_process(name, seed, model, blocks, flood_s + 6.0, flood_from_s=flood_s)
    before = [r for r in records if flood_s - 3 < r["t"] < flood_s]
    during = [r for r in records if r["t"] > flood_s + 1.0]
    rate = (len(during) - 1) / (during[-1]["t"] - during[0]["t"])
    per_node = sum(r["frames"] for r in during) / (during[-1]["t"] - during[0]["t"]) / len(profile.nodes)
    return {"moving_before": any(not at_rest(r) for r in before), "rate_hz": rate, "frames_hz": per_node,
            "rest": float(np.mean([at_rest(r) for r in during])),
            "holds": sorted({r["hold"] for r in during if r["hold"]})[:2],
            "status_rate_hz": min(r["loop_hz"] for r in during)}


def switches(ticks: list[dict]) -> list[tuple[float, str]]:
    return [(b["t"], b["mode"]) for a, b in zip(ticks, ticks[1:]) if a["mode"] != b["mode"]]


def corrupt_bar(name: str, seed: int, model: Path, work: Path, duration_s: float = 75.0) -> dict:
    runs = {}
    for corrupt in ("0", "0.002"):
        process, port = emulator(name, seed, "--neutral", "3", "--hold", "3", "--corrupt", corrupt)
        log = work / f"corrupt-{corrupt}-{name}-{seed}.jsonl"
        log.unlink(missing_ok=True)
        live_cli(port, name, model, log, duration_s)
        process.kill()
        ticks = read_log(log)
        runs[corrupt] = {"switches": switches(ticks), "held": float(np.mean([r["hold"] is not None for r in ticks]))}
    clean = runs["0"]["switches"]
    extra = [(t, mode) for t, mode in runs["0.002"]["switches"]
             if not any(m == mode and abs(t - u) <= 1.5 for u, m in clean)]
    return {"clean": len(clean), "corrupt": len(runs["0.002"]["switches"]), "extra": len(extra),
            "held_clean": runs["0"]["held"], "held_corrupt": runs["0.002"]["held"]}


def loop_rate(ticks: list[dict], after_s: float = 2.0) -> tuple[float, int, float]:
    """Ticks per second after the first ``after_s``, periods missed, lowest 1-s rate."""
    t = np.array([r["t"] for r in ticks])
    steady = t > after_s
    return (float((steady.sum() - 1) / (t[steady][-1] - t[steady][0])), ticks[-1]["overruns"],
            min(r["loop_hz"] for r in ticks if r["t"] > after_s))


def video_bar(name: str, seed: int, model: Path, work: Path, duration_s: float = 25.0) -> dict:
    """The loop's rate with --video, and without it on the same stream (the machine's own share)."""
    out = {}
    for filmed in (False, True):
        process, port = emulator(name, seed, "--neutral", "30", "--hold", "2")
        log, video = work / f"video-{filmed}-{name}-{seed}.jsonl", work / f"video-{name}-{seed}.mp4"
        log.unlink(missing_ok=True)
        video.unlink(missing_ok=True)
        live_cli(port, name, model, log, duration_s, *(("--video", str(video)) if filmed else ()))
        process.kill()
        out[filmed] = loop_rate(read_log(log))
    return {"rate_hz": out[True][0], "overruns": out[True][1], "min_loop_hz": out[True][2],
            "plain_rate_hz": out[False][0], "plain_overruns": out[False][1],
            "film_bytes": video.stat().st_size if video.exists() else 0}


Row = tuple[str, str, bool]   # bar, measured, met


def neutral_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = neutral_bar(name, seed, model)
    return [("neutral hold: arm at rest after calibration", f"{100 * r['rest']:.1f} % of {r['ticks']} ticks "
             f"(settled at {r['warm_s']:.1f} s, neutral at {r['neutral_s']:.1f} s)", r["rest"] >= 0.95)]


def bad_rows(name: str, seed: int, model: Path) -> list[Row]:
    rows = []
    for bad in ("zero", "+32767", "-32768", "gyro saturated"):
        r = bad_values_bar(name, seed, model, bad)
        rows.append((f"node 1 {bad}: arm at rest after the first such frame",
                     f"{1000 * r['rest_after_s']:.0f} ms (moving before: {r['moving_before']}, held to the end: "
                     f"{r['held_to_end']}, status: {r['hold']})",
                     r["rest_after_s"] <= 0.1 and r["moving_before"] and r["held_to_end"]))
    return rows


def flood_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = flood_bar(name, seed, model)
    return [("flood (samples as fast as the pty takes them): not silent, arm at rest",
             f"{r['frames_hz']:.0f} frames/s per node; loop {r['rate_hz']:.1f} Hz (status and log say "
             f"{r['status_rate_hz']:.0f} Hz at the lowest), arm at rest {100 * r['rest']:.0f} % of the "
             f"flood's ticks (moving before: {r['moving_before']}), status: {'; '.join(r['holds'])}",
             r["rest"] == 1.0 and r["moving_before"])]


def lost_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = lost_bar(name, seed, model)
    return [("emulator killed: ticks go on, rest, --duration kept",
             f"rest {1000 * r['rest_after_s']:.0f} ms after the last frame (moving: {r['moving_at_loss']}), "
             f"{r['ticks_after']} ticks after it (largest gap {1000 * r['max_tick_gap_s']:.0f} ms), "
             f"wall {r['wall_s']:.1f} s for --duration {r['duration_s']:g}",
             r["rest_after_s"] <= 0.1 and r["moving_at_loss"] and r["all_rest_after"]
             and r["max_tick_gap_s"] < 0.1 and abs(r["wall_s"] - r["duration_s"]) <= 1.0)]


def corrupt_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = corrupt_bar(name, seed, model, model.parent)
    return [("--corrupt 0.002: mode switches the clean stream does not have",
             f"{r['extra']} (clean {r['clean']} switches, corrupted {r['corrupt']}; arm held "
             f"{100 * r['held_clean']:.0f} % / {100 * r['held_corrupt']:.0f} % of ticks)", r["extra"] == 0)]


def video_rows(name: str, seed: int, model: Path) -> list[Row]:
    r = video_bar(name, seed, model, model.parent)
    return [("live --video: control rate",
             f"{r['rate_hz']:.2f} Hz, {r['overruns']} periods missed, lowest 1-s rate {r['min_loop_hz']:.0f} Hz "
             f"(film {r['film_bytes']} bytes; without --video: {r['plain_rate_hz']:.2f} Hz, "
             f"{r['plain_overruns']} missed)", r["rate_hz"] >= 59.5)]


# bar -> (rows, for every participant or the first only)
BARS = {"neutral": (neutral_rows, True), "bad": (bad_rows, True), "flood": (flood_rows, False),
        "lost": (lost_rows, False), "corrupt": (corrupt_rows, False), "video": (video_rows, False)}


def run_live(seeds: list[int], participants: list[str], bars: list[str], out: Path) -> None:
    """The live loop's safety bars, end to end."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for seed in seeds:
            for name in participants:
                model = model_for(name, seed, work)
                heading = session_heading(seed)
                print(f"{name} seed {seed} (heading {heading:.0f} deg)", file=sys.stderr, flush=True)
                for bar in bars:
                    function, everyone = BARS[bar]
                    if everyone or name == participants[0]:
                        for row in function(name, seed, model):
                            rows.append((name, seed, *row))
                            print(rows[-1], file=sys.stderr, flush=True)
    lines = [f"# Live loop safety (`python benchmarks/faults.py live --seeds {' '.join(map(str, seeds))} "
             f"--participants {' '.join(participants)}`)", "",
             f"Machine: {os.cpu_count()} cores, shared. Every run is real time (62.5 Hz frames on a pty, 60 Hz ticks).", "",
             "| participant | seed | bar | measured | met |", "|---|---|---|---|---|"]
    lines += [f"| {n} | {s} | {bar} | {value} | {'yes' if ok else 'NO'} |" for n, s, bar, value, ok in rows]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
