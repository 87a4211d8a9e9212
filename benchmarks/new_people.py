"""A new person's classifier, as shipped, against a plain scikit-learn LDA, on many new people.

    python benchmarks/new_people.py [--first-seed 0] [--people 100] [--no-p1] [--name NAME] [--jobs 1]

Members: synthetic people drawn by ``tasks.participants.population`` (seeds first-seed ..
first-seed + people - 1; development used seeds 0-43, 100-139 and 200-339, confirmations
10100-10129, 10200-10229, 10300-10329, 10400-10429, 10500-10529 and 10600-10629), each trained on pass 1 and
tested on pass 2,
and P1's five real days (each ordered day pair, 20 members). Every member goes through what
``bomi train`` / ``bomi evaluate`` do without ``--profile``: the profile derived from the training
recording and the settings chosen on it (``bomi.chain.select_settings``). Plain LDA: scikit-learn's
``LinearDiscriminantAnalysis()`` (defaults: 'svd' solver, no shrinkage) on the same FV windows.
Per member also the CV estimate of the chosen settings and the CV accuracy of every candidate. Writes
benchmarks/results/new_people_<name>.{json,md,png}.
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
from multiprocessing import Pool
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bomi.chain import CONSISTENCY, REQUIRED_GAIN, evaluate, prepare, select_settings, train  # noqa: E402
from bomi.dataset import data_dir  # noqa: E402
from bomi.derived import derive_profile  # noqa: E402
from bomi.recording import Recording  # noqa: E402
from bomi.reproduce import DAYS, read_days  # noqa: E402
from tasks.participants.population import draw_person, pass_recordings  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def plain_lda_accuracy(training: Recording, test: Recording, spec, neutral_samples: int) -> float:
    """scikit-learn's default LDA on the single-label windows of ``spec``."""
    a, b = prepare(training, spec, neutral_samples), prepare(test, spec, neutral_samples)
    lda = LinearDiscriminantAnalysis().fit(a.features[a.pure], a.labels[a.pure])
    return float(np.mean(lda.predict(b.features[b.pure]) == b.labels[b.pure]))


def member(name: str, training: Recording, test: Recording) -> dict:
    """The shipped policy and plain LDA on one (training, test) pair."""
    profile = derive_profile([training])
    selection = select_settings([training], profile, profile.spec)
    model = train([training], profile, selection=selection)
    return {"member": name, "nodes": len(profile.nodes), "classes": len(profile.classes),
            "policy": evaluate(model, test, profile.neutral_samples).accuracy,
            "plain_lda": plain_lda_accuracy(training, test, profile.spec, profile.neutral_samples),
            "cv_estimate": selection.accuracy, "settings": selection.describe(),
            "cv_candidates": selection.candidates}


def person_member(seed: int) -> dict:
    training, test = pass_recordings(draw_person(seed))
    return {"seed": seed, **member(f"person {seed}", training, test)}


def over_seeds(function, seeds: range, jobs: int) -> list:
    """``function(seed)`` for every person seed, in ``jobs`` processes, with a progress bar."""
    with Pool(jobs) as pool:
        return list(tqdm(pool.imap(function, seeds), total=len(seeds), desc="people", unit="person"))


def p1_members(directory: Path) -> list[dict]:
    days = read_days(directory)
    return [{"seed": None, **member(f"P1 day {a}->{b}", days[a], days[b])}
            for a, b in tqdm(list(itertools.permutations(DAYS, 2)), desc="P1 day pairs", unit="pair")]


def summary(rows: list[dict]) -> dict:
    policy = np.array([r["policy"] for r in rows])
    plain = np.array([r["plain_lda"] for r in rows])
    diff = policy - plain
    cv = np.array([np.nan if r["cv_estimate"] is None else r["cv_estimate"] for r in rows])
    return {"members": len(rows), "policy_mean": float(policy.mean()), "plain_mean": float(plain.mean()),
            "policy_worst": float(policy.min()), "plain_worst": float(plain.min()),
            "worst_difference": float(diff.min()), "worst_member": rows[int(diff.argmin())]["member"],
            "share_below_plain": float(np.mean(diff < 0)), "share_below_plain_by_0.5": float(np.mean(diff < -0.005)),
            "median_abs_cv_error": float(np.nanmedian(np.abs(cv - policy))),
            "cv_error_of_median_member": float(np.nanmedian(cv) - np.median(policy)),
            "share_extras_chosen": float(np.mean([r["settings"] != "plain" for r in rows]))}


