"""The paper's "reliability over days" table on the published P1 recordings (`bomi reproduce`,
benchmarks/reproduce_table.py): the day-1 model tested on days 2..5 for FV1, FV2 and FV3, every
setting (LDA shrinkage, rejection threshold) chosen on day 1 alone (P1's direction spread, chosen
leave-one-day-out by benchmarks/direction_spread.py, comes with the profile); beside it the 5 x 5
day-pair matrix (a model trained on each day, tested on every other day) for P1's shipped settings
and for the per-person rule, each with and without training on smaller copies of the motions."""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi import paper
from bomi.chain import Evaluation, Selection, evaluate, evaluate_each, select_settings, select_settings_each, train
from bomi.classifier import PostProcessing
from bomi.features import FEATURE_KINDS
from bomi.derived import DERIVED_AMPLITUDE_SCALES
from bomi.profiles import SELECT, Profile
from bomi.recording import Recording, read_recording

DAYS = (1, 2, 3, 4, 5)


@dataclass
class FeatureReproduction:
    kind: str
    selection: Selection          # shrinkage and rejection threshold chosen on day 1
    within_day1: float | None     # whole-hold 3-fold CV accuracy within day 1 of the chosen settings
    days: dict[int, Evaluation]   # day -> without rejection
    rejecting: dict[int, Evaluation]  # day -> with the day-1 threshold


def read_days(directory: Path) -> dict[int, Recording]:
    """day -> the published recording of that day."""
    paths = {day: directory / f"day{day}_testp.mat" for day in DAYS}
    return {day: read_recording(path) for day, path in tqdm(paths.items(), desc="reading days", unit="day")}


def reproduce(recordings: dict[int, Recording], profile: Profile) -> list[FeatureReproduction]:
    """Day-1 model tested on days 2..5, for FV1, FV2, FV3; every setting chosen on day 1 alone."""
    out = []
    for kind in tqdm(FEATURE_KINDS, desc="feature vectors", unit="FV"):
        spec = replace(profile.spec, kind=kind)
        chosen = select_settings([recordings[1]], profile, spec)
        model = train([recordings[1]], replace(profile, amplitude_scales=chosen.amplitude_scales), spec,
                      chosen.shrinkage, PostProcessing())
        rejecting = PostProcessing(rejection_threshold=chosen.rejection_threshold)
        out.append(FeatureReproduction(
            kind, chosen, chosen.accuracy,
            {d: evaluate(model, recordings[d], profile.neutral_samples) for d in DAYS[1:]},
            {d: evaluate(model, recordings[d], profile.neutral_samples, rejecting) for d in DAYS[1:]}))
    return out


@dataclass
class DayPairs:
    """A model trained on each day with one way of setting the classifier, tested on every other day."""

    name: str
    accuracy: dict[tuple[int, int], float]   # (training day, test day) -> accuracy
    chosen: dict[int, str]                   # training day -> the settings used, and why

    @property
    def off_diagonal(self) -> list[float]:
        return [self.accuracy[pair] for pair in sorted(self.accuracy)]


def day_pair_variants(profile: Profile) -> dict[str, Profile]:
    """P1's shipped settings, the per-person rule (shrinkage and rejection threshold chosen on the
    training day), and each also trained on the motions at DERIVED_AMPLITUDE_SCALES of their size."""
    rule = replace(profile, shrinkage=SELECT, select_rejection=True)
    return {f"{profile.name} as shipped": profile,
            f"{profile.name} + smaller motions": replace(profile, amplitude_scales=DERIVED_AMPLITUDE_SCALES),
            "per-person rule": rule,
            "per-person rule + smaller motions": replace(rule, amplitude_scales=DERIVED_AMPLITUDE_SCALES)}


def day_pairs(recordings: dict[int, Recording], profile: Profile) -> list[DayPairs]:
    """Every ordered pair of days (20) for every variant; settings only ever chosen on the training day.
    A day's models are trained together (the variants that choose their settings share the candidates
    they have in common: ``select_settings_each``) and each day is tested once for all the models
    trained on the others (``evaluate_each``): the same models and scores, each computed once."""
    variants = day_pair_variants(profile)
    selecting = [name for name, variant in variants.items() if variant.shrinkage == SELECT or variant.select_rejection]
    models, chosen = {}, {name: {} for name in variants}
    progress = tqdm(total=len(variants) * len(DAYS), desc="day-pair models", unit="model")
    for train_day in DAYS:
        selections = dict(zip(selecting, select_settings_each([recordings[train_day]],
                                                              [variants[name] for name in selecting], profile.spec)))
        for name, variant in variants.items():
            selection = selections.get(name)
            model = models[name, train_day] = train([recordings[train_day]], variant, selection=selection)
            rejection = "off" if model.post.rejection_threshold is None else model.post.rejection_threshold
            chosen[name][train_day] = f"shrinkage {model.shrinkage}, rejection {rejection}" + (
                f" ({selection.reason})" if selection else "")
            progress.update()
    progress.close()
    scored = {}
    for test_day in DAYS:
        trained = [key for key in models if key[1] != test_day]
        for (name, train_day), evaluation in zip(trained, evaluate_each([models[key] for key in trained],
                                                                        recordings[test_day], profile.neutral_samples)):
            scored[name, train_day, test_day] = evaluation.accuracy
    return [DayPairs(name, {(a, b): scored[name, a, b] for a in DAYS for b in DAYS if a != b}, chosen[name])
            for name in variants]


