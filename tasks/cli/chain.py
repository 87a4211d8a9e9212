"""`bomi train`, `bomi evaluate`, `bomi reproduce`, `bomi fuse`: the signal chain on recordings."""
from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi.chain import Evaluation, evaluate, require_for
from bomi.classifier import Model, PostProcessing
from bomi.dataset import data_dir
from bomi.derived import derive_profile, describe
from bomi.errors import BomiError
from bomi.features import FEATURE_KINDS, FeatureSpec
from bomi.files import atomic_output, check_input, write_text
from bomi.fusion import NodeCalibration, fused_recording, mounting_warnings
from bomi.model_io import SUFFIXES, check_model_for, load_model, save_model
from bomi.passes import in_sample_share, join, pass_bounds, passes_text, split_passes
from bomi.profiles import DEFAULT_NEUTRAL_SAMPLES, Profile, save_profile
from bomi.recording import RAW_SIGNALS, RECORDING_SUFFIXES, Recording, write_recording
from bomi.reproduce import day_pairs, read_days, reproduce, reproduction_markdown, reproduction_record
from tasks.cli import add_command
from tasks.cli.options import add_force, check_outputs, open_unit_interval, positive_int
from tasks.experiments.training import (class_listing, fit_and_report, fit_model, misread_warning, read,
                                       read_all_passes, read_passes, short_names)
from tasks.operators.stick import arm_profile


DEFAULT_CONFUSION = "confusion.png"  # evaluate's own output when --png names none


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(subparsers, "train")
    p.add_argument("recordings", nargs="+", metavar="RECORDING", help=".mat or .csv recordings")
    p.add_argument("--profile", help="profile name (P1, P4, P5) or TOML file (default: derived from the recordings, "
                                     "printed)")
    p.add_argument("--features", choices=FEATURE_KINDS, help="override the profile's feature vector (default: "
                                                              "the profile's)")
    p.add_argument("--out", required=True, help="model file to write (.json or .npz)")
    p.add_argument("--save-profile", metavar="PATH", help="also write the profile the model was trained for as TOML "
                                                          "(e.g. the derived one), for --profile PATH of live/evaluate")
    p.add_argument("--verbose", action="store_true", help="describe each recording and list the variables ignored")
    p.add_argument("--allow-missing-classes", action="store_true",
                   help="train even if the recordings have no samples of some classes of --profile (the model "
                        "then never outputs them); without it that is an error")
    add_force(p)
    p.set_defaults(func=train_command)

    p = add_command(subparsers, "evaluate")
    p.add_argument("--train", required=True, metavar="A", help="training recording, or a trained model (.json/.npz)")
    p.add_argument("--test", required=True, action="append", metavar="B", help="test recording (repeatable)")
    p.add_argument("--profile", help="profile name or TOML file (default: derived from the training recording, printed)")
    p.add_argument("--features", choices=FEATURE_KINDS,
                   help="override the feature vector, only when training (default: the profile's)")
    p.add_argument("--reject", type=open_unit_interval, metavar="P",
                   help="confidence rejection threshold (posterior, between 0 and 1; default: the model's)")
    p.add_argument("--vote", type=positive_int, metavar="N",
                   help="majority vote over the last N decisions (default: the model's)")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON")
    p.add_argument("--png", metavar="OUT", help=f"confusion matrix figure (default {DEFAULT_CONFUSION}, replaced on "
                                                "each run; a file you name is replaced only with --force)")
    p.add_argument("--verbose", action="store_true", help="describe each recording and list the variables ignored")
    add_force(p)
    p.set_defaults(func=evaluate_command)

    p = add_command(subparsers, "reproduce")
    p.add_argument("--data", type=Path, help="dataset directory (default: BOMI_DATA_DIR or ../shared/data/...)")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON")
    p.add_argument("--markdown", metavar="OUT", help="write the table as markdown")
    add_force(p)
    p.set_defaults(func=reproduce_command)

    p = add_command(subparsers, "fuse")
    p.add_argument("input", metavar="IN", help=".mat or .csv recording")
    p.add_argument("--out", required=True, help="CSV recording to write")
    p.add_argument("--profile", help="take the node calibrations from this profile "
                                     "(default: headset constants for node 1, uncalibrated otherwise)")
    p.add_argument("--verbose", action="store_true", help="describe the recording and list the variables ignored")
    add_force(p)
    p.set_defaults(func=fuse_command)

    p = add_command(subparsers, "split")
    p.add_argument("input", metavar="IN", help=".mat or .csv recording")
    p.add_argument("--out-dir", required=True, type=Path, help="directory to write IN's passes to, as "
                                                                "<stem>_pass<k>.csv (created if missing)")
    p.add_argument("--verbose", action="store_true", help="describe the recording and list the variables ignored")
    add_force(p)
    p.set_defaults(func=split_command)