def markdown(record: dict) -> str:
    lines = [f"Command: `{record['command']}`", "",
             f"An extra must gain {100 * record['required_gain']:g} point(s) in the CV and {record['consistency']:g} "
             "standard errors over the held-out holds to replace what is chosen before it.", "",
             "| members | n | policy mean | plain LDA mean | policy worst | plain worst | worst policy - plain (who) "
             "| share below plain | share > 0.5 point below | median abs(CV - test) | extras chosen |",
             "|" + "---|" * 11]
    for name, s in record["summary"].items():
        lines.append(f"| {name} | {s['members']} | {100 * s['policy_mean']:.2f} | {100 * s['plain_mean']:.2f} | "
                     f"{100 * s['policy_worst']:.2f} | {100 * s['plain_worst']:.2f} | "
                     f"{100 * s['worst_difference']:+.2f} ({s['worst_member']}) | {100 * s['share_below_plain']:.1f} % | "
                     f"{100 * s['share_below_plain_by_0.5']:.1f} % | {100 * s['median_abs_cv_error']:.2f} | "
                     f"{100 * s['share_extras_chosen']:.1f} % |")
    lines += ["", "| member | nodes | classes | settings | CV estimate | policy | plain LDA | difference |", "|" + "---|" * 8]
    for r in record["rows"]:
        cv = "-" if r["cv_estimate"] is None else f"{100 * r['cv_estimate']:.2f}"
        lines.append(f"| {r['member']} | {r['nodes']} | {r['classes']} | {r['settings']} | {cv} | "
                     f"{100 * r['policy']:.2f} | {100 * r['plain_lda']:.2f} | {100 * (r['policy'] - r['plain_lda']):+.2f} |")
    return "\n".join(lines) + "\n"


def figure(rows: list[dict], path: Path) -> None:
    policy = 100 * np.array([r["policy"] for r in rows])
    plain = 100 * np.array([r["plain_lda"] for r in rows])
    cv = 100 * np.array([np.nan if r["cv_estimate"] is None else r["cv_estimate"] for r in rows])
    p1 = np.array([r["seed"] is None for r in rows])
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.4))
    for ax, x, label in ((axes[0], plain, "plain scikit-learn LDA, test accuracy (%)"),
                         (axes[1], cv, "CV estimate on the training pass (%)")):
        ax.scatter(x[~p1], policy[~p1], s=10, label="synthetic people")
        ax.scatter(x[p1], policy[p1], s=14, marker="x", color="C3", label="P1 day pairs")
        low = float(np.nanmin(np.r_[x, policy])) - 1
        ax.plot([low, 100], [low, 100], color="0.5", lw=0.8)
        ax.set_xlabel(label)
        ax.set_ylabel("shipped policy, test accuracy (%)")
        ax.legend(fontsize=8)
    axes[0].set_title("policy vs plain LDA (above the line: policy better)", fontsize=9)
    axes[1].set_title("does the CV predict the test?", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--people", type=int, default=100)
    parser.add_argument("--no-p1", action="store_true", help="leave P1's real day pairs out")
    parser.add_argument("--data", type=Path, help="P1's dataset directory (default: BOMI_DATA_DIR)")
    parser.add_argument("--name", default="dev")
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args(argv)
    out = RESULTS / f"new_people_{args.name}"
    if args.people < 0 or args.jobs < 1 or args.first_seed < 0:
        print("new_people: error: --people >= 0, --jobs >= 1, --first-seed >= 0", file=sys.stderr)
        return 2
    rows = over_seeds(person_member, range(args.first_seed, args.first_seed + args.people), args.jobs)
    groups = {"synthetic people": rows}
    if not args.no_p1:
        p1 = p1_members(args.data or data_dir())
        groups["P1 day pairs"] = p1
        rows = rows + p1
    groups["all"] = rows
    record = {"command": "python benchmarks/new_people.py " + " ".join(argv if argv is not None else sys.argv[1:]),
              "required_gain": REQUIRED_GAIN, "consistency": CONSISTENCY, "summary": {k: summary(v) for k, v in groups.items() if v}, "rows": rows}
    out.with_suffix(".json").write_text(json.dumps(record, indent=1) + "\n")
    out.with_suffix(".md").write_text(markdown(record))
    figure(rows, out.with_suffix(".png"))
    print(markdown(record).split("\n\n| member |")[0])
    print(f"wrote {out}.{{json,md,png}}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
