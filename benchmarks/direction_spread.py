"""How far P1's lone motions are turned in training (profile ``[classifier] direction_spread``), chosen
leave-one-day-out.

For every spread of the grid, a model is trained on each of P1's five days (P1's other settings as
shipped) and tested on every other day (20 ordered pairs). For each test day the spread is chosen
on the other four days alone: the best mean accuracy over the 12 ordered pairs among them (the
smallest spread on a tie); the test day is never looked at. With ``--cv`` it also reports the
cross-validation within each training day (whole holds held out, ``bomi.chain.cross_validate``) for
every spread (what the training day alone says). Writes benchmarks/results/direction_spread.{md,json}.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi.chain import Candidate, cross_validate, evaluate, train
from bomi.dataset import data_dir
from bomi.profiles import load_profile
from bomi.reproduce import DAYS, read_days

RESULTS = Path(__file__).resolve().parent / "results"
SPREADS = (0.0, 15.0, 30.0, 45.0, 60.0)   # degrees; fixed before any choice was made


def pair_matrix(recordings: dict, profile) -> dict[tuple[int, int], float]:
    out = {}
    for a in DAYS:
        model = train([recordings[a]], profile)
        out.update({(a, b): evaluate(model, recordings[b], profile.neutral_samples).accuracy for b in DAYS if b != a})
    return out


def choose_per_test_day(matrices: dict[float, dict]) -> dict[int, float]:
    """Test day -> the spread with the best mean accuracy over the ordered pairs of the other days."""
    chosen = {}
    for test in DAYS:
        others = [d for d in DAYS if d != test]
        score = {s: np.mean([m[(a, b)] for a in others for b in others if a != b]) for s, m in matrices.items()}
        chosen[test] = max(SPREADS, key=lambda s: (score[s], -s))
    return chosen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cv", action="store_true", help="also the whole-hold CV within each training day (slow)")
    args = parser.parse_args()
    shipped = load_profile("P1")
    recordings = read_days(data_dir())
    matrices = {s: pair_matrix(recordings, replace(shipped, direction_spread=s))
                for s in tqdm(SPREADS, desc="spreads", unit="spread")}
    chosen = choose_per_test_day(matrices)
    picked = {(a, b): matrices[chosen[b]][(a, b)] for a in DAYS for b in DAYS if a != b}
    cv = {}
    if args.cv:
        setting = Candidate(shipped.shrinkage, shipped.amplitude_scales)
        for day in tqdm(DAYS, desc="whole-hold CV", unit="day"):
            cv[day] = {s: cross_validate([recordings[day]], replace(shipped, direction_spread=s), shipped.spec,
                                         [setting])[0].accuracy for s in SPREADS}
    lines = ["Command: `python benchmarks/direction_spread.py" + (" --cv" if args.cv else "") + "`.", "",
             f"P1 (shrinkage {shipped.shrinkage}), lone motions (c7, c8) also trained turned by +-spread degrees. "
             "Accuracy (%) over all 20 ordered day pairs, and the day-1 model on days 2..5.", "",
             "| spread (deg) | mean of 20 pairs | worst pair | day-1 model on days 2, 3, 4, 5 |", "|---|---|---|---|"]
    for s, m in matrices.items():
        worst = min(m, key=m.get)
        lines.append(f"| {s:g} | {100 * np.mean(list(m.values())):.2f} | {100 * m[worst]:.2f} ({worst[0]} -> {worst[1]}) | "
                     + ", ".join(f"{100 * m[(1, b)]:.2f}" for b in DAYS[1:]) + " |")
    worst = min(picked, key=picked.get)
    lines += ["", "Chosen leave-one-day-out (each test day: best mean over the 12 pairs of the other four days): "
              + ", ".join(f"day {d}: {s:g}" for d, s in chosen.items())
              + f". Those choices on their test days: mean {100 * np.mean(list(picked.values())):.2f}, worst "
              f"{100 * picked[worst]:.2f} ({worst[0]} -> {worst[1]}).", ""]
    lines += ["| test day left out | " + " | ".join(f"{s:g}" for s in SPREADS) + " |", "|---|" + "---|" * len(SPREADS)]
    for test in DAYS:
        others = [d for d in DAYS if d != test]
        lines.append(f"| {test} | " + " | ".join(
            f"{100 * np.mean([m[(a, b)] for a in others for b in others if a != b]):.2f}" for m in matrices.values()) + " |")
    if cv:
        lines += ["", "Cross-validation within each training day, whole holds held out (%):", "",
                  "| training day | " + " | ".join(f"{s:g}" for s in SPREADS) + " |", "|---|" + "---|" * len(SPREADS)]
        lines += [f"| {d} | " + " | ".join(f"{100 * v:.2f}" for v in row.values()) + " |" for d, row in cv.items()]
    text = "\n".join(lines) + "\n"
    print(text)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "direction_spread.md").write_text(text)
    (RESULTS / "direction_spread.json").write_text(json.dumps({
        "spreads": list(SPREADS),
        "pairs": {f"{s:g}": {f"{a}->{b}": v for (a, b), v in m.items()} for s, m in matrices.items()},
        "chosen_per_test_day": {str(d): s for d, s in chosen.items()},
        "cv": {str(d): {f"{s:g}": v for s, v in row.items()} for d, row in cv.items()}}, indent=1) + "\n")


if __name__ == "__main__":
    main()
