"""Ours against something else, as distributions: the twin against the person it was fitted to
(``twin``: the README's row "P1's twin of one real day predicts another day's accuracy"), and two
`bomi benchmark --json` runs against each other (``outcomes``: a change that alters every
trajectory, such as the physics, checked to leave the outcomes' distributions alone; also what
``benchmarks/records_identity.py --no-jit`` uses).

    python benchmarks/comparisons.py twin --first-seed S [--pairs M] [--jobs J] [--data DIR]
                                          [--population N] [--skip-days]
    python benchmarks/comparisons.py outcomes --before before.json --after after.json --out NAME

``twin``: P1, every ordered pair of days (k, j): the twin fitted on real day k alone (tasks.participants.twin,
profile P1), with the drift between days it cannot see taken from a prior fitted on the three
other days (neither k nor j: nothing of day j enters the prediction), performs M pairs of
synthetic sessions (`bomi synth`: day k's protocol through simulated frames and the fusion; pair i
of the 20 uses seeds S + 2Mi .. S + 2Mi + 2M - 1). A pair's accuracy is the mean of session 1 -> 2
and 2 -> 1; the prediction of the real day k -> j accuracy is the mean over the M pairs, reported
with its standard error (the pairs' spread / sqrt(M)): each synthetic session draws its own day,
so one pair is one draw of the day-to-day drift. Real: train on day k, test on day j, profile P1
(what `bomi evaluate --train dayk --test dayj --profile P1` prints). Per pair: prediction, its
standard error, real, gap.

With ``--population N``: N synthetic people (tasks/participants/population.py, people S .. S + N - 1)
with known parameters, two passes each; the twin of each person's first pass (the person's profile,
prior P1) against the true parameters (recovery, per parameter) and its pass-to-pass prediction
(M session pairs, seeds drawn from the person's seed) against the person's pass 1 -> 2 accuracy.

Writes benchmarks/results/twin_validation_S.{md,json,png} (with --skip-days: ..._S_population.*).

``outcomes``: Did a physics change alter the task's outcomes?  Two ``bomi benchmark --json`` files of the
same participants, operators and task seeds, one before the change and one after, compared as
distributions over the seeds (a physics change alters every trajectory, so records cannot be
identical; what must hold is that the outcomes are drawn from the same distribution).

    bomi benchmark --participants P1 --operators joystick --seeds 60 --first-seed 0 --jobs 1 --json before.json
    (change; the same command) --json after.json
    python benchmarks/comparisons.py outcomes --before before.json --after after.json --out NAME

Per operator: success rate (Fisher's exact test), completion time of the successful episodes
(Mann-Whitney U and two-sample Kolmogorov-Smirnov, scipy), cube drops, mode switches and
unintended displacement (Mann-Whitney U), and the paired per-seed difference of completion time.
Writes benchmarks/results/NAME.md, .json and .png (completion time ECDFs).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import itertools
import json
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import Enum
from multiprocessing import Pool
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bomi.chain import evaluate  # noqa: E402
from bomi.dataset import data_dir  # noqa: E402
from bomi.errors import BomiError  # noqa: E402
from bomi.profiles import Profile, load_profile  # noqa: E402
from bomi.recording import Recording  # noqa: E402
from bomi.reproduce import DAYS, read_days  # noqa: E402
from tasks.experiments.training import fit_model  # noqa: E402
from tasks.participants.participant import (ParticipantParams, load_participant, protocol_session,  # noqa: E402
                                            session_recording)
from tasks.participants.population import draw_person, pass_recordings, true_profile  # noqa: E402
from tasks.participants.twin import fit_twin, twin_toml  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
BAR_POINTS = 3.0
BAR_PAIRS = 16
DEFAULT_PAIRS = 4


def accuracy(train_on: Recording, test_on: Recording, profile: Profile) -> float:
    """Percent accuracy of the model `bomi evaluate --profile` trains on ``train_on``, tested on ``test_on``."""
    model = fit_model([train_on], profile, profile.spec)
    return 100 * evaluate(model, test_on, profile.neutral_samples).accuracy


def as_participant(twin, directory: Path) -> ParticipantParams:
    """The twin through its file, as every command reads it."""
    path = directory / f"{twin.name}.toml"
    path.write_text(twin_toml(twin, f"validation twin {twin.name}"))
    return load_participant(path)


def session(params: ParticipantParams, profile: Profile, seed: int, worn: Profile | None = None) -> Recording:
    """What `bomi synth --participant ... --seed seed` writes; ``worn``: the sensors' real mountings
    when they differ from the ones ``profile`` (and so the fusion) assumes."""
    return session_recording(protocol_session(params, worn or profile, seed, params.protocol), profile,
                             holds_only=params.protocol.holds_only)


@dataclass(frozen=True)
class Prediction:
    """The twin's session-to-session accuracy over disjoint pairs of synthetic sessions: per pair the
    mean of session 1 -> 2 and 2 -> 1; the prediction is their mean, its standard error the pairs'
    spread / sqrt(pairs)."""

    per_pair: tuple[float, ...]

    @property
    def mean(self) -> float:
        return float(np.mean(self.per_pair))

    @property
    def standard_error(self) -> float:
        if len(self.per_pair) < 2:
            return float("nan")
        return float(np.std(self.per_pair, ddof=1) / np.sqrt(len(self.per_pair)))


def predicted(params: ParticipantParams, profile: Profile, seeds: Sequence[tuple[int, int]],
              worn: Profile | None = None) -> Prediction:
    """The twin's prediction from the session pairs of ``seeds``."""
    values = []
    for seed_a, seed_b in seeds:
        a, b = session(params, profile, seed_a, worn), session(params, profile, seed_b, worn)
        values.append((accuracy(a, b, profile) + accuracy(b, a, profile)) / 2)
    return Prediction(tuple(values))


