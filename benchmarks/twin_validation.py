"""Out-of-sample check of the twin (`bomi twin`): does a twin fitted on one day predict the next day?

    python benchmarks/twin_validation.py --first-seed S [--data DIR] [--population N]

P1, every ordered pair of days (k, j): the twin fitted on real day k alone (tasks.participants.twin,
profile P1), with the drift between days it cannot see taken from a prior fitted on the three
other days (neither k nor j: nothing of day j enters the prediction), performs two synthetic
sessions (`bomi synth`: day k's protocol through simulated frames and the fusion, seeds S + 2i and
S + 2i + 1). Its prediction of the real day k -> j accuracy is the session-to-session accuracy,
the mean of session 1 -> 2 and 2 -> 1. Real: train on day k, test on day j, profile P1 (what
`bomi evaluate --train dayk --test dayj --profile P1` prints). Per pair: prediction, real, gap.

With ``--population N``: N synthetic people (tasks/participants/population.py, people S .. S + N - 1)
with known parameters, two passes each; the twin of each person's first pass (the person's profile,
prior P1) against the true parameters (recovery, per parameter) and its pass-to-pass prediction
(sessions S + 500 + 2i, + 1) against the person's pass 1 -> 2 accuracy.

Writes benchmarks/results/twin_validation_S.{md,json,png}.
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bomi.chain import evaluate  # noqa: E402
from bomi.dataset import data_dir  # noqa: E402
from bomi.errors import BomiError  # noqa: E402
from bomi.profiles import Profile, load_profile  # noqa: E402
from bomi.recording import Recording  # noqa: E402
from bomi.reproduce import DAYS, read_days  # noqa: E402
from tasks.cli.chain import fit_model  # noqa: E402
from tasks.participants.participant import (ParticipantParams, load_participant, protocol_session,  # noqa: E402
                                            session_recording)
from tasks.participants.population import draw_person, pass_recordings  # noqa: E402
from tasks.participants.twin import fit_twin, twin_toml  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
BAR_POINTS = 3.0
BAR_PAIRS = 16


def accuracy(train_on: Recording, test_on: Recording, profile: Profile) -> float:
    """Percent accuracy of the model `bomi evaluate --profile` trains on ``train_on``, tested on ``test_on``."""
    model = fit_model([train_on], profile, profile.spec)
    return 100 * evaluate(model, test_on, profile.neutral_samples).accuracy


def as_participant(twin, directory: Path) -> ParticipantParams:
    """The twin through its file, as every command reads it."""
    path = directory / f"{twin.name}.toml"
    path.write_text(twin_toml(twin, f"validation twin {twin.name}"))
    return load_participant(path)


def session(params: ParticipantParams, profile: Profile, seed: int) -> Recording:
    """What `bomi synth --participant ... --seed seed` writes."""
    return session_recording(protocol_session(params, profile, seed, params.protocol), profile,
                             holds_only=params.protocol.holds_only)


def predicted(params: ParticipantParams, profile: Profile, seeds: tuple[int, int]) -> float:
    """The twin's session-to-session accuracy: mean of session 1 -> 2 and 2 -> 1."""
    a, b = (session(params, profile, s) for s in seeds)
    return (accuracy(a, b, profile) + accuracy(b, a, profile)) / 2


def day_pairs(days: dict[int, Recording], profile: Profile, first_seed: int, directory: Path) -> list[dict]:
    rows = []
    for i, (k, j) in enumerate(tqdm(list(itertools.permutations(DAYS, 2)), desc="day pairs", unit="pair")):
        others = [days[d] for d in DAYS if d not in (k, j)]
        prior = as_participant(fit_twin(others, profile, None, f"P1-prior-{k}{j}"), directory)
        twin = as_participant(fit_twin([days[k]], profile, prior, f"P1-day{k}-for-{j}"), directory)
        seeds = (first_seed + 2 * i, first_seed + 2 * i + 1)
        pred, real = predicted(twin, profile, seeds), accuracy(days[k], days[j], profile)
        rows.append({"train_day": k, "test_day": j, "seeds": list(seeds), "predicted_pct": pred, "real_pct": real,
                     "gap_points": pred - real})
    return rows


