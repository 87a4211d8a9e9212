"""A twin (a virtual participant fitted to a person's recordings) checked against the person, and
the paper's calibration protocol for a participant fitted from none."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from bomi.chain import PLAIN, cross_validate
from bomi.classifier import NEUTRAL_LABEL
from bomi.profiles import Profile
from bomi.protocol import protocol_order
from bomi.recording import Recording
from tasks.participants.participant import Protocol, load_participant, protocol_session, session_recording

TWIN_MARGIN = 0.10   # the twin's calibration may read this far (share of windows) from the person's own: else a warning
PAPER_HOLD_S = 5.0                 # the paper's protocol, for a participant with no recording of its own
PAPER_REPETITIONS = 3


def self_check(twin_file: Path, recordings: list[Recording], profile: Profile) -> str:
    """The twin checked against the person: its own calibration (the first pass's protocol, seed 0)
    and the person's passes, each cross-validated as `bomi train` does (plain LDA, whole holds held
    out); both figures, and a warning when they differ by more than TWIN_MARGIN."""
    params = load_participant(twin_file)
    session = protocol_session(params, profile, 0, params.protocol)
    synthetic = session_recording(session, profile, holds_only=params.protocol.holds_only)
    plain = replace(profile, direction_spread=0.0)
    twin, person = (cross_validate(recs, plain, profile.spec, [PLAIN])[0].accuracy for recs in ([synthetic], recordings))
    text = (f"self-check: the twin's calibration reads {100 * twin:.1f} %, the person's own {100 * person:.1f} % "
            "(cross-validated, plain LDA, whole holds held out)")
    if abs(twin - person) > TWIN_MARGIN:
        text = (f"warning: {text}: more than {100 * TWIN_MARGIN:g} points apart; its episodes will not predict this "
                "person's (see the [provenance] of what was not measured)")
    return text


def paper_protocol(classes: list[int]) -> Protocol:
    """The paper's calibration: neutral, then each motion held 5 s three times, 5 s of neutral between."""
    runs = [NEUTRAL_LABEL]
    for label, _ in protocol_order(classes, PAPER_REPETITIONS, (1.0,)):
        runs += [label, NEUTRAL_LABEL]
    return Protocol(tuple(runs), (PAPER_HOLD_S,) * len(runs), True, "the paper's calibration")