# --------------------------------------------------------------------------------------- helpers

def _spec(profile: Profile, kind: str | None) -> FeatureSpec:
    return replace(profile.spec, kind=kind) if kind else profile.spec


def confusion_text(evaluation: Evaluation, classes: Sequence[int]) -> str:
    from sklearn.metrics import confusion_matrix

    matrix = confusion_matrix(evaluation.truth, evaluation.predicted, labels=list(classes))
    width = max(6, len(str(matrix.max())) + 1)
    lines = ["true\\pred " + "".join(f"c{c}".rjust(width) for c in classes)]
    lines += [f"c{c}".ljust(10) + "".join(str(v).rjust(width) for v in row) for c, row in zip(classes, matrix)]
    return "\n".join(lines)


def save_confusion_figure(path: Path, evaluations: Sequence[Evaluation], classes: Sequence[int],
                          names: Sequence[str]) -> None:
    from sklearn.metrics import confusion_matrix

    from tasks.experiments.figures import confusion_figure
    confusion_figure(path, [(f"{Path(ev.source).name}: accuracy {100 * ev.accuracy:.2f} % of {len(ev.truth):,} windows",
                             confusion_matrix(ev.truth, ev.predicted, labels=list(classes))) for ev in evaluations],
                     names)


def class_names(classes: Sequence[int], profile: Profile | None) -> list[str]:
    """``c<label>`` and, when the profile is known, the class's name (its joystick function for a long one)."""
    known = {cls.label: cls for cls in profile.classes} if profile else {}
    names = []
    for label in classes:
        cls = known.get(label)
        if cls is None:
            names.append(f"c{label}")
        else:
            name = cls.name if len(cls.name) <= 18 else cls.name[:17] + "…"
            names.append(f"c{label} {cls.function}: {name}" if cls.function != "neutral" else f"c{label} {name}")
    return names


def holds_text(ev: Evaluation) -> str:
    """The accuracy on the holds, the transitions left out said (or that there is nothing to leave out)."""
    if ev.allowances is None:
        return (f"on the holds: {100 * ev.holds_accuracy:.2f} %, the same windows (the recording keeps only its "
                "holds: no move to leave out)")
    return (f"on the holds: {100 * ev.holds_accuracy:.2f} % over {int(ev.holds.sum())} windows, the transitions "
            f"left out: {ev.allowances.text()}; the all-window figure scores the person's reaction to each cue too")


# -------------------------------------------------------------------------------------- commands
def settings_text(model: Model) -> str:
    """The classifier settings a model was trained with, in words."""
    rejection = "off" if model.post.rejection_threshold is None else model.post.rejection_threshold
    copies = ", ".join(f"{s:g}" for s in model.amplitude_scales) or "none"
    return f"shrinkage {model.shrinkage}, smaller copies {copies}, rejection threshold {rejection}"


def _derived(recordings: Sequence[Recording]) -> Profile:
    """The profile the recordings imply, printed."""
    profile = derive_profile(recordings)
    print(describe(profile))
    return profile


