"""Replaying a logged trial: its session's logged bytes (BoMI) or stick (joystick), tick by tick at
the logged tick times, through the same loop, chain and simulated arm, up to the end of the trial;
then the hand's path and (BoMI) the decisions are set against the logged ones. The simulation is
deterministic, so the deviation is 0 up to floating point, and the decisions are the logged ones,
labels, gamma and nu to the bit. The trial must have run with the session's model.json and
profile.toml: their SHA-256 against the trial record's (``load_trial``; a session from before
the records kept them can only be judged by its decisions).

With another model, the trial's decisions are re-scored offline: the logged frames through a
chain of that model (the logged neutral offsets), each decision against the class the stand-in
performed. Those decisions never reach an arm: with them the arm's path would have differed.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bomi.chain import OnlineChain
from bomi.classifier import Model
from bomi.errors import BomiError
from bomi.frames import FrameParser, ImuFrame
from bomi.profiles import Profile
from sim.env import ArmSim
from sim.joystick import LAYOUTS, JoystickState
from tasks.operators.assist import NONE, parse_assist
from tasks.stacking import metrics
from tasks.stacking.env import stick_state
from tasks.trials.displays import Headless
from tasks.trials.checks import (RECORDS_FILE, check_against_record, check_logged_digest, check_logged_model,
                                 inside, read_records)
from tasks.trials.assisted import TrialAssistance
from tasks.trials.dataset import SessionData
from tasks.trials.session import (UNKNOWN, Controller, Session, SimulatedClock, TickRecorder, TrialArm, TrialDisplay,
                                  TrialPlan, run_joystick)


class LogEnded(Exception):
    """The log ends before the replayed trial does (a trial cut short by a lost input)."""


@dataclass
class LoggedStick:
    """The logged stick of each tick, in order (a ``session.StickDevice``)."""

    stick: np.ndarray
    pressed: np.ndarray
    k: int = 0

    def read(self, now: float) -> JoystickState:
        if self.k >= len(self.stick):
            raise LogEnded
        stick, pressed = self.stick[self.k], self.pressed[self.k]
        self.k += 1
        return stick_state(stick, pressed)  # a logged tick is an action of the env's space

    def close(self) -> None:
        """Nothing to release."""


@dataclass(frozen=True)
class DecisionsCompared:
    """A trial's replayed decisions against its logged ones, in order (tick, label, gamma, nu; gamma
    and nu compared bit for bit). ``first_difference``: the first pair that differs, described."""

    replayed: int
    logged: int
    alike: int
    first_difference: str | None = None

    @property
    def same(self) -> bool:
        return self.first_difference is None


@dataclass(frozen=True)
class Replayed:
    number: int
    ticks: int
    logged_ticks: int
    max_deviation_m: float
    success: bool
    logged_success: bool
    decisions: DecisionsCompared | None = None   # None: a joystick trial


Made = tuple[int, int, float, float]   # a decision: tick, label, gamma, nu


def _replay_bomi(data: SessionData, arm: TrialArm, chain: OnlineChain, made: list[Made],
                 assist: TrialAssistance) -> None:
    """The logged bytes of each tick through the live loop's tick (``tasks.trials.live.LiveLoop``, which is
    deterministic given its inputs) at the logged tick time, until the arm's last trial is over; the
    decisions the loop acted on, appended to ``made``."""
    from tasks.trials.live import LiveLoop

    def keep(tick) -> None:
        made.extend((tick.tick, d.label, d.gamma, d.nu) for d in tick.decisions)

    loop = LiveLoop(chain, arm, on_neutral=arm.ready, observers=[keep], assist=assist)
    parser, seen = FrameParser(), 0
    reconnected = data.ticks.get("reconnected", np.zeros(len(data.ticks["t"]), dtype=bool)).tolist()
    for t, chunk, again in zip(data.ticks["t"].tolist(), data.tick_bytes(), reconnected):
        if arm.finished:
            return
        frames = parser.feed(chunk, t)
        events = parser.safety_events[seen:]
        seen += len(events)
        loop.tick(t, frames, events, again)


def logged_assistance(data: SessionData, arm: TrialArm, profile: Profile | None) -> TrialAssistance:
    """The assistance the session ran with (its ``assist`` attribute; none in a file from before it was
    logged), on the replayed arm with the controls it had."""
    from tasks.stacking.vocabulary import Controls
    from tasks.stacking.channels import profile_controls
    options = parse_assist(data.attrs.get("assist", NONE), f"{data.path}: attribute assist")
    buttons = (profile_controls(profile) if profile is not None else Controls()).buttons
    return TrialAssistance(options, arm, arm.sim.layout, buttons)


def session_plan(data: SessionData) -> TrialPlan:
    return TrialPlan(**json.loads(data.attrs["plan"]))


def replay_trial(data: SessionData, number: int, profile: Profile | None, model: Model | None) -> Replayed:
    """Re-run the session of ``data`` up to the end of trial ``number``; its hand path against the log's."""
    row = data.trial_row(number)
    if row is None:
        raise BomiError(f"{data.path}: no trial {number} in this session")
    go, end = int(data.trials["go_tick"][row]), int(data.trials["end_tick"][row])
    sim = ArmSim(layout=LAYOUTS[data.attrs["layout"]])
    if not math.isclose(sim.dt, data.attrs["dt"], rel_tol=1e-9):
        sim.close()
        raise BomiError(f"{data.path}: attribute dt: logged at {data.attrs['dt']:g} s a tick, this simulated arm "
                        f"steps {sim.dt:g} s: not replayable here")
    try:
        controller = Controller(data.attrs["controller"])
        arm = TrialArm(sim, session_plan(data), ready=controller is Controller.JOYSTICK, last_trial=number)
        made: list[Made] = []
        assist = logged_assistance(data, arm, profile)
        if controller is Controller.BOMI:
            _replay_bomi(data, arm, OnlineChain(model, profile), made, assist)
        else:
            session = Session(controller, arm, TickRecorder(arm), "replay")
            clock = SimulatedClock()  # the joystick's ticks depend on nothing but their order
            try:
                run_joystick(session, LoggedStick(data.ticks["stick"], data.ticks["pressed"]),
                             display=TrialDisplay(Headless(), arm), clock=clock, sleep=clock.sleep, assist=assist)
            except LogEnded:
                pass  # a trial cut short: replayed up to where its log ends
    finally:
        sim.close()
    result = next((r for r in arm.results if r.number == number), None)
    if result is None:
        raise BomiError(f"{data.path}: trial {number} never started when replayed: the log does not hold the ticks "
                        f"before its go_tick {go}")
    stop = result.end_tick if result.end_tick >= 0 else len(arm.rows)  # cut short: the log's end
    replayed = np.array([r["hand_pos"] for r in arm.rows[result.go_tick:stop]])
    logged = data.ticks["hand_pos"][go:end]
    common = min(len(replayed), len(logged))
    deviation = float(np.max(np.linalg.norm(replayed[:common] - logged[:common], axis=1))) if common else float("nan")
    decisions = compare_decisions(data, made, go, min(end, stop)) if controller is Controller.BOMI else None
    return Replayed(number, stop - result.go_tick, end - go, deviation, result.success,
                    bool(data.trials["success"][row]), decisions)


