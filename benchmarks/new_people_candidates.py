"""Every candidate setting's cross-validation beside its pass-2 accuracy, on synthetic development people.

    python benchmarks/new_people_candidates.py --first-seed 200 --people 100 --name dev200 [--jobs 1]

The diagnostic behind the settings rule of ``bomi.chain.choose_candidate``: per person (trained on
pass 1 with the profile derived from it, tested on pass 2, as ``benchmarks/new_people.py``), every
candidate of ``select_settings`` (each shrinkage of SHRINKAGE_GRID, with and without the smaller
copies) at every rejection threshold of THRESHOLD_GRID (and none): its CV accuracy, its paired gain
over plain per held-out hold (mean, standard error, share of holds it wins/loses), and its pass-2
accuracy. Shows which extras win the within-pass CV and lose across passes, and what their CV win
looked like. Writes benchmarks/results/new_people_candidates_<name>.{json,md}; the json (not kept in the
repository: 0.6-1.6 MB, rewritten by this command) keeps per-hold counts, on which the shipped rule (``bomi.chain.choose_candidate``, ``choose_threshold``) is
replayed (``replay``: what it would choose, and that choice's pass-2 accuracy against plain's):

    python benchmarks/new_people_candidates.py --replay benchmarks/results/new_people_candidates_dev200.json
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from bomi.chain import (CONSISTENCY, PLAIN, REQUIRED_GAIN, SHRINKAGE_GRID, THRESHOLD_GRID, Candidate, HoldScores,
                        Selection, choose_candidate, choose_threshold, cross_validate, prepare,
                        settings_candidates, train)
from bomi.classifier import posteriors, reject
from bomi.derived import derive_profile
from new_people import over_seeds   # the benchmark beside this one (run as a script from benchmarks/)
from tasks.participants.population import draw_person, pass_recordings

RESULTS = Path(__file__).resolve().parent / "results"
THRESHOLDS = (None, *THRESHOLD_GRID)


def _key(candidate: Candidate, threshold: float | None) -> str:
    return str(candidate) if threshold is None else f"{candidate} + rejection below {threshold}"


def person(seed: int) -> dict:
    """Per (candidate, threshold): per-hold CV counts (correct, windows) and the pass-2 accuracy."""
    training, test = pass_recordings(draw_person(seed))
    profile = derive_profile([training])
    candidates = settings_candidates(profile)
    results = cross_validate([training], replace(profile, direction_spread=0.0), profile.spec, candidates)
    holds = np.unique(results[0].holds)
    prepared = prepare(test, profile.spec, profile.neutral_samples)
    pure = prepared.pure
    rows = {}
    for candidate, result in zip(candidates, results):
        model = train([training], profile, selection=Selection(candidate.shrinkage, candidate.amplitude_scales,
                                                                None, None, None, {}))
        prob = posteriors(model, prepared.features[pure])
        raw, confidence = model.classes[prob.argmax(axis=1)], prob.max(axis=1)
        for threshold in THRESHOLDS:
            correct = result.correct(threshold)
            rows[_key(candidate, threshold)] = {
                "hold_correct": [int(correct[result.holds == h].sum()) for h in holds],
                "test": float(np.mean(reject(raw, confidence, threshold) == prepared.labels[pure]))}
    return {"seed": seed, "nodes": len(profile.nodes), "classes": len(profile.classes),
            "hold_windows": [int(np.sum(results[0].holds == h)) for h in holds], "candidates": rows}


def paired(record: dict, key: str, base: str = str(PLAIN)) -> dict:
    """The CV gain of ``key`` over ``base`` and its standard error over the held-out holds (as the
    rule sees them: ``HoldScores.gain_over``), the share of holds it wins and loses, its pass-2 gain."""
    windows = np.array(record["hold_windows"], dtype=float)
    a, b = (HoldScores(np.array(record["candidates"][k]["hold_correct"], dtype=float), windows) for k in (key, base))
    gain, se = a.gain_over(b)
    return {"gain": gain, "se": se, "wins": float(np.mean(a.correct > b.correct)),
            "losses": float(np.mean(a.correct < b.correct)),
            "test_gain": record["candidates"][key]["test"] - record["candidates"][base]["test"]}


def replay(person: dict, consistency: float = CONSISTENCY) -> str:
    """The key of what the shipped rule chooses from ``person``'s recorded per-hold CV counts."""
    windows = np.array(person["hold_windows"], dtype=float)
    scores = {key: HoldScores(np.array(row["hold_correct"], dtype=float), windows)
              for key, row in person["candidates"].items()}
    copies = next((k for k in scores if k.startswith("copies at ") and "rejection" not in k), "copies at ")
    scales = tuple(float(s) for s in copies.removeprefix("copies at ").split(", ") if s)
    candidates = [Candidate(s, c) for c in ((), scales) for s in SHRINKAGE_GRID if str(Candidate(s, c)) in scores]
    chosen = choose_candidate(candidates, scores, consistency)
    threshold = choose_threshold(scores[str(chosen)], {t: scores[_key(chosen, t)] for t in THRESHOLD_GRID}, consistency)
    return _key(chosen, threshold)