def pair_seeds(first: int, pairs: int) -> list[tuple[int, int]]:
    """``pairs`` session pairs from ``first`` on: (first, first + 1), (first + 2, first + 3), ..."""
    return [(first + 2 * p, first + 2 * p + 1) for p in range(pairs)]


def person_session_seeds(person_seed: int, pairs: int) -> list[tuple[int, int]]:
    """The session pairs of a synthetic person's twin, drawn from the person's seed (a population
    run's seeds are its people's)."""
    state = np.random.SeedSequence([person_seed, 28]).generate_state(2 * pairs)
    return [(int(state[2 * p]), int(state[2 * p + 1])) for p in range(pairs)]


_DAYS: dict[int, Recording] = {}


def _load_days(directory: Path) -> None:
    """Worker initialiser: P1's five days, read once per process."""
    _DAYS.update(read_days(directory))


def day_pair(task: tuple[int, int, int, int]) -> dict:
    """Ordered day pair (k, j): the twin of day k (its drift prior from the other three days) against day k -> j."""
    k, j, first_seed, pairs = task
    profile = load_profile("P1")
    with tempfile.TemporaryDirectory() as temp:
        others = [_DAYS[d] for d in DAYS if d not in (k, j)]
        prior = as_participant(fit_twin(others, profile, None, f"P1-prior-{k}{j}"), Path(temp))
        twin = as_participant(fit_twin([_DAYS[k]], profile, prior, f"P1-day{k}-for-{j}"), Path(temp))
    seeds = pair_seeds(first_seed, pairs)
    with contextlib.redirect_stdout(io.StringIO()):     # the settings choice's lines, once per model
        pred, real = predicted(twin, profile, seeds), accuracy(_DAYS[k], _DAYS[j], profile)
    return {"train_day": k, "test_day": j, "seeds": [seeds[0][0], seeds[-1][1]], "pairs": pairs,
            "predicted_pct": pred.mean, "predicted_se": pred.standard_error, "per_pair_pct": list(pred.per_pair),
            "real_pct": real, "gap_points": pred.mean - real}


def run_tasks(function, tasks: list, jobs: int, desc: str, unit: str, initializer=None, initargs=()) -> list[dict]:
    """``function`` over ``tasks``, results in order, in ``jobs`` processes, with a progress bar on stderr."""
    if jobs <= 1:
        if initializer is not None:
            initializer(*initargs)
        return [function(t) for t in tqdm(tasks, desc=desc, unit=unit)]
    with Pool(jobs, initializer=initializer, initargs=initargs) as pool:
        return list(tqdm(pool.imap(function, tasks), total=len(tasks), desc=desc, unit=unit))


def day_pairs(directory: Path, first_seed: int, pairs: int, jobs: int) -> list[dict]:
    """Every ordered pair of P1's days; pair i uses the session seeds first_seed + 2 * pairs * i on."""
    tasks = [(k, j, first_seed + 2 * pairs * i, pairs) for i, (k, j) in enumerate(itertools.permutations(DAYS, 2))]
    return run_tasks(day_pair, tasks, jobs, "day pairs", "pair", _load_days, (directory,))


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