def train_command(args: argparse.Namespace) -> int:
    outputs = check_outputs({"--out": (args.out, SUFFIXES), "--save-profile": (args.save_profile, (".toml",))},
                            inputs=args.recordings + ([args.profile] if args.profile else []), force=args.force)
    out = outputs["--out"]
    for path in args.recordings:
        check_input(path, "recording")
    profile = arm_profile(args.profile) if args.profile else None
    recordings = read_all_passes(args.recordings, args.verbose)
    profile = profile or _derived(recordings)
    model = fit_and_report(recordings, profile, _spec(profile, args.features), args.allow_missing_classes)
    save_model(out, model, overwrite=args.force)
    print(f"trained {model.spec.kind} LDA on {len(recordings)} pass(es) of {len(args.recordings)} recording(s), "
          f"{settings_text(model)}: wrote {out}")
    if outputs["--save-profile"]:
        save_profile(outputs["--save-profile"], profile, overwrite=args.force)
        print(f"profile {profile.name}: wrote {outputs['--save-profile']} (bomi live --profile "
              f"{outputs['--save-profile']} --model {out} ...)")
    print(class_listing(profile, model.classes.tolist()))
    return 0


def _training_source(path: str) -> str:
    """'model' or 'recording', by suffix; anything else (a pickle, say) is refused by name."""
    suffix = Path(path).suffix.lower()
    if suffix in SUFFIXES:
        return "model"
    if suffix in RECORDING_SUFFIXES:
        return "recording"
    raise BomiError(f"{path}: --train takes a recording ({', '.join(RECORDING_SUFFIXES)}) or a model "
                    f"({', '.join(SUFFIXES)}), not '{suffix or 'no suffix'}' (pickles are never loaded)")


def evaluate_command(args: argparse.Namespace) -> int:
    inputs = [args.train, *args.test]
    png_named = args.png is not None
    outputs = check_outputs({"--png": (args.png if png_named else DEFAULT_CONFUSION, (".png",)),
                             "--json": (args.json, (".json",))},
                            inputs=inputs, force=args.force, defaults=() if png_named else ("--png",))
    kind = _training_source(args.train)
    check_input(args.train, kind)
    profile = arm_profile(args.profile) if args.profile else None
    if kind == "model" and args.features:
        raise BomiError(f"{args.train}: --features only applies when training from a recording")
    model = None
    if kind == "model":
        model = load_model(args.train)
        if profile is not None:  # without a profile the model is taken as it is
            check_model_for(model, profile, args.train)
    training = None if model else read_passes(args.train, args.verbose)
    tests = read_all_passes(args.test, args.verbose)
    if training is not None:
        profile = profile or _derived(training)
    spec = model.spec if model else _spec(profile, args.features)
    for rec in tests:  # before any long work: every test recording holds what the model reads, and labels
        require_for(rec, spec)
        rec.require_labels()
    if model is None:
        model = fit_model(training, profile, spec)
    neutral_samples = profile.neutral_samples if profile else DEFAULT_NEUTRAL_SAMPLES
    post = PostProcessing(rejection_threshold=args.reject if args.reject is not None else model.post.rejection_threshold,
                          vote_length=args.vote if args.vote is not None else model.post.vote_length)
    evaluations = [evaluate(model, rec, neutral_samples, post)
                   for rec in tqdm(tests, desc="evaluating", unit="file", disable=len(tests) < 2)]
    results = []
    if model.cv_accuracy is not None:
        print(f"model: {settings_text(model)}")
    for rec, ev in zip(tests, evaluations):
        in_sample = in_sample_share(rec, model.training_runs)
        line = f"{rec.source}: accuracy {100 * ev.accuracy:.2f} % over {len(ev.truth)} windows"
        if in_sample > 0:
            share = "" if in_sample == 1 else f" for {100 * in_sample:.0f} % of its rows"
            line += (f" IN-SAMPLE{share}: the model was trained on these rows, so this is no measure of how it "
                     "reads new data (test on another pass or day)")
        elif model.cv_accuracy is not None:
            line += f" (the training CV estimated {100 * model.cv_accuracy:.2f} %)"
        if post.rejection_threshold is not None:
            line += (f"; rejected {100 * ev.rejected_share:.2f} %, accuracy of accepted windows "
                     f"{100 * ev.accepted_accuracy:.2f} %")
        print(line)
        print(f"  {holds_text(ev)}")
        print(confusion_text(ev, model.classes.tolist()))
        warning = misread_warning(ev.truth[ev.holds], ev.predicted[ev.holds], short_names(profile), rec.source)
        if warning:
            print(warning)
        allowance = None if ev.allowances is None else ev.allowances.seconds
        results.append({"test": rec.source, "accuracy": ev.accuracy, "in_sample_share": in_sample,
                        "cv_estimate": model.cv_accuracy,
                        "holds_accuracy": ev.holds_accuracy, "hold_windows": int(ev.holds.sum()),
                        "transition_allowance_s": None if allowance is None else {
                            "median": float(np.median(allowance)), "min": float(allowance.min()),
                            "max": float(allowance.max()), "moves_timed": ev.allowances.timed,
                            "cues": len(allowance)},
                        "windows": int(len(ev.truth)),
                        "rejected_share": ev.rejected_share, "accepted_accuracy": ev.accepted_accuracy})
    with atomic_output(outputs["--png"], overwrite=args.force or not png_named) as temp:
        save_confusion_figure(temp, evaluations, model.classes.tolist(), class_names(model.classes.tolist(), profile))
    print(f"confusion matrices: {outputs['--png']}")
    if outputs["--json"]:
        record = {"train": str(args.train), "features": model.spec.kind, "shrinkage": model.shrinkage,
                  "post_processing": {"rejection_threshold": post.rejection_threshold, "vote_length": post.vote_length},
                  "results": results}
        write_text(outputs["--json"], json.dumps(record, indent=1) + "\n", overwrite=args.force)
    return 0