def replay_summary(people: list[dict], consistency: float = CONSISTENCY) -> str:
    """The rule replayed on recorded people: its pass-2 accuracy against plain's."""
    keys = [replay(p, consistency) for p in people]
    diff = np.array([p["candidates"][k]["test"] - p["candidates"][str(PLAIN)]["test"] for p, k in zip(people, keys)])
    gap = [abs(np.sum(p["candidates"][k]["hold_correct"]) / np.sum(p["hold_windows"]) - p["candidates"][k]["test"])
           for p, k in zip(people, keys)]
    lines = [f"Rule: an extra must gain {100 * REQUIRED_GAIN:g} point(s) of CV; the simplest option within {consistency:g} standard "
             f"errors of the best (over the held-out holds). {len(people)} people: pass-2 mean policy - plain {100 * diff.mean():+.3f} points, "
             f"worst {100 * diff.min():+.2f} (person {people[int(diff.argmin())]['seed']}), share more than 0.5 point "
             f"below plain {100 * np.mean(diff < -0.005):.1f} %, extras chosen {100 * np.mean([k != str(PLAIN) for k in keys]):.0f} %, "
             f"median abs(CV - pass 2) {100 * np.median(gap):.2f} points",
             "", "| person | chosen | pass-2 gain over plain |", "|---|---|---|"]
    lines += [f"| {p['seed']} | {k} | {100 * d:+.2f} |" for p, k, d in zip(people, keys, diff) if k != str(PLAIN)]
    return "\n".join(lines) + "\n"


def markdown(record: dict) -> str:
    lines = [f"Command: `{record['command']}`", "",
             "Per candidate (over people): how often its pooled CV gain over plain is >= 2 points, and of those "
             "how often it then loses > 0.5 point to plain on pass 2; the mean CV gain and pass-2 gain when "
             "it wins the CV by 2 points; how many of those had a gain of more than 2 standard errors over the held-out holds.", "",
             "| candidate | CV gain >= 2 | of which pass 2 < plain - 0.5 | mean CV gain | mean pass-2 gain | "
             "of the >= 2: hold t > 2 | of those, pass 2 < plain - 0.5 |", "|" + "---|" * 7]
    keys = list(record["people"][0]["candidates"])
    for key in keys[1:]:
        stats = [paired(p, key) for p in record["people"]]
        big = [s for s in stats if s["gain"] >= 0.02]
        lost = [s for s in big if s["test_gain"] < -0.005]
        steady = [s for s in big if s["gain"] > 2 * s["se"]]
        lines.append(f"| {key} | {len(big)} | {len(lost)} | "
                     f"{100 * np.mean([s['gain'] for s in big]) if big else float('nan'):.2f} | "
                     f"{100 * np.mean([s['test_gain'] for s in big]) if big else float('nan'):.2f} | {len(steady)} | "
                     f"{sum(s['test_gain'] < -0.005 for s in steady)} |")
    lines += ["", "Every (person, candidate) whose pooled CV gain over plain is >= 2 points:", "",
              "| person | candidate | CV gain | its SE over the holds | t | holds won | holds lost | pass-2 gain |",
              "|" + "---|" * 8]
    for p in record["people"]:
        for key in keys[1:]:
            s = paired(p, key)
            if s["gain"] >= 0.02:
                t = s["gain"] / s["se"] if s["se"] > 0 else float("inf")
                lines.append(f"| {p['seed']} | {key} | {100 * s['gain']:+.2f} | {100 * s['se']:.2f} | {t:.2f} | "
                             f"{100 * s['wins']:.0f} % | {100 * s['losses']:.0f} % | "
                             f"{100 * s['test_gain']:+.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--first-seed", type=int, default=200)
    parser.add_argument("--people", type=int, default=100)
    parser.add_argument("--name", default="dev")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--replay", type=Path, nargs="+", help="replay the rule on these json files instead")
    parser.add_argument("--consistency", type=float, default=CONSISTENCY,
                        help="with --replay: standard errors of the rule (default: the shipped one; 0: the rule before)")
    args = parser.parse_args(argv)
    if args.replay:
        people = [p for path in args.replay for p in json.loads(path.read_text())["people"]]
        print(replay_summary(people, args.consistency), end="")
        return 0
    if args.people < 1 or args.jobs < 1 or args.first_seed < 0:
        print("new_people_candidates: error: --people >= 1, --jobs >= 1, --first-seed >= 0", file=sys.stderr)
        return 2
    people = over_seeds(person, range(args.first_seed, args.first_seed + args.people), args.jobs)
    record = {"command": "python benchmarks/new_people_candidates.py " + " ".join(argv if argv is not None else sys.argv[1:]),
              "people": people}
    out = RESULTS / f"new_people_candidates_{args.name}"
    out.with_suffix(".json").write_text(json.dumps(record) + "\n")
    out.with_suffix(".md").write_text(replay_summary(people) + "\n" + markdown(record))
    print(replay_summary(people).split("\n\n")[0])
    print(f"wrote {out}.{{json,md}}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
