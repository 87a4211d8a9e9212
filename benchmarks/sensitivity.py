"""Sensitivity of virtual P1's BoMI episodes to the knobs that shaped the results: each knob alone at
50 % and 150 % of the value its TOML file gives, beside the unchanged settings, on the same seeds.

    python benchmarks/sensitivity.py [--seeds 10] [--first-seed 2000] [--jobs 2] [--knobs KEY,KEY]

The knobs are the documented settings of ``tasks/operators/operator.toml`` ([learning], [planner]), of
``tasks/participants/P1.toml`` ([feel]) and the majority vote (``vote_length``, whose default is
``tasks.experiments.jobs.DEFAULT_VOTE``).  Seeds 0-999 are for development; the reported table uses a
held-out range distinct from the headline's (2000-2009), run once the knobs are frozen.  Writes
benchmarks/results/sensitivity.md and .json.
"""
from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path

from tasks.experiments.engine import ProcessPool
from tasks.experiments.jobs import DEFAULT_VOTE, EpisodeJob, run_many
from tasks.experiments.summary import aggregate
from bomi.errors import BomiError
from tasks.participants.participant import PARTICIPANT_DIR, load_participant
from tasks.operators.params import DEFAULT_OPERATOR_FILE, load_operator

RESULTS = Path(__file__).resolve().parent / "results"
PARTICIPANT = "P1"
FACTORS = (0.5, 1.5)
VOTE = "vote_length"
# file prefix -> the tables of that file whose every key is a knob
KNOB_TABLES = {"operator": (DEFAULT_OPERATOR_FILE, ("learning", "planner")),
               "participant": (PARTICIPANT_DIR / f"{PARTICIPANT}.toml", ("feel",))}


def knob_values() -> dict[str, float]:
    """Every knob (``file.table.key``, or ``vote_length``) with its value as shipped."""
    knobs: dict[str, float] = {}
    for prefix, (path, tables) in KNOB_TABLES.items():
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        for table in tables:
            for key, value in data[table].items():
                knobs[f"{prefix}.{table}.{key}"] = value
    knobs[VOTE] = DEFAULT_VOTE
    return knobs


def scaled(value: float, factor: float) -> float | int:
    """``value`` x ``factor``; an integer knob stays an integer of at least 1."""
    return max(1, round(value * factor)) if isinstance(value, int) else value * factor


def invalid(knob: str, value: float) -> str | None:
    """Why ``knob`` cannot take ``value`` (its file's check), or None when it can."""
    if knob == VOTE:
        return None if value >= 1 else "the vote needs at least 1 decision"
    file, key = knob.split(".", 1)
    try:
        if file == "operator":
            load_operator(overrides={key: value})
        else:
            load_participant(PARTICIPANT, {key: value})
    except BomiError as exc:
        return str(exc).rsplit(": ", 1)[-1]
    return None


def job(seed: int, knob: str | None = None, value: float | None = None) -> EpisodeJob:
    if knob is None:
        return EpisodeJob("bomi", PARTICIPANT, seed)
    if knob == VOTE:
        return EpisodeJob("bomi", PARTICIPANT, seed, vote_length=int(value))
    return EpisodeJob("bomi", PARTICIPANT, seed, overrides=((knob, value),))


def summary(records: list[dict]) -> dict:
    row, = aggregate(records)
    return {key: row[key] for key in ("episodes", "successes", "success_ci95", "completion_time_mean",
                                      "completion_time_ci95", "accuracy_all_decisions", "accuracy_excused_transitions")}


def markdown(rows: list[dict], seeds: list[int]) -> str:
    def cell(r: dict) -> str:
        if "invalid" in r:
            return f"not valid ({r['value']:g}: {r['invalid']})"
        ci = r["completion_time_ci95"]
        time = "-" if r["completion_time_mean"] is None else f"{r['completion_time_mean']:.1f}" + (
            f" [{ci[0]:.0f}, {ci[1]:.0f}]" if ci else "")
        acc = "-" if r["accuracy_all_decisions"] is None else f"{100 * r['accuracy_all_decisions']:.1f} %"
        return f"{r['successes']}/{r['episodes']}, {time} s, {acc}"
    lines = [f"# Sensitivity of P1's BoMI episodes (seeds {seeds[0]}-{seeds[-1]})", "",
             "Each cell: successes, mean completion time of the successes [Student-t 95 % interval], accuracy "
             "over all decisions.", "",
             "| knob | value | x 0.5 | as shipped | x 1.5 |", "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| `{r['knob']}` | {r['value']:g} | {cell(r['low'])} | {cell(r['base'])} | {cell(r['high'])} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=2000)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--knobs", help="comma-separated subset of the knobs (default: all)")
    args = parser.parse_args()
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    knobs = knob_values()
    if args.knobs:
        wanted = [k.strip() for k in args.knobs.split(",")]
        unknown = [k for k in wanted if k not in knobs]
        if unknown:
            parser.error(f"--knobs: unknown {', '.join(unknown)} (known: {', '.join(knobs)})")
        knobs = {k: knobs[k] for k in wanted}
    edits = [(knob, scaled(value, f)) for knob, value in knobs.items() for f in FACTORS]
    reasons = {case: invalid(*case) for case in edits}
    cases = [(None, None)] + [case for case in edits if reasons[case] is None]
    jobs = [job(seed, knob, value) for knob, value in cases for seed in seeds]
    records = run_many(jobs, ProcessPool(args.jobs))
    by_case = {case: summary(records[k * len(seeds):(k + 1) * len(seeds)]) for k, case in enumerate(cases)}
    by_case.update({case: {"value": case[1], "invalid": reason} for case, reason in reasons.items() if reason})
    base = by_case[(None, None)]
    rows = [{"knob": knob, "value": value, "low": by_case[(knob, scaled(value, FACTORS[0]))], "base": base,
             "high": by_case[(knob, scaled(value, FACTORS[1]))]} for knob, value in knobs.items()]
    RESULTS.mkdir(exist_ok=True)
    text = markdown(rows, seeds)
    (RESULTS / "sensitivity.md").write_text(text, encoding="utf-8")
    (RESULTS / "sensitivity.json").write_text(json.dumps(
        {"participant": PARTICIPANT, "seeds": seeds, "factors": FACTORS, "rows": rows,
         "episodes": records}, indent=2) + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
