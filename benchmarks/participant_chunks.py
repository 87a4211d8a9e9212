"""What the virtual participant's synthesis costs per chunk, as a BoMI episode asks for it.

    python benchmarks/participant_chunks.py [--seed 952] [--chunks 600] [--repeats 15]

Virtual P1 (task session of ``--seed``, a development seed: 0-999) is asked for its deliveries as
``BomiChannel`` asks: a chunk reaching ``lead_s`` (0.95 of the reaction time) past the current tick
every ~23 ticks of 1/60 s, and three times in between with nothing new; an intent (a random class
and lean, from the seed) is set at 2 % of the ticks.  Reported: CPU microseconds per chunk
(``time.process_time`` around ``deliveries`` only), the least of the repeats (the least disturbed
on a shared machine) and their median, and a SHA-256 of every delivery (frames, arrival times,
node and sample indices) and of the true angles: equal digests at two commits mean the same output
to the bit.  Writes benchmarks/results/participant_chunks.md.
"""
from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tasks.cli.task import arm_profile
from tasks.participants.participant import VirtualParticipant, load_participant

RESULTS = Path(__file__).resolve().parent / "results"
TICK_S = 1.0 / 60.0


def run(seed: int, chunks: int) -> tuple[float, str]:
    """CPU us per chunk of one run, and the digest of its output."""
    params = load_participant("P1")
    vp = VirtualParticipant(params, arm_profile(params.profile), seed)
    lead_s = 0.95 * params.reaction_s
    ticks = max(1, round(lead_s / TICK_S))
    rng, labels = np.random.default_rng(seed), [0, *sorted(params.classes)]
    digest, spent, t = hashlib.sha256(), 0.0, 0.0
    for _ in range(chunks):
        for k in range(ticks):
            t += TICK_S
            if rng.random() < 0.02:
                label = int(rng.choice(labels))
                vp.set_intent(label, float(rng.uniform(0.2, 1.0)) if label else 0.0, t)
            asks = [t] if k % 8 == 3 else []
            asks += [t + lead_s] if k == ticks - 1 else []
            for t_end in asks:
                started = time.process_time()
                delivery = vp.deliveries(t_end)
                spent += time.process_time() - started
                for array in (delivery.arrival_s, delivery.node_index, delivery.sample_index):
                    digest.update(np.ascontiguousarray(array).tobytes())
                digest.update(delivery.stream())
    digest.update(vp.truth().angles.tobytes())
    return spent / chunks * 1e6, digest.hexdigest()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=952, help="participant seed (development: 0-999)")
    parser.add_argument("--chunks", type=int, default=600, help="chunks per run")
    parser.add_argument("--repeats", type=int, default=15, help="runs (the least is reported)")
    args = parser.parse_args()
    if args.repeats < 1 or args.chunks < 1:
        print("bomi: error: --repeats and --chunks: must be at least 1", file=sys.stderr)
        return 2
    runs = [run(args.seed, args.chunks) for _ in tqdm(range(args.repeats), desc="runs", file=sys.stderr)]
    if len({d for _, d in runs}) != 1:
        print("bomi: error: the runs differ in output", file=sys.stderr)
        return 1
    costs = [c for c, _ in runs]
    text = (f"# Virtual participant per chunk (`python benchmarks/participant_chunks.py --seed {args.seed} "
            f"--chunks {args.chunks} --repeats {args.repeats}`)\n\n"
            "| CPU us/chunk (least) | CPU us/chunk (median) | output SHA-256 |\n|---|---|---|\n"
            f"| {min(costs):.0f} | {statistics.median(costs):.0f} | {runs[0][1][:16]} |\n")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "participant_chunks.md").write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
