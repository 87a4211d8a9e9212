"""Training a person's classifier from their recordings, with what a clinician reads printed: the
passes found, the settings chosen by cross-validation, and how good the classifier is (a warning
naming the most confused classes below POOR_ACCURACY). Used by `bomi train`, `bomi record`,
`bomi twin` and the benchmarks."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bomi.chain import Selection, check_training_data, leave_one_pass_out, select_settings, train
from bomi.classifier import Model
from bomi.errors import BomiError
from bomi.features import FeatureSpec
from bomi.passes import check_class_sets, pass_bounds, passes_text, split_passes
from bomi.profiles import SELECT, Profile
from bomi.recording import Recording, read_recording

# Below this cross-validated accuracy a classifier is flagged to the clinician: the paper's three
# participants read 89-98 % offline (Table I), and at 85 % one window in seven is a wrong command.
POOR_ACCURACY = 0.85
CONFUSIONS_SHOWN = 3    # the most confused pairs of classes a warning names
CONFUSION_FLOOR = 0.05  # ... each read as the other in at least this share of its windows


def read(path: str | Path, verbose: bool) -> Recording:
    """``read_recording``; with ``verbose``, what it holds and the variables the chain ignores."""
    rec = read_recording(path)
    if verbose:
        print(rec.describe())
        if rec.ignored:
            print(f"{rec.source}: ignored {len(rec.ignored)} variable(s): {', '.join(rec.ignored)}")
    return rec


def read_passes(path: str | Path, verbose: bool) -> list[Recording]:
    """The passes of the protocol in one labelled recording (bomi.passes), said when there are several;
    a BomiError when they hold different classes."""
    rec = read(path, verbose)
    bounds = pass_bounds(rec)
    if len(bounds) > 1:
        print(passes_text(rec, bounds))
    passes = split_passes(rec, bounds)
    check_class_sets(passes)
    return passes


def read_all_passes(paths: Sequence[str | Path], verbose: bool) -> list[Recording]:
    """Every pass of every recording, in order."""
    return [p for path in paths for p in read_passes(path, verbose)]


def class_listing(profile: Profile, labels: Sequence[int]) -> str:
    """The classes a model knows, one per line, by label, joystick function and name."""
    by_label = {cls.label: cls for cls in profile.classes}
    return f"{len(labels)} classes:\n" + "\n".join(
        f"  c{label} {by_label[label].function}: {by_label[label].name}" for label in labels)



def fit_model(recordings: Sequence[Recording], profile: Profile, spec: FeatureSpec,
              allow_missing_classes: bool = False) -> Model:
    """Train ``profile``'s model, first checking every recording (``check_training_data``: a class of
    the profile without windows is an error unless ``allow_missing_classes``) and choosing (and
    printing) what the profile leaves to the person's own data."""
    return _fit(recordings, profile, spec, allow_missing_classes)[0]


def _fit(recordings: Sequence[Recording], profile: Profile, spec: FeatureSpec,
         allow_missing_classes: bool = False) -> tuple[Model, Selection | None]:
    check_training_data(recordings, profile, spec, allow_missing_classes)
    selection = None
    if profile.shrinkage == SELECT or profile.select_rejection:
        print("choosing the classifier settings on the training recording (cross-validation) ...", flush=True)
        selection = select_settings(recordings, profile, spec)
        print(selection.explain())
    return train(recordings, profile, spec, selection=selection, allow_missing_classes=allow_missing_classes), selection


def most_confused(truth: np.ndarray, decided: np.ndarray) -> list[tuple[int, int, float]]:
    """(class, read as, share of the class's windows) of the CONFUSIONS_SHOWN largest confusions of at
    least CONFUSION_FLOOR, largest first."""
    pairs = []
    for label in np.unique(truth):
        mine = decided[truth == label]
        for other, n in zip(*np.unique(mine[mine != label], return_counts=True)):
            if n / len(mine) >= CONFUSION_FLOOR:
                pairs.append((int(label), int(other), float(n / len(mine))))
    return sorted(pairs, key=lambda p: -p[2])[:CONFUSIONS_SHOWN]


def short_names(profile: Profile | None) -> dict[int, str]:
    """``c<label> (<function>)`` of each class of the profile (empty without one: ``c<label>``)."""
    return {cls.label: f"c{cls.label} ({cls.function})" for cls in profile.classes} if profile else {}