class Swap(Enum):
    """A group of the twin's parameters replaced by the person's truth (the ablation of --ablation)."""

    DRIFT = "drift between passes"            # day_gain_log_std, day_std_deg: a prior for one pass
    REPETITION = "repetition spread"          # rep_std_deg (classes and neutral)
    SWAY_TREMOR = "sway, tremor"              # sway_std_deg, tremor_std_deg, the tremor spectrum
    TIMING = "onset, reaction, spasms"        # priors for a holds-only pass; the twin has no spasms


SWAP_KEYS = {Swap.DRIFT: ("day_gain_log_std", "day_std_deg"), Swap.REPETITION: ("rep_std_deg",),
             Swap.SWAY_TREMOR: ("sway_std_deg", "tremor_std_deg")}


def with_truth(twin: ParticipantParams, true: ParticipantParams, swap: Swap) -> ParticipantParams:
    """The twin with one group of parameters taken from the person's truth (postures stay the twin's:
    measured through the assumed mountings, as the fusion sees them)."""
    if swap is Swap.TIMING:
        return replace(twin, onset_s=true.onset_s, reaction_s=true.reaction_s, spasm=true.spasm)
    keys = SWAP_KEYS[swap]
    classes = {c: replace(m, **{k: getattr(true.classes[c], k) for k in keys}) for c, m in twin.classes.items()}
    if swap is Swap.DRIFT:
        return replace(twin, classes=classes)
    neutral = replace(twin.neutral, **{k: getattr(true.neutral, k) for k in keys})
    spectrum = true.tremor_spectrum if swap is Swap.SWAY_TREMOR else twin.tremor_spectrum
    return replace(twin, classes=classes, neutral=neutral, tremor_spectrum=spectrum)


def ablation(person, twin: ParticipantParams, seeds: Sequence[tuple[int, int]]) -> dict[str, float]:
    """Predictions (same session seeds) of the twin with each group of parameters true, and of the
    person's true parameters performing the twin's protocol with the real mountings (what the
    participant model gives with every parameter right)."""
    out = {f"twin with true {swap.value} %": predicted(with_truth(twin, person.params, swap), person.profile,
                                                        seeds).mean for swap in Swap}
    true = replace(person.params, protocol=twin.protocol)
    out["true parameters %"] = predicted(true, person.profile, seeds, true_profile(person)).mean
    return out


def population_member(task: tuple[int, int, bool]) -> dict:
    """One synthetic person: the twin of pass 1, its recovery and its prediction of the pass 1 -> 2
    accuracy (and, with ``with_ablation``, the predictions with groups of true parameters)."""
    seed, pairs, with_ablation = task
    person = draw_person(seed)
    first, second = pass_recordings(person)
    with tempfile.TemporaryDirectory() as temp:
        twin = as_participant(fit_twin([first], person.profile, load_participant("P1"), f"twin-of-N{seed}",
                                       person.profile.name), Path(temp))
    with contextlib.redirect_stdout(io.StringIO()):
        seeds = person_session_seeds(seed, pairs)
        pred = predicted(twin, person.profile, seeds)
        real = accuracy(first, second, person.profile)
        swapped = ablation(person, twin, seeds) if with_ablation else {}
    return {"person": seed, "nodes": len(person.profile.nodes), "motions": len(person.params.classes),
            "pairs": pairs, "predicted_pct": pred.mean, "predicted_se": pred.standard_error,
            "per_pair_pct": list(pred.per_pair), "real_pct": real, "gap_points": pred.mean - real,
            "truth": truth_summary(person), "ablation": swapped, **recovery(person, twin)}


def truth_summary(person) -> dict[str, float | bool]:
    """What of a synthetic person the participant model has no parameter for."""
    return {"mounting_error_deg": person.mounting_error_deg,
            "neutral_drift_deg": float(np.abs(person.neutral_drift_deg).max()),
            "heading_drift_deg_per_min": float(np.abs(person.yaw_drift_deg_per_min).max()),
            "glitching_node": person.glitch is not None}