def _ratio(twin: np.ndarray, true: np.ndarray) -> float:
    """Median over entries of twin / true (1: recovered)."""
    return float(np.median(np.asarray(twin) / np.maximum(np.asarray(true), 1e-9)))


def recovery(person, twin: ParticipantParams) -> dict[str, float]:
    """Per parameter: how far the twin of a person's first pass is from the person's true parameters."""
    true = person.params
    labels = sorted(true.classes)
    posture_error = [np.linalg.norm(twin.classes[c].posture_deg - true.classes[c].posture_deg) for c in labels]
    posture_size = [np.linalg.norm(true.classes[c].posture_deg) for c in labels]
    pick = lambda params, key: np.concatenate([getattr(params.classes[c], key) for c in labels])  # noqa: E731
    peak = lambda params: float(params.tremor_spectrum[0][np.argmax(params.tremor_spectrum[1])])  # noqa: E731
    return {
        "posture error / size": float(np.median(np.array(posture_error) / np.array(posture_size))),
        "posture error (deg)": float(np.median(posture_error)),
        "rep_std_deg twin / true": _ratio(pick(twin, "rep_std_deg"), pick(true, "rep_std_deg")),
        "neutral rep_std_deg twin / true": _ratio(twin.neutral.rep_std_deg, true.neutral.rep_std_deg),
        "sway_std_deg twin / true": _ratio(pick(twin, "sway_std_deg")[:, :2], pick(true, "sway_std_deg")[:, :2]),
        "tremor_std_deg twin / true": _ratio(pick(twin, "tremor_std_deg")[:, :2], pick(true, "tremor_std_deg")[:, :2]),
        "tremor peak (Hz) twin - true": peak(twin) - peak(true),
        "onset_s twin - true (prior)": twin.onset_s - true.onset_s,
        "reaction_s twin - true (prior)": twin.reaction_s - true.reaction_s,
        "day_gain_log_std twin - true (prior)": float(np.median([twin.classes[c].day_gain_log_std
                                                                 - true.classes[c].day_gain_log_std for c in labels])),
    }


def population(first_seed: int, people: int, directory: Path) -> list[dict]:
    """Each person's twin of pass 1: recovery, and its pass-to-pass prediction against the real pass 1 -> 2."""
    prior = load_participant("P1")
    rows = []
    for i, seed in enumerate(tqdm(range(first_seed, first_seed + people), desc="people", unit="person")):
        person = draw_person(seed)
        first, second = pass_recordings(person)
        twin = as_participant(fit_twin([first], person.profile, prior, f"twin-of-N{seed}", person.profile.name),
                              directory)
        seeds = (first_seed + 500 + 2 * i, first_seed + 500 + 2 * i + 1)
        rows.append({"person": seed, "nodes": len(person.profile.nodes), "motions": len(person.params.classes),
                     "seeds": list(seeds), "predicted_pct": predicted(twin, person.profile, seeds),
                     "real_pct": accuracy(first, second, person.profile), **recovery(person, twin)})
        rows[-1]["gap_points"] = rows[-1]["predicted_pct"] - rows[-1]["real_pct"]
    return rows