def reproduce_command(args: argparse.Namespace) -> int:
    outputs = check_outputs({"--json": (args.json, (".json",)), "--markdown": (args.markdown, (".md",))},
                            force=args.force)
    directory = args.data or data_dir()
    if not directory.is_dir():
        raise BomiError(f"{directory}: dataset directory not found (set BOMI_DATA_DIR)")
    profile, recordings = arm_profile("P1"), read_days(directory)
    record = reproduction_record(reproduce(recordings, profile), day_pairs(recordings, profile))
    table = reproduction_markdown(record)
    print(table)
    if outputs["--json"]:
        write_text(outputs["--json"], json.dumps(record, indent=1) + "\n", overwrite=args.force)
    if outputs["--markdown"]:
        write_text(outputs["--markdown"], table, overwrite=args.force)
    return 0


def fuse_command(args: argparse.Namespace) -> int:
    out = check_outputs({"--out": (args.out, (".csv",))}, inputs=[args.input], force=args.force)["--out"]
    profile = arm_profile(args.profile) if args.profile else None
    rec = read(args.input, args.verbose)
    rec.require(rec.node_indices, RAW_SIGNALS, "fuse")
    bounds = pass_bounds(rec)
    if len(bounds) > 1:
        print(passes_text(rec, bounds).replace("calibrated and counted as one pass", "fused from its own start"))
    calibrations = {i: NodeCalibration.default_for(i) for i in rec.node_indices}
    if profile is not None:
        calibrations.update({n.index: n.calibration for n in profile.nodes})
    fused = join([fused_recording(p, calibrations) for p in split_passes(rec, bounds)], rec.source)
    for line in mounting_warnings(rec, fused, calibrations):
        print(line)
    write_recording(out, fused, overwrite=args.force)
    print(f"fused {len(rec)} samples of node(s) {list(rec.node_indices)}: wrote {out}")
    return 0


def split_command(args: argparse.Namespace) -> int:
    check_input(args.input, "recording")
    if args.out_dir.exists() and not args.out_dir.is_dir():
        raise BomiError(f"{args.out_dir}: --out-dir is a file, not a directory")
    rec = read(args.input, args.verbose)
    bounds = pass_bounds(rec)
    passes = split_passes(rec, bounds)
    stem = Path(args.input).stem
    paths = [args.out_dir / f"{stem}_pass{k}.csv" for k in range(1, len(passes) + 1)]
    args.out_dir.mkdir(parents=True, exist_ok=True)
    check_outputs({f"pass {k}": (path, (".csv",)) for k, path in enumerate(paths, start=1)}, inputs=[args.input],
                  force=args.force)
    one = "no Time clock" if rec.time is None else "no pause of the Time clock longer than a move's"
    print(passes_text(rec, bounds).replace(": each is calibrated and counted as one pass", "")
          if len(bounds) > 1 else f"{rec.source}: one pass ({one})")
    for path, part in zip(paths, passes):
        write_recording(path, part, overwrite=args.force)
        print(f"{part.source}: {len(part)} rows: wrote {path}")
    return 0