def compare_decisions(data: SessionData, made: list[Made], go: int, end: int) -> DecisionsCompared:
    """The decisions replayed in ticks [go, end) against the logged ones of those ticks, pair by pair."""
    d = data.decisions
    span = (d["tick"] >= go) & (d["tick"] < end)
    logged = list(zip(d["tick"][span].tolist(), d["label"][span].tolist(), d["gamma"][span].tolist(),
                      d["nu"][span].tolist()))
    replayed = [m for m in made if go <= m[0] < end]
    alike, first = 0, None
    for k, (a, b) in enumerate(zip(logged, replayed)):
        if a[:2] == b[:2] and _bits(a[2:]) == _bits(b[2:]):
            alike += 1
        elif first is None:
            first = (f"decision {k + 1} (tick {a[0]}): logged c{a[1]} gamma {a[2]!r} nu {a[3]!r}, replayed "
                     f"c{b[1]} gamma {b[2]!r} nu {b[3]!r} (tick {b[0]})")
    if first is None and len(logged) != len(replayed):
        first = f"{len(logged)} logged, {len(replayed)} replayed"
    return DecisionsCompared(len(replayed), len(logged), alike, first)


def _bits(values: tuple[float, ...]) -> bytes:
    return np.array(values, dtype=np.float64).tobytes()


@dataclass(frozen=True)
class Rescored:
    """A trial's decisions re-made offline with another model. Accuracies are None when nobody knows
    what was intended (a person); ``agreement``: the share of the logged decisions the other model
    decided alike, decision by decision (matched by the frame that made them)."""

    decisions: int
    logged_decisions: int
    agreement: float
    accuracy: float | None = None
    accuracy_excused: float | None = None
    logged_accuracy: float | None = None
    logged_accuracy_excused: float | None = None