def population_markdown(rows: list[dict]) -> str:
    keys = [k for k in rows[0] if k not in ("person", "nodes", "motions", "seeds", "predicted_pct", "real_pct",
                                            "gap_points")]
    gaps = np.array([r["gap_points"] for r in rows])
    lines = ["## Synthetic people (tasks/participants/population.py): the twin of pass 1 against the truth", "",
             "Parameter recovery, median over people (per person: median over classes and angles):", "",
             "| parameter | median | 10th-90th percentile |", "|---|---|---|"]
    for key in keys:
        values = [r[key] for r in rows]
        lines.append(f"| {key} | {np.median(values):+.3f} | {np.percentile(values, 10):+.3f} .. "
                     f"{np.percentile(values, 90):+.3f} |")
    lines += ["", "Prediction: the twin's session-to-session accuracy against the person's pass 1 -> 2 accuracy:", "",
              "| person | nodes | motions | predicted % | real pass 1 -> 2 % | gap |", "|---|---|---|---|---|---|"]
    lines += [f"| {r['person']} | {r['nodes']} | {r['motions']} | {r['predicted_pct']:.2f} | {r['real_pct']:.2f} | "
              f"{r['gap_points']:+.2f} |" for r in rows]
    lines += ["", f"Mean absolute gap {np.mean(np.abs(gaps)):.2f} points (mean gap {np.mean(gaps):+.2f}); within "
              f"{BAR_POINTS:g} points for {int(np.sum(np.abs(gaps) <= BAR_POINTS))} of {len(rows)} people.", ""]
    return "\n".join(lines)


RATIO_KEYS = ("rep_std_deg twin / true", "neutral rep_std_deg twin / true", "sway_std_deg twin / true",
              "tremor_std_deg twin / true")


def population_figure(rows: list[dict], path: Path) -> None:
    """Left: the twin's prediction against each person's pass 1 -> 2 accuracy; right: recovered / true per parameter."""
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    real = np.array([r["real_pct"] for r in rows])
    pred = np.array([r["predicted_pct"] for r in rows])
    lo = min(real.min(), pred.min()) - 1
    ax.fill_between([lo, 100.5], [lo - BAR_POINTS, 100.5 - BAR_POINTS], [lo + BAR_POINTS, 100.5 + BAR_POINTS],
                    color="C2", alpha=0.15, label=f"within {BAR_POINTS:g} points")
    ax.plot([lo, 100.5], [lo, 100.5], "k--", lw=0.8)
    ax.scatter(real, pred)
    for r in rows:
        ax.annotate(str(r["person"]), (r["real_pct"], r["predicted_pct"]), fontsize=6)
    ax.set_xlim(lo, 100.5)
    ax.set_ylim(lo, 100.5)
    ax.set_xlabel("person's real accuracy, pass 1 -> pass 2 (%)")
    ax.set_ylabel("twin of pass 1: session-to-session accuracy (%)")
    ax.legend(loc="upper left", fontsize=8)
    bx.boxplot([[r[k] for r in rows] for k in RATIO_KEYS])
    bx.set_xticks(range(1, len(RATIO_KEYS) + 1), [k.replace(" twin / true", "") for k in RATIO_KEYS])
    bx.axhline(1.0, color="k", lw=0.8, ls="--")
    bx.set_ylabel("twin / true (median per person)")
    bx.tick_params(axis="x", labelsize=7)
    fig.suptitle(f"Twins of {len(rows)} synthetic people (one pass each) against their truth")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def markdown(rows: list[dict], first_seed: int) -> str:
    gaps = np.array([r["gap_points"] for r in rows])
    within = int(np.sum(np.abs(gaps) <= BAR_POINTS))
    lines = [
        "# The twin of P1 fitted on one day, predicting the real accuracy on another day (out of sample)",
        "",
        f"`python benchmarks/twin_validation.py --first-seed {first_seed}`. Twin: day k alone (`bomi twin`, profile "
        "P1), its drift between days from a prior fitted on the three days that are neither k nor j. Prediction: "
        "the twin's two synthetic sessions (`bomi synth`), mean of 1 -> 2 and 2 -> 1. Real: train on day k, test on "
        "day j (`bomi evaluate --profile P1`).",
        "",
        "| train day k | test day j | seeds | predicted % | real % | gap (points) |",
        "|---|---|---|---|---|---|",
    ]
    lines += [f"| {r['train_day']} | {r['test_day']} | {r['seeds'][0]}, {r['seeds'][1]} | {r['predicted_pct']:.2f} "
              f"| {r['real_pct']:.2f} | {r['gap_points']:+.2f} |" for r in rows]
    lines += ["", f"Mean absolute gap {np.mean(np.abs(gaps)):.2f} points (mean gap {np.mean(gaps):+.2f}); "
              f"within {BAR_POINTS:g} points on {within} of {len(rows)} pairs (bar: at least {BAR_PAIRS}) -> "
              f"{'met' if within >= BAR_PAIRS else 'missed'}.", ""]
    return "\n".join(lines)


