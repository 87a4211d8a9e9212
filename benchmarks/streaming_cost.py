"""Per-sample cost of the streaming chain for 3 nodes (P1 profile, FV3 day-1 model), in microseconds.

Replays the raw ACC/GYRO/MAG columns of day 2 through each stage separately (fusion of the three
nodes, window update, FV3 features, LDA decision with post-processing) and through the whole
``OnlineChain.push`` path; reports median and p99 per sample (one sample = one row of all 3 nodes).
Writes benchmarks/results/streaming_cost.md and .json.
"""
from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi.chain import OnlineChain, train
from bomi.classifier import posteriors
from bomi.dataset import data_dir
from bomi.features import WindowBuffer, features
from bomi.fusion import NodeFusion
from bomi.profiles import load_profile
from bomi.recording import read_recording

RESULTS = Path(__file__).resolve().parent / "results"
SAMPLES = 12000
BUDGET_US = {"median": 50.0, "p99": 200.0}


def timed(samples: int, step) -> np.ndarray:
    """Run ``step(k)`` for k in range(samples); per-call wall time in microseconds."""
    clock = time.perf_counter_ns
    out = np.empty(samples)
    for k in tqdm(range(samples), leave=False, mininterval=1.0):
        start = clock()
        step(k)
        out[k] = clock() - start
    return out / 1000.0


def main() -> None:
    profile = load_profile("P1")
    model = train([read_recording(data_dir() / "day1_testp.mat")], profile)
    rec = read_recording(data_dir() / "day2_testp.mat")
    nodes = model.spec.nodes
    raw = {i: (rec.nodes[i].acc.tolist(), rec.nodes[i].gyro.tolist(), rec.nodes[i].mag.tolist()) for i in nodes}
    n = min(SAMPLES, len(rec))

    fusions = {i: NodeFusion(next(c.calibration for c in profile.nodes if c.index == i)) for i in nodes}
    angles = {i: [] for i in nodes}

    def fuse_step(k: int) -> None:
        for i in nodes:
            acc, gyro, mag = raw[i]
            angles[i].append(fusions[i].update(acc[k], gyro[k], mag[k]))

    states = np.hstack([np.hstack([rec.nodes[i].angles, rec.nodes[i].gyro]) for i in nodes])
    components = model.spec.components
    buffer = WindowBuffer(model.spec.window, len(components), model.spec.stride)
    windows = []

    def window_step(k: int) -> None:
        window = buffer.push(states[k, components])
        windows.append(None if window is None else window.copy())

    full: list = []

    def feature_step(k: int) -> None:
        full.append(features(model.spec.kind, windows[k][None]))

    decisions = []

    def decision_step(k: int) -> None:
        prob = posteriors(model, full[k])[0]
        best = int(prob.argmax())
        decisions.append((int(model.classes[best]), float(prob[best])))

    chain = OnlineChain(model, profile)
    order = list(nodes[1:]) + [nodes[0]]

    def chain_step(k: int) -> None:
        for i in order:
            acc, gyro, mag = raw[i]
            chain.push(i, acc[k], gyro[k], mag[k])

    stages = {"fusion (3 nodes)": timed(n, fuse_step), "window update": timed(n, window_step)}
    first = model.spec.window - 1
    windows[:] = windows[first:]
    stages["FV3 features"] = timed(n - first, feature_step)
    stages["LDA decision"] = timed(n - first, decision_step)
    stages["whole chain: OnlineChain.push x 3"] = timed(n, chain_step)[first:]

    rows = {name: {"median_us": float(np.median(t)), "p99_us": float(np.percentile(t, 99)), "samples": int(t.size)}
            for name, t in stages.items()}
    total = rows["whole chain: OnlineChain.push x 3"]
    record = {"nodes": len(nodes), "features": model.spec.kind, "n_features": int(model.coef.shape[1]),
              "classes": int(len(model.classes)), "budget_us": BUDGET_US, "stages": rows,
              "meets_budget": total["median_us"] <= BUDGET_US["median"] and total["p99_us"] <= BUDGET_US["p99"],
              "machine": {"python": platform.python_version(), "processor": platform.machine(),
                          "numpy": np.__version__, "cpus": os.cpu_count(),
                          "load_average_1min_after_run": os.getloadavg()[0]}}
    lines = ["| stage (per sample of 3 nodes) | median (us) | p99 (us) | samples |", "|---|---|---|---|"]
    lines += [f"| {name} | {r['median_us']:.1f} | {r['p99_us']:.1f} | {r['samples']} |" for name, r in rows.items()]
    table = (f"Streaming cost, P1 profile, {model.spec.kind} ({record['n_features']} features, "
             f"{record['classes']} classes), day-2 raw columns replayed; budget median <= 50 us, p99 <= 200 us "
             f"for the whole chain: {'met' if record['meets_budget'] else 'NOT met'} "
             f"(machine load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs).\n\n" + "\n".join(lines) + "\n")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "streaming_cost.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / "streaming_cost.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