def rescore_trial(data: SessionData, number: int, profile: Profile, model: Model) -> Rescored:
    """Trial ``number``'s logged frames through a chain of ``model`` (offline, no arm, the logged
    neutral offsets), its decisions scored against the stand-in's intended classes (when known)
    beside the logged decisions' score."""
    row = data.trial_row(number)
    if row is None:
        raise BomiError(f"{data.path}: no trial {number} in this session")
    if data.attrs["controller"] != Controller.BOMI.value:
        raise BomiError(f"{data.path}: trial {number} was a joystick trial: there are no decisions to re-score")
    neutral = json.loads(data.attrs["neutral"] or "null")
    if neutral is None:
        raise BomiError(f"{data.path}: the session never took its neutral posture: nothing to re-score")
    go, end = int(data.trials["go_tick"][row]), int(data.trials["end_tick"][row])
    chain = OnlineChain(model, profile)
    chain.set_neutral({int(node): offset for node, offset in neutral.items()})
    f = data.frames
    made: dict[int, int] = {}  # frame row -> the other model's decision
    for k in range(int(np.searchsorted(f["tick"], end))):
        frame = ImuFrame(int(f["node_id"][k]), int(f["period_ms"][k]), int(f["counter"][k]),
                         tuple(int(v) for v in f["mag"][k]), tuple(int(v) for v in f["gyro"][k]),
                         tuple(int(v) for v in f["acc"][k]))
        decision = chain.push_frame(frame)
        if decision is not None and f["tick"][k] >= go:
            made[k] = decision.label
    d = data.decisions
    span = (d["tick"] >= go) & (d["tick"] < end)
    logged_rows, logged_labels = d["frame_row"][span], d["label"][span]
    alike = [made[r] == label for r, label in zip(logged_rows.tolist(), logged_labels.tolist()) if r in made]
    agreement = float(np.mean(alike)) if alike else float("nan")
    rows = np.array(sorted(made), dtype=int)
    intended = f["intended"][rows] if rows.size else np.zeros(0, int)
    if rows.size == 0 or np.any(intended == UNKNOWN):
        return Rescored(len(made), int(span.sum()), agreement)
    decided = np.array([made[r] for r in rows.tolist()])
    allowance = int(data.attrs["allowance"])
    return Rescored(len(made), int(span.sum()), agreement,
                    metrics.accuracy_all_decisions(intended, decided),
                    metrics.accuracy_excused_transitions(intended, decided, allowance),
                    metrics.accuracy_all_decisions(d["intended"][span], logged_labels),
                    metrics.accuracy_excused_transitions(d["intended"][span], logged_labels, allowance))


@dataclass(frozen=True)
class LoggedTrial:
    """A trial of a session directory, every file it needs read and checked: its session file, and
    for the BoMI the logged profile and the model, which must be the ones the session ran
    (``model_sha256``: the model file's digest as the trial record logged it and the file still has;
    None: the record predates the digests, and the model could not be checked)."""

    number: int
    controller: Controller
    data: SessionData
    profile: Profile | None = None
    model: Model | None = None
    model_sha256: str | None = None


def load_trial(directory: Path, number: int) -> LoggedTrial:
    """Trial ``number`` of the `bomi trial` directory ``directory``, checked before use (one line per fault)."""
    from bomi.files import check_input
    from bomi.model_io import load_model
    from tasks.operators.stick import arm_profile
    from tasks.trials.dataset import file_sha256, read_session, trial_file
    if not directory.is_dir():
        raise BomiError(f"{directory}: not a directory (a `bomi trial` output directory)")
    records = read_records(directory)
    if number not in records:
        raise BomiError(f"{directory / RECORDS_FILE}: no trial {number} (there are {len(records)})")
    record = records[number]
    path = inside(directory, trial_file(directory, record.controller.value, number).name)  # a resumed session: several
    data = read_session(check_input(path, "trial data"))
    if data.attrs["controller"] != record.controller.value:
        raise BomiError(f"{path}: a {data.attrs['controller']} session, trials.jsonl says trial {number} was "
                        f"{record.controller.value}")
    row = data.trial_row(number)
    if row is None:
        raise BomiError(f"{path}: no trial {number} in this session (trials.jsonl lists it)")
    check_against_record(path, record, data.trials, row)
    if record.controller is not Controller.BOMI:
        return LoggedTrial(number, record.controller, data)
    profile_path, model_path = inside(directory, "profile.toml"), inside(directory, "model.json")
    for file, what, logged in ((model_path, "model", record.model_sha256),
                               (profile_path, "profile", record.profile_sha256)):
        check_logged_digest(file, what, logged, file_sha256(check_input(file, what)))
    profile = arm_profile(check_input(profile_path, "profile"))
    model = load_model(check_input(model_path, "model"))
    check_logged_model(path, data.attrs, profile, model, model_path)
    return LoggedTrial(number, record.controller, data, profile, model, record.model_sha256)