def figure(rows: list[dict], path: Path) -> None:
    real = np.array([r["real_pct"] for r in rows])
    pred = np.array([r["predicted_pct"] for r in rows])
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    lo = min(real.min(), pred.min()) - 1
    ax.fill_between([lo, 100.5], [lo - BAR_POINTS, 100.5 - BAR_POINTS], [lo + BAR_POINTS, 100.5 + BAR_POINTS],
                    color="C2", alpha=0.15, label=f"within {BAR_POINTS:g} points")
    ax.plot([lo, 100.5], [lo, 100.5], "k--", lw=0.8)
    ax.scatter(real, pred, color="C0")
    for r in rows:
        ax.annotate(f"{r['train_day']}>{r['test_day']}", (r["real_pct"], r["predicted_pct"]), fontsize=6)
    ax.set_xlim(lo, 100.5)
    ax.set_ylim(lo, 100.5)
    ax.set_xlabel("real accuracy, train day k, test day j (%)")
    ax.set_ylabel("twin of day k: session-to-session accuracy (%)")
    ax.legend(loc="upper left", fontsize=8)
    labels = [f"{r['train_day']}>{r['test_day']}" for r in rows]
    bx.bar(labels, [r["gap_points"] for r in rows], color=["C0" if abs(r["gap_points"]) <= BAR_POINTS else "C3"
                                                           for r in rows])
    bx.axhspan(-BAR_POINTS, BAR_POINTS, color="C2", alpha=0.15)
    bx.set_ylabel("predicted - real (points)")
    bx.tick_params(axis="x", labelrotation=90, labelsize=7)
    fig.suptitle("Twin of P1 fitted on one day vs the real day-to-day accuracy (out of sample)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first-seed", type=int, required=True, help="first synthetic-session seed (40 are used)")
    parser.add_argument("--data", type=Path, default=None, help="directory of dayN_testp.mat (default: BOMI_DATA_DIR)")
    parser.add_argument("--population", type=int, default=0, metavar="N", help="also N synthetic people (default 0)")
    parser.add_argument("--skip-days", action="store_true", help="only the synthetic people")
    args = parser.parse_args(argv)
    profile = load_profile("P1")
    try:
        days = read_days(args.data or data_dir())
    except BomiError as exc:
        print(f"twin_validation: error: {exc}", file=sys.stderr)
        return 2
    name = f"twin_validation_{args.first_seed}"
    RESULTS.mkdir(exist_ok=True)
    record: dict = {"first_seed": args.first_seed}
    text = ""
    with tempfile.TemporaryDirectory() as temp:
        if not args.skip_days:
            rows = day_pairs(days, profile, args.first_seed, Path(temp))
            gaps = [abs(r["gap_points"]) for r in rows]
            record.update({"pairs": rows, "mean_abs_gap_points": float(np.mean(gaps)),
                           "pairs_within_bar": int(sum(g <= BAR_POINTS for g in gaps)), "bar_points": BAR_POINTS,
                           "bar_pairs": BAR_PAIRS})
            text = markdown(rows, args.first_seed)
            figure(rows, RESULTS / f"{name}.png")
        if args.population:
            people = population(args.first_seed, args.population, Path(temp))
            record["population"] = people
            population_figure(people, RESULTS / f"{name}_population.png")
            text += "\n" + population_markdown(people)
            name += "_population" if args.skip_days else ""
    (RESULTS / f"{name}.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / f"{name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
