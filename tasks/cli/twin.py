"""`bomi twin`, `bomi synth`: a virtual participant fitted to a person's recordings, and its sessions."""
from __future__ import annotations

import argparse
import os
from dataclasses import replace
from pathlib import Path

from bomi.files import check_input, write_text
from bomi.derived import derive_profile, describe
from bomi.frames import SAMPLE_RATE_HZ
from bomi.profiles import Profile, save_profile
from bomi.recording import Recording, write_recording
from tasks.cli import add_command
from tasks.experiments.training import read_all_passes
from tasks.cli.options import add_force, check_outputs, non_negative_int
from bomi.errors import BomiError
from bomi.recording import check_recording_seconds
from tasks.experiments.twins import PAPER_HOLD_S, paper_protocol, self_check
from tasks.participants.participant import load_participant, parse_participant_text, protocol_session, session_recording
from tasks.participants.twin import fit_twin, same_person, twin_toml
from tasks.operators.stick import arm_profile

PROFILE_SUFFIX = ".profile.toml"   # a derived profile is written beside the twin: P.toml -> P.profile.toml
NO_PRIOR = "none"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(subparsers, "twin", description=(
        "Fit a virtual participant to a person's calibration recording(s) (a file holding several passes "
        "of the protocol, found by the pauses of its Time clock, counts as several): posture, "
        "repetition spread, sway and tremor of every class, onset and reaction time where the recording "
        "keeps the transitions, drift between passes where there are several; the rest from a prior "
        "participant. The file says per parameter what it was measured from, or which prior it took."))
    p.add_argument("recordings", nargs="+", metavar="REC", help="labelled .mat or .csv recordings: their passes "
                                                                "(days or sessions) are found in each")
    p.add_argument("--out", required=True, type=Path, help="participant TOML to write")
    p.add_argument("--profile", help="profile name (P1, P4, P5) or TOML file (default: derived from the recordings "
                                     f"as `bomi train` derives it, written beside --out as *{PROFILE_SUFFIX})")
    p.add_argument("--prior", default="P1", help="participant whose parameters stand in for what the recordings "
                                                 "cannot show (default %(default)s, fitted on P1's five days); "
                                                 f"'{NO_PRIOR}': everything must be measurable (timing is assumed)")
    p.add_argument("--name", help="the participant's name (default: the --out file's stem)")
    p.add_argument("--verbose", action="store_true", help="describe each recording and list the variables ignored")
    p.add_argument("--same-person", action="store_true",
                   help="the recordings are one person's even though their nodes or classes differ (default: "
                        "recordings that differ are refused as two people)")
    p.add_argument("--no-check", action="store_true",
                   help="skip the self-check (the twin's calibration cross-validated beside the person's; a few s)")
    add_force(p)
    p.set_defaults(func=twin_command)

    p = add_command(subparsers, "synth", description=(
        "A virtual participant performs the protocol of its source recording (same classes, order, hold and "
        "rest durations, same nodes) through simulated IMU frames and the fusion; written as a recording that "
        "`bomi train` and `bomi evaluate` read. Each seed is a different session (and day) of the same person."))
    p.add_argument("--participant", required=True, help="participant: a twin's TOML file, or P1, P4, P5")
    p.add_argument("--seed", type=non_negative_int, required=True, help="the session: its day, repetitions and noise")
    p.add_argument("--out", required=True, type=Path, help="CSV recording to write")
    add_force(p)
    p.set_defaults(func=synth_command)


def _profile_for(args: argparse.Namespace, recordings: list[Recording], derived: Path | None) -> tuple[Profile, str]:
    """(profile, what the participant file names as its profile): the one given (a file by its path
    relative to the twin's file, which reads it so: the two move together), else the one the recordings
    imply (as `bomi train` derives it, printed), written to ``derived``."""
    if derived is None:
        reference = args.profile
        if Path(args.profile).suffix.lower() == ".toml":
            reference = Path(os.path.relpath(Path(args.profile).resolve(), args.out.resolve().parent)).as_posix()
        return arm_profile(args.profile), reference
    profile = derive_profile(recordings)
    print(describe(profile))
    return profile, derived.name