def reproduction_record(rows: list[FeatureReproduction], pairs: list[DayPairs]) -> dict:
    def pooled(evaluations: dict[int, Evaluation]) -> dict:
        truth = np.concatenate([e.truth for e in evaluations.values()])
        predicted = np.concatenate([e.predicted for e in evaluations.values()])
        rejected = np.concatenate([e.rejected for e in evaluations.values()])
        return {"accepted_accuracy": float(np.mean(predicted[~rejected] == truth[~rejected])),
                "rejected_share": float(np.mean(rejected))}

    return {
        "paper_day1_model_fv3": paper.DAY1_MODEL_PCT,
        "method": "train on day 1 (the day-1 test recording stands in for the unpublished training recording), "
                  "test on days 2..5; settings chosen by a whole-hold 3-fold CV within day 1 (an extra "
                  "only when it beats the plain setting)",
        "features": {r.kind: {
            "shrinkage": r.selection.shrinkage, "rejection_threshold": r.selection.rejection_threshold,
            "settings": r.selection.describe(), "selection": r.selection.reason,
            "day1_cv_accuracy": r.selection.candidates,
            "within_day1_cv_accuracy": r.within_day1,
            "days": {d: {"accuracy": e.accuracy, "windows": int(len(e.truth))} for d, e in r.days.items()},
            "mean_accuracy_days_2_5": float(np.mean([e.accuracy for e in r.days.values()])),
            "with_rejection": {d: {"accuracy": e.accuracy, "accepted_accuracy": e.accepted_accuracy,
                                   "rejected_share": e.rejected_share} for d, e in r.rejecting.items()},
            "with_rejection_pooled_days_2_5": pooled(r.rejecting),
        } for r in rows},
        "day_pairs": {p.name: {
            "accuracy": {f"{a}->{b}": v for (a, b), v in sorted(p.accuracy.items())},
            "mean": float(np.mean(p.off_diagonal)), "worst": float(np.min(p.off_diagonal)),
            "worst_pair": "{}->{}".format(*min(p.accuracy, key=p.accuracy.get)),
            "settings": {str(day): text for day, text in p.chosen.items()},
        } for p in pairs},
    }


def reproduction_markdown(record: dict) -> str:
    features = record["features"]
    kinds = list(features)
    header = ["Day", "Paper FV3"] + kinds + [f"{k} + rejection: accepted (rejected)" for k in kinds]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    day1 = [f"{100 * features[k]['within_day1_cv_accuracy']:.2f}" for k in kinds]
    lines.append(f"| 1 (within day 1: paper 5-fold CV, ours whole-hold 3-fold) | {paper.DAY1_MODEL_PCT[1]:.2f} | "
                 + " | ".join(day1)
                 + " |" + " - |" * len(kinds))
    for day in DAYS[1:]:
        ours = [f"{100 * features[k]['days'][day]['accuracy']:.2f}" for k in kinds]
        rej = [f"{100 * features[k]['with_rejection'][day]['accepted_accuracy']:.2f} "
               f"({100 * features[k]['with_rejection'][day]['rejected_share']:.2f})" for k in kinds]
        lines.append(f"| {day} | {paper.DAY1_MODEL_PCT[day]:.2f} | " + " | ".join(ours + rej) + " |")
    paper_mean = np.mean([paper.DAY1_MODEL_PCT[d] for d in DAYS[1:]])
    means = [f"{100 * features[k]['mean_accuracy_days_2_5']:.2f}" for k in kinds]
    pooled = [f"{100 * features[k]['with_rejection_pooled_days_2_5']['accepted_accuracy']:.2f} "
              f"({100 * features[k]['with_rejection_pooled_days_2_5']['rejected_share']:.2f})" for k in kinds]
    lines.append(f"| mean 2..5 (rejection: pooled) | {paper_mean:.2f} | " + " | ".join(means + pooled) + " |")
    candidates = list(features[kinds[0]]["day1_cv_accuracy"])
    selection = ["| Day-1 CV | " + " | ".join(candidates) + " | chosen |", "|" + "---|" * (len(candidates) + 2)]
    for k in kinds:
        f = features[k]
        selection.append(f"| {k} | " + " | ".join(f"{100 * f['day1_cv_accuracy'][c]:.2f}" if c in f["day1_cv_accuracy"]
                                                  else "-" for c in candidates) + f" | {f['settings']} |")
    return ("Accuracy (%) of the day-1 model on each day; rejection columns: accuracy of accepted windows "
            "(share of windows rejected, %).\n\n" + "\n".join(lines) + "\n\n" + day_pairs_markdown(record["day_pairs"])
            + "\n\nSettings chosen on day 1 alone: accuracy (%) of the whole-hold 3-fold cross-validation "
              "per candidate setting (an extra replaces the plain setting only when it gains the required margin).\n\n"
            + "\n".join(selection) + "\n")


def day_pairs_markdown(pairs: dict) -> str:
    """Each variant's 5 x 5 matrix (rows: training day, columns: test day) with its mean and worst pair."""
    out = ["Day pairs: accuracy (%) of a model trained on the row's day, tested on the column's day "
           "(all 20 ordered pairs; a rejected window counts as the neutral class).\n"]
    for name, p in pairs.items():
        out.append(f"{name}: mean {100 * p['mean']:.2f}, worst {100 * p['worst']:.2f} (day {p['worst_pair']})\n")
        out.append("| train \\ test | " + " | ".join(f"day {d}" for d in DAYS) + " |")
        out.append("|" + "---|" * (len(DAYS) + 1))
        for a in DAYS:
            cells = ["-" if a == b else f"{100 * p['accuracy'][f'{a}->{b}']:.2f}" for b in DAYS]
            out.append(f"| day {a} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)