def population(first_seed: int, people: int, pairs: int, jobs: int, with_ablation: bool) -> list[dict]:
    """Each person's twin of pass 1: recovery, and its pass-to-pass prediction against the real pass 1 -> 2."""
    tasks = [(seed, pairs, with_ablation) for seed in range(first_seed, first_seed + people)]
    return run_tasks(population_member, tasks, jobs, "people", "person")


def population_markdown(rows: list[dict]) -> str:
    keys = [k for k in rows[0] if k not in ("person", "nodes", "motions", "pairs", "predicted_pct", "predicted_se",
                                            "per_pair_pct", "real_pct", "gap_points", "truth", "ablation")]
    gaps = np.array([r["gap_points"] for r in rows])
    lines = ["## Synthetic people (tasks/participants/population.py): the twin of pass 1 against the truth", "",
             "Parameter recovery, median over people (per person: median over classes and angles):", "",
             "| parameter | median | 10th-90th percentile |", "|---|---|---|"]
    for key in keys:
        values = [r[key] for r in rows]
        lines.append(f"| {key} | {np.median(values):+.3f} | {np.percentile(values, 10):+.3f} .. "
                     f"{np.percentile(values, 90):+.3f} |")
    lines += ["", "Prediction: the twin's session-to-session accuracy against the person's pass 1 -> 2 accuracy:", "",
              "| person | nodes | motions | predicted % | standard error | real pass 1 -> 2 % | gap |",
              "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['person']} | {r['nodes']} | {r['motions']} | {r['predicted_pct']:.2f} | {r['predicted_se']:.2f} | "
              f"{r['real_pct']:.2f} | {r['gap_points']:+.2f} |" for r in rows]
    lines += ["", f"Mean absolute gap {np.mean(np.abs(gaps)):.2f} points (mean gap {np.mean(gaps):+.2f}); within "
              f"{BAR_POINTS:g} points for {int(np.sum(np.abs(gaps) <= BAR_POINTS))} of {len(rows)} people; "
              f"median standard error of a prediction {np.median([r['predicted_se'] for r in rows]):.2f} points "
              f"({rows[0]['pairs']} session pairs).", ""]
    if rows[0]["ablation"]:
        lines += ablation_markdown(rows)
    return "\n".join(lines)


def ablation_markdown(rows: list[dict]) -> list[str]:
    """Per person: the prediction with each group of parameters true (same session seeds), and what
    the participant model has no parameter for."""
    names = list(rows[0]["ablation"])
    lines = ["Ablation (same session seeds): the twin's prediction with one group of its parameters replaced by "
             "the truth, and the true parameters themselves (real mountings). What is left between the last "
             "column and the real accuracy is what the participant model has no parameter for (the neutral "
             "posture's drift between passes, heading drift within a pass, glitching nodes) and the one draw the "
             "real pass 2 is.", "",
             "| person | twin % | " + " | ".join(names) + " | real % | mounting error (deg) | neutral drift (deg) "
             "| heading drift (deg/min) | glitch |", "|---" * (len(names) + 7) + "|"]
    for r in rows:
        t = r["truth"]
        lines.append(f"| {r['person']} | {r['predicted_pct']:.2f} | "
                     + " | ".join(f"{r['ablation'][n]:.2f}" for n in names)
                     + f" | {r['real_pct']:.2f} | {t['mounting_error_deg']:.1f} | {t['neutral_drift_deg']:.1f} | "
                       f"{t['heading_drift_deg_per_min']:.1f} | {'yes' if t['glitching_node'] else 'no'} |")
    real = np.array([r["real_pct"] for r in rows])
    lines.append("| mean abs gap to real | " + " | ".join(
        f"{np.mean(np.abs(np.array([r[k] if k == 'predicted_pct' else r['ablation'][k] for r in rows]) - real)):.2f}"
        for k in ["predicted_pct"] + names) + " | | | | | |")
    lines.append("| mean gap to real | " + " | ".join(
        f"{np.mean(np.array([r[k] if k == 'predicted_pct' else r['ablation'][k] for r in rows]) - real):+.2f}"
        for k in ["predicted_pct"] + names) + " | | | | | |")
    return lines + [""]


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
    ax.errorbar(real, pred, yerr=[r["predicted_se"] for r in rows], fmt="o", ms=4, capsize=2,
                label="twin (+- standard error)")
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