def twin_command(args: argparse.Namespace) -> int:
    derived = None if args.profile else args.out.with_name(args.out.name.removesuffix(".toml") + PROFILE_SUFFIX)
    outputs = check_outputs({"--out": (args.out, (".toml",)), "derived profile": (derived, (".toml",))},
                            inputs=list(args.recordings) + ([args.profile] if args.profile else []), force=args.force)
    for path in args.recordings:
        check_input(path, "recording")
    prior = None if args.prior == NO_PRIOR else load_participant(args.prior)
    recordings = read_all_passes(args.recordings, args.verbose)
    if not args.same_person:
        same_person(recordings)
    derived = outputs["derived profile"]
    profile, reference = _profile_for(args, recordings, derived)
    name = args.name or args.out.name.removesuffix(".toml")
    twin = fit_twin(recordings, profile, prior, name, reference)
    for line in twin.fallbacks:
        print(f"not measurable, prior used: {line}")
    sources = ", ".join(Path(r.source).name for r in recordings)
    text = twin_toml(twin, f"Twin fitted on {sources} (profile {profile.name if derived is None else reference}).")
    try:  # the validator `bomi synth` reads it with: every twin written is a participant
        parse_participant_text(text, str(outputs["--out"]))
    except ValueError as exc:
        raise BomiError(f"{sources}: the twin fitted is no participant `bomi synth` accepts ({exc}); nothing "
                        "written") from None
    if derived is not None:
        save_profile(derived, replace(profile, name=name), overwrite=args.force)
        print(f"profile derived from the recordings: wrote {derived}")
    write_text(outputs["--out"], text, overwrite=args.force)
    if not args.no_check:
        print(self_check(outputs["--out"], recordings, profile))
    measured = sum(v.startswith("measured") for v in twin.provenance.values())
    print(f"twin {name}: {len(twin.postures)} motion classes on {len(profile.nodes)} node(s), {twin.passes} pass(es); "
          f"{measured} of {len(twin.provenance)} parameter groups measured ([provenance]); wrote {outputs['--out']}")
    print(f"its sessions: bomi synth --participant {outputs['--out']} --seed N --out session.csv; its episodes: "
          f"bomi run-task --operator bomi --participant {outputs['--out']}")
    return 0


def synth_command(args: argparse.Namespace) -> int:
    out = check_outputs({"--out": (args.out, (".csv",))}, inputs=[args.participant], force=args.force)["--out"]
    params = load_participant(args.participant)
    profile = arm_profile(params.profile)
    protocol = params.protocol
    if protocol is None:
        protocol = paper_protocol(sorted(params.classes))
        print(f"{params.name} was not fitted from a recording: performing the protocol of {protocol.source} "
              f"({len(protocol.labels)} runs of {PAPER_HOLD_S:g} s, holds only)")
    check_recording_seconds(sum(protocol.durations_s), f"{args.participant}: the [protocol] of {protocol.source}")
    session = protocol_session(params, profile, args.seed, protocol)
    rec = session_recording(session, profile, holds_only=protocol.holds_only)
    write_recording(out, rec, overwrite=args.force)
    labels = sorted(set(rec.labels.tolist()))
    print(f"{params.name}, seed {args.seed}: the protocol of {protocol.source} ({len(protocol.labels)} runs, "
          f"{'holds only' if protocol.holds_only else 'every row after the cue'}), {len(rec)} rows "
          f"({len(rec) / SAMPLE_RATE_HZ:.0f} s), node(s) {list(profile.node_indices)}, classes "
          f"{', '.join(f'c{c}' for c in labels)}: wrote {out}")
    return 0