def misread_classes(truth: np.ndarray, decided: np.ndarray) -> list[tuple[int, float, list[tuple[int, float]]]]:
    """(class, share of its windows read as itself, [(read as, share), ...]) of every class read as
    itself in fewer than POOR_ACCURACY of its windows (the floor of the whole classifier, per class: a
    class below it is a wrong command in more than one window in seven), worst first; what it is read
    as: the other classes taking at least CONFUSION_FLOOR of its windows, most first."""
    out = []
    for label in np.unique(truth):
        mine = decided[truth == label]
        recall = float(np.mean(mine == label))
        if recall < POOR_ACCURACY:
            others, counts = np.unique(mine[mine != label], return_counts=True)
            read_as = sorted(((int(o), float(n / len(mine))) for o, n in zip(others, counts)
                              if n / len(mine) >= CONFUSION_FLOOR), key=lambda p: -p[1])
            out.append((int(label), recall, read_as))
    return sorted(out, key=lambda c: c[1])


def misread_warning(truth: np.ndarray, decided: np.ndarray, names: Mapping[int, str], source: str) -> str | None:
    """One warning line naming each class ``source`` reads as another (``misread_classes``), or None."""
    misread = misread_classes(truth, decided)
    if not misread:
        return None
    each = "; ".join(f"{names.get(label, f'c{label}')} read as itself in {100 * recall:.0f} % of its "
                     f"{np.count_nonzero(truth == label)} windows"
                     + (", as " + ", ".join(f"{names.get(o, f'c{o}')} in {100 * share:.0f} %" for o, share in read_as)
                        if read_as else "")
                     for label, recall, read_as in misread)
    return (f"warning: {source}: {len(misread)} class(es) below {100 * POOR_ACCURACY:g} % of their windows: {each}. "
            "The person makes these motions differently here than in the training recording (retrain on both, "
            "or record the motion again)")


def fit_and_report(passes: Sequence[Recording], profile: Profile, spec: FeatureSpec,
                   allow_missing_classes: bool = False) -> Model:
    """``fit_model``, then the one figure that says how good the classifier is, printed: with several
    passes, each decided by a model trained on the others (leave-one-pass-out); with one, the
    cross-validation within it. A warning, naming the classes most confused, when it is below POOR_ACCURACY."""
    model, selection = _fit(passes, profile, spec, allow_missing_classes)
    same_classes = len({tuple(sorted(set(p.labels.tolist()))) for p in passes}) == 1
    why = ("the passes hold different classes" if len(passes) > 1
           else "one pass: record a second for a figure on a pass the model has not seen")
    out = None
    if same_classes:
        try:
            out = leave_one_pass_out(passes, profile, model)
        except BomiError as exc:   # the passes but one cannot train every class: the within-pass figure
            why = f"no leave-one-pass-out figure: {exc}"
    if out is not None:   # judged on the holds: the person's reaction to each cue is no error of the classifier
        accuracy, headline = out.holds_accuracy, out.text()
        truth = np.concatenate([ev.truth[ev.holds] for ev in out.evaluations])
        decided = np.concatenate([ev.predicted[ev.holds] for ev in out.evaluations])
    elif selection is not None and selection.held_out is not None:
        accuracy, (truth, decided) = selection.accuracy, selection.held_out
        headline = f"cross-validated accuracy {100 * accuracy:.2f} % (whole holds held out within each pass; {why})"
    else:
        print("how good is this classifier: not estimated (no cross-validation: too little data or fixed settings)")
        return model
    print(f"how good is this classifier: {headline}")
    if out is not None:   # each pass read by the others' model: a class another pass reads as another, named
        warning = misread_warning(truth, decided, short_names(profile), "leave-one-pass-out")
        if warning:
            print(warning)
    if accuracy < POOR_ACCURACY:
        confused = ", ".join(f"c{a} read as c{b} in {100 * share:.0f} % of its windows"
                             for a, b, share in most_confused(truth, decided))
        print(f"warning: accuracy {100 * accuracy:.2f} % is below {100 * POOR_ACCURACY:g} %: about one window in "
              f"{max(2, round(1 / (1 - accuracy)))} would be a wrong command. Most confused: {confused or 'no single pair'}. "
              "Make those motions more distinct (or drop one), then record again")
    return model
