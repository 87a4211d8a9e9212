"""The rest-offset training copies (``bomi.chain.rest_offsets``) offline: where they help, where they cost.

    python benchmarks/rest_offsets.py --people 601,606,610 [--name NAME]
    python benchmarks/rest_offsets.py --p1

``--people``: synthetic people (tasks/participants/population.py; development seeds only), their two
passes: each pass read by the model of the other (the derived profile's plain LDA and smaller copies),
without and with the copies (``bomi.chain.rest_offset_scores``, what the derived profile decides on),
and whether the derived profile takes them. ``--p1``: P1's shipped profile on every ordered pair of its five real days
(20), trained as ``bomi reproduce`` trains it, without and with the copies forced on: the real
person the copies must not harm (its day files are one pass each, so a derived profile of them would
never take the copies).

Writes benchmarks/results/rest_offsets_NAME.md (``--people``) or rest_offsets_p1.md.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


from bomi.chain import evaluate, rest_offset_scores, train  # noqa: E402
from bomi.dataset import data_dir  # noqa: E402
from bomi.derived import derive_profile  # noqa: E402
from bomi.profiles import load_profile  # noqa: E402
from bomi.reproduce import DAYS, read_days  # noqa: E402
from tasks.participants.population import draw_person, pass_recordings  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"


def people_range(text: str) -> list[int]:
    """'400-417' or '400,403' -> the population seeds."""
    if "-" in text:
        first, last = (int(part) for part in text.split("-"))
        return list(range(first, last + 1))
    return [int(part) for part in text.split(",")]


def people_report(people: list[int], argv: list[str]) -> str:
    lines = [f"# Rest-offset copies on synthetic people's two passes (`python benchmarks/rest_offsets.py {' '.join(argv)}`)",
             "", "Each pass read by the model of the other (plain LDA and the smaller copies), pooled over both.", "",
             "| person | motions | without | with | taken by the derived profile |", "|---|---|---|---|---|"]
    gains = []
    for person in tqdm(people, desc="people", unit="person"):
        passes = pass_recordings(draw_person(person))
        profile = derive_profile(list(passes))
        accuracy = [100 * scores.accuracy for scores in rest_offset_scores(passes, profile)]
        gains.append(accuracy[1] - accuracy[0])
        lines.append(f"| {person} | {len(profile.classes) - 1} | {accuracy[0]:.2f} % | {accuracy[1]:.2f} % | "
                     f"{'yes' if profile.rest_offsets else 'no'} |")
    lines += ["", f"Mean gain {np.mean(gains):+.2f} points over {len(gains)} people; "
                  f"lower with the copies for {sum(g < 0 for g in gains)} of them."]
    return "\n".join(lines) + "\n"


def p1_report() -> str:
    recordings, profile = read_days(data_dir()), load_profile("P1")
    lines = ["# Rest-offset copies on P1's real days (`python benchmarks/rest_offsets.py --p1`)", "",
             "The day-1 ... day-5 model on every other day (20 ordered pairs), P1's shipped profile.", "",
             "| copies | mean | worst (pair) |", "|---|---|---|"]
    for on in (False, True):
        variant = replace(profile, rest_offsets=on)
        accuracy = {}
        for a in tqdm(DAYS, desc=f"copies {'on' if on else 'off'}", unit="day"):
            model = train([recordings[a]], variant)
            accuracy.update({(a, b): 100 * evaluate(model, recordings[b], variant.neutral_samples).accuracy
                             for b in DAYS if b != a})
        worst = min(accuracy, key=accuracy.get)
        lines.append(f"| {'on' if on else 'off'} | {np.mean(list(accuracy.values())):.2f} % | "
                     f"{accuracy[worst]:.2f} % (day {worst[0]} -> {worst[1]}) |")
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--people", help="population seeds, 'FIRST-LAST' or a list (development)")
    parser.add_argument("--p1", action="store_true", help="P1's twenty day pairs")
    parser.add_argument("--name", default="dev", help="result file's name (--people)")
    args = parser.parse_args()
    if args.p1 == bool(args.people):
        parser.error("give --people or --p1")
    if args.p1:
        text, out = p1_report(), RESULTS / "rest_offsets_p1.md"
    else:
        people = people_range(args.people)
        if any(not 0 <= p < 1000 for p in people):
            parser.error("--people: development people only (0-999)")
        text, out = people_report(people, sys.argv[1:]), RESULTS / f"rest_offsets_{args.name}.md"
    out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