def markdown(rows: list[dict], command: str) -> str:
    gaps = np.array([r["gap_points"] for r in rows])
    within = int(np.sum(np.abs(gaps) <= BAR_POINTS))
    lines = [
        "# The twin of P1 fitted on one day, predicting the real accuracy on another day (out of sample)",
        "",
        f"`{command}`. Twin: day k alone (`bomi twin`, profile P1), its drift between days from a prior fitted on "
        "the three days that are neither k nor j. Prediction: the mean over pairs of the twin's synthetic sessions "
        "(`bomi synth`) of the mean of 1 -> 2 and 2 -> 1; standard error: the pairs' spread / sqrt(pairs). Real: "
        "train on day k, test on day j (`bomi evaluate --profile P1`).",
        "",
        "| train day k | test day j | session seeds | pairs | predicted % | standard error | real % | gap (points) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    lines += [f"| {r['train_day']} | {r['test_day']} | {r['seeds'][0]}-{r['seeds'][1]} | {r['pairs']} | "
              f"{r['predicted_pct']:.2f} | {r['predicted_se']:.2f} | {r['real_pct']:.2f} | {r['gap_points']:+.2f} |"
              for r in rows]
    lines += ["", f"Mean absolute gap {np.mean(np.abs(gaps)):.2f} points (mean gap {np.mean(gaps):+.2f}); "
              f"within {BAR_POINTS:g} points on {within} of {len(rows)} pairs (bar: at least {BAR_PAIRS}) -> "
              f"{'met' if within >= BAR_PAIRS else 'missed'}. Median standard error of a prediction "
              f"{np.median([r['predicted_se'] for r in rows]):.2f} points ({rows[0]['pairs']} session pairs).", ""]
    return "\n".join(lines)


def figure(rows: list[dict], path: Path) -> None:
    real = np.array([r["real_pct"] for r in rows])
    pred = np.array([r["predicted_pct"] for r in rows])
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    lo = min(real.min(), pred.min()) - 1
    ax.fill_between([lo, 100.5], [lo - BAR_POINTS, 100.5 - BAR_POINTS], [lo + BAR_POINTS, 100.5 + BAR_POINTS],
                    color="C2", alpha=0.15, label=f"within {BAR_POINTS:g} points")
    ax.plot([lo, 100.5], [lo, 100.5], "k--", lw=0.8)
    ax.errorbar(real, pred, yerr=[r["predicted_se"] for r in rows], fmt="o", ms=4, capsize=2, color="C0",
                label="twin (+- standard error)")
    for r in rows:
        ax.annotate(f"{r['train_day']}>{r['test_day']}", (r["real_pct"], r["predicted_pct"]), fontsize=6)
    ax.set_xlim(lo, 100.5)
    ax.set_ylim(lo, 100.5)
    ax.set_xlabel("real accuracy, train day k, test day j (%)")
    ax.set_ylabel("twin of day k: session-to-session accuracy (%)")
    ax.legend(loc="upper left", fontsize=8)
    labels = [f"{r['train_day']}>{r['test_day']}" for r in rows]
    bx.bar(labels, [r["gap_points"] for r in rows], yerr=[r["predicted_se"] for r in rows], capsize=2,
           color=["C0" if abs(r["gap_points"]) <= BAR_POINTS else "C3" for r in rows])
    bx.axhspan(-BAR_POINTS, BAR_POINTS, color="C2", alpha=0.15)
    bx.set_ylabel("predicted - real (points)")
    bx.tick_params(axis="x", labelrotation=90, labelsize=7)
    fig.suptitle("Twin of P1 fitted on one day vs the real day-to-day accuracy (out of sample)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def twin_main(args: argparse.Namespace) -> int:
    """The twin's out-of-sample check (day pairs of P1; synthetic people)."""
    for option, value, least in (("--pairs", args.pairs, 2), ("--jobs", args.jobs, 1)):
        if value < least:
            print(f"comparisons twin: error: {option} must be at least {least}, got {value}", file=sys.stderr)
            return 2
    started = time.perf_counter()
    directory = args.data or data_dir()
    if not args.skip_days:
        try:
            read_days(directory)
        except BomiError as exc:
            print(f"comparisons twin: error: {exc}", file=sys.stderr)
            return 2
    name = f"twin_validation_{args.first_seed}"
    command = " ".join(["python benchmarks/comparisons.py"] + sys.argv[1:])
    RESULTS.mkdir(exist_ok=True)
    record: dict = {"first_seed": args.first_seed, "pairs_per_prediction": args.pairs, "command": command}
    text = ""
    if not args.skip_days:
        rows = day_pairs(directory, args.first_seed, args.pairs, args.jobs)
        gaps = [abs(r["gap_points"]) for r in rows]
        record.update({"day_pairs": rows, "mean_abs_gap_points": float(np.mean(gaps)),
                       "pairs_within_bar": int(sum(g <= BAR_POINTS for g in gaps)), "bar_points": BAR_POINTS,
                       "bar_pairs": BAR_PAIRS})
        text = markdown(rows, command)
        figure(rows, RESULTS / f"{name}.png")
    if args.population:
        people = population(args.first_seed, args.population, args.pairs, args.jobs, args.ablation)
        record["population"] = people
        population_figure(people, RESULTS / f"{name}_population.png")
        text += "\n" + population_markdown(people)
        name += "_population" if args.skip_days else ""
    record["wall_time_s"] = round(time.perf_counter() - started, 1)
    text += f"\nWall time {record['wall_time_s']:.0f} s (--jobs {args.jobs}).\n"
    (RESULTS / f"{name}.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / f"{name}.md").write_text(text)
    print(text)
    return 0


# ------------------------------------------------------------- two benchmark runs as distributions
COUNTS = ("cube_drops", "mode_switches", "unintended_displacement_mm")


def fail(message: str) -> None:
    print(f"bomi: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def benchmark_episodes(path: Path) -> dict[str, dict[int, dict]]:
    """Per operator, the episodes by seed."""
    try:
        records = json.loads(path.read_text())["episodes"]
        out: dict[str, dict[int, dict]] = {}
        for episode in records:
            out.setdefault(episode["operator"], {})[episode["seed"]] = episode
    except (OSError, ValueError, KeyError, TypeError) as exc:
        fail(f"{path}: not a `bomi benchmark --json` file ({type(exc).__name__}: {exc})")
    return out


def compare(before: dict[int, dict], after: dict[int, dict]) -> dict:
    if sorted(before) != sorted(after):
        fail("--before and --after hold different task seeds")
    seeds = sorted(before)
    ok_b = [before[s]["success"] for s in seeds]
    ok_a = [after[s]["success"] for s in seeds]
    t_b = np.array([before[s]["completion_time"] for s in seeds if before[s]["success"]])
    t_a = np.array([after[s]["completion_time"] for s in seeds if after[s]["success"]])
    both = [s for s in seeds if before[s]["success"] and after[s]["success"]]
    paired = np.array([after[s]["completion_time"] - before[s]["completion_time"] for s in both])
    row = {"seeds": [seeds[0], seeds[-1]], "n": len(seeds),
           "successes": [int(sum(ok_b)), int(sum(ok_a))],
           "success_p_fisher": float(stats.fisher_exact([[sum(ok_b), len(seeds) - sum(ok_b)],
                                                         [sum(ok_a), len(seeds) - sum(ok_a)]])[1]),
           "time_median": [float(np.median(t_b)), float(np.median(t_a))],
           "time_mean": [float(t_b.mean()), float(t_a.mean())],
           "time_p_mannwhitney": float(stats.mannwhitneyu(t_b, t_a).pvalue),
           "time_p_ks": float(stats.ks_2samp(t_b, t_a).pvalue),
           "paired_time_difference_median": float(np.median(paired)) if len(paired) else None,
           "times": [t_b.tolist(), t_a.tolist()]}
    for key in COUNTS:
        b = np.array([before[s][key] for s in seeds], float)
        a = np.array([after[s][key] for s in seeds], float)
        same = np.array_equal(np.sort(b), np.sort(a))
        row[key] = {"total": [float(b.sum()), float(a.sum())], "mean": [float(b.mean()), float(a.mean())],
                    "p_mannwhitney": 1.0 if same else float(stats.mannwhitneyu(b, a).pvalue)}
    return row


def outcomes_markdown(record: dict) -> str:
    lines = [f"# Task outcomes before and after a physics change ({record['name']})", "",
             f"`python benchmarks/comparisons.py outcomes {record['command']} --out {record['name']}`", "", record["note"], "",
             "| operator | seeds | successes (before / after), Fisher p | completion time median s (before / after) | "
             "Mann-Whitney p | KS p | paired median difference s | cube drops (total) | mode switches (mean), p | "
             "unintended displacement mm (mean), p |", "|---|---|---|---|---|---|---|---|---|---|"]
    for operator, r in record["operators"].items():
        drops, switches, disp = (r[k] for k in COUNTS)
        lines.append(
            f"| {operator} | {r['seeds'][0]}-{r['seeds'][1]} | {r['successes'][0]} / {r['successes'][1]} of {r['n']}, "
            f"{r['success_p_fisher']:.2f} | {r['time_median'][0]:.2f} / {r['time_median'][1]:.2f} | "
            f"{r['time_p_mannwhitney']:.2f} | {r['time_p_ks']:.2f} | {r['paired_time_difference_median']:+.2f} | "
            f"{drops['total'][0]:.0f} / {drops['total'][1]:.0f} | {switches['mean'][0]:.1f} / {switches['mean'][1]:.1f}, "
            f"{switches['p_mannwhitney']:.2f} | {disp['mean'][0]:.0f} / {disp['mean'][1]:.0f}, {disp['p_mannwhitney']:.2f} |")
    lines += ["", f"![completion time ECDFs]({record['name']}.png)"]
    return "\n".join(lines) + "\n"


def outcomes_figure(record: dict, path: Path) -> None:
    operators = record["operators"]
    fig, axes = plt.subplots(1, len(operators), figsize=(5 * len(operators), 3.6), squeeze=False)
    for ax, (operator, r) in zip(axes[0], operators.items()):
        for times, label in zip(r["times"], ("before", "after")):
            x = np.sort(times)
            ax.step(x, np.arange(1, len(x) + 1) / len(x), where="post", label=f"{label} (n={len(x)})")
        ax.set(title=f"{operator}: completion time, seeds {r['seeds'][0]}-{r['seeds'][1]}",
               xlabel="completion time (s)", ylabel="share of successful episodes")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def outcomes_main(args: argparse.Namespace) -> None:
    """Two `bomi benchmark --json` runs compared as distributions."""
    for path in args.before + args.after:
        if not path.is_file():
            fail(f"{path}: no such file")
    before, after = {}, {}
    for paths, into in ((args.before, before), (args.after, after)):
        for path in paths:
            into.update(benchmark_episodes(path))
    record = {"name": args.out, "note": args.note,
              "command": " ".join([f"--before {p}" for p in args.before] + [f"--after {p}" for p in args.after]),
              "operators": {op: compare(before[op], after[op]) for op in before if op in after}}
    if not record["operators"]:
        fail("--before and --after share no operator")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.out}.json").write_text(json.dumps(record, indent=1))
    (RESULTS / f"{args.out}.md").write_text(outcomes_markdown(record))
    outcomes_figure(record, RESULTS / f"{args.out}.png")
    print(outcomes_markdown(record))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    groups = parser.add_subparsers(dest="comparison", required=True)
    twin = groups.add_parser("twin", help="a twin's prediction against the person's real accuracy")
    twin.add_argument("--first-seed", type=int, required=True,
                        help="first synthetic-session seed of the day pairs (40 x --pairs are used), and the first "
                             "synthetic person of --population")
    twin.add_argument("--data", type=Path, default=None, help="directory of dayN_testp.mat (default: BOMI_DATA_DIR)")
    twin.add_argument("--population", type=int, default=0, metavar="N", help="also N synthetic people (default 0)")
    twin.add_argument("--skip-days", action="store_true", help="only the synthetic people")
    twin.add_argument("--pairs", type=int, default=DEFAULT_PAIRS,
                        help=f"pairs of synthetic sessions per prediction (default {DEFAULT_PAIRS}, at least 2)")
    twin.add_argument("--ablation", action="store_true",
                        help="population: also predict with each group of parameters true (5 more predictions)")
    twin.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    twin.set_defaults(run=twin_main)
    outcomes = groups.add_parser("outcomes", help="two bomi benchmark --json runs as distributions")
    outcomes.add_argument("--before", type=Path, required=True, action="append", help="bomi benchmark --json file(s)")
    outcomes.add_argument("--after", type=Path, required=True, action="append", help="the same runs after the change")
    outcomes.add_argument("--out", default="physics_outcomes", help="name of the result files in benchmarks/results")
    outcomes.add_argument("--note", default="", help="a line saying what changed between the two runs")
    outcomes.set_defaults(run=outcomes_main)
    args = parser.parse_args()
    return args.run(args) or 0


if __name__ == "__main__":
    sys.exit(main())
