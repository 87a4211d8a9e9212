"""`bomi trial` (the paper's session: N trials per controller, scored, logged, reported) and
`bomi replay` (a logged trial re-run, or re-scored with another model). See tasks.trials."""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from bomi.chain import OnlineChain
from bomi.errors import BomiError
from bomi.files import check_input
from bomi.model_io import check_model_for, load_model, save_model
from bomi.profiles import save_profile
from bomi.serial_source import BASE_STATION_BAUD, RetryPolicy, SerialSource, StreamReader
from sim.env import ArmSim
from sim.joystick import BUTTONS, THREE_AXIS
from tasks.cli import add_command
from tasks.cli.options import add_force, non_negative_int, non_negative_seconds, positive_int, seconds, seed
from tasks.cli.task import _simulated_time, _stage
from tasks.planner import DEFAULT_OPERATOR_FILE, Controls, load_operator
from tasks.stick import arm_profile, profile_layout
from tasks.trials.session import (DEFAULT_COUNTDOWN_S, DEFAULT_TIME_LIMIT_S, DEFAULT_TRIALS, Controller, Session,
                                  SimulatedClock, TappedParser, TickRecorder, TrialArm, TrialDisplay, TrialPlan,
                                  TrialStatusLine,
                                  episode_log, node1_id, run_bomi, run_joystick, trial_record)

# what a session writes into its directory (--force replaces these, and only these)
FILES = ("trials.jsonl", "bomi.h5", "joystick.h5", "model.json", "profile.toml", "report.md", "trial_times.png",
         "timeline_bomi.png", "timeline_joystick.png")


def _say(line: str) -> None:
    print(f"trial: {line}", file=sys.stderr, flush=True)


def _controllers(text: str) -> list[Controller]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    allowed = [c.value for c in Controller]
    bad = [name for name in names if name not in allowed]
    if bad or not names or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"a comma-separated list of {', '.join(allowed)} without repeats, "
                                         f"got {text!r}")
    return [Controller(name) for name in names]


def register(subparsers: argparse._SubParsersAction) -> None:
    trial = add_command(
        subparsers, "trial",
        description="The paper's session: for each controller N trials of the stacking task, each from the "
                    "task's start after a countdown, timed from the first command to success or the time limit, "
                    "scored like `bomi benchmark`'s episodes (DIR/trials.jsonl), every tick logged (DIR/bomi.h5, "
                    "DIR/joystick.h5; docs/trials.md) and reported (DIR/report.md, timeline figures). The BoMI "
                    "runs on the live loop (`bomi live`'s safety); the joystick is a gamepad, or the viewer's keys. "
                    "--stand-in puts a virtual participant at the controls: no person needed, and time then runs "
                    "as fast as the simulation allows (a simulated clock).")
    who = trial.add_mutually_exclusive_group()
    who.add_argument("--stand-in", metavar="PARTICIPANT",
                     help="a virtual participant (P1, P4, P5 or a participant TOML file) at the controls")
    who.add_argument("--port", metavar="PORT_OR_URL",
                     help="a person (the default without --stand-in): the BoMI's base-station stream (serial "
                          "port, pty path or pyserial URL)")
    trial.add_argument("--controller", type=_controllers, default=[Controller.BOMI, Controller.JOYSTICK],
                       help="comma-separated controllers, in session order (default bomi,joystick)")
    trial.add_argument("--profile", help="the BoMI's profile (a shipped name or a TOML file; default: the "
                                         "stand-in's own profile)")
    trial.add_argument("--model", type=Path, help="the BoMI's model file (.json/.npz) for the profile (with "
                                                  "--port: required; with --stand-in: default, the stand-in "
                                                  "calibrates through its stream first)")
    trial.add_argument("--gamepad", type=non_negative_int, metavar="N",
                       help="a person's joystick: gamepad N (pygame's numbering; needs bomi-jaco[gamepad]; "
                            "default: gamepad 0 if there is one, else the viewer's keys)")
    trial.add_argument("--trials", type=positive_int, default=DEFAULT_TRIALS,
                       help="trials per controller (default %(default)s)")
    trial.add_argument("--countdown", type=non_negative_seconds, default=DEFAULT_COUNTDOWN_S,
                       help="seconds of countdown before each trial, the arm held (default %(default)s)")
    trial.add_argument("--time-limit", type=seconds, default=DEFAULT_TIME_LIMIT_S,
                       help="seconds from the go before a trial fails (default %(default)s)")
    trial.add_argument("--seed", type=seed, default=0,
                       help="cube placements (k-th trial: seed + k - 1) and the stand-in's body and noise "
                            "(default %(default)s)")
    trial.add_argument("--predict", metavar="PARTICIPANT",
                       help="also simulate this virtual participant's episodes on the same cube placements "
                            "and set them beside the trials in the report (default: none)")
    trial.add_argument("--operator-file", type=Path, default=DEFAULT_OPERATOR_FILE,
                       help="the stand-in's scripted user (TOML; default: the shipped tasks/operator.toml)")
    trial.add_argument("--headless", action="store_true", help="no viewer window (default: a window when a "
                                                               "display is there)")
    trial.add_argument("--baud", type=positive_int, default=BASE_STATION_BAUD,
                       help="baud rate of a real port (default %(default)s)")
    trial.add_argument("--retries", type=non_negative_int, default=RetryPolicy.attempts,
                       help="reconnection attempts after the stream is lost (default %(default)s)")
    trial.add_argument("--out", type=Path, required=True, help="output directory (must not exist unless --force)")
    add_force(trial)
    trial.set_defaults(func=cmd_trial)

    replay = add_command(
        subparsers, "replay",
        description="Re-run a logged trial of a `bomi trial` directory from its logged frames (BoMI) or stick "
                    "(joystick) through the chain and the simulated arm, and compare the hand's path with the "
                    "logged one; with --model, re-score the trial's decisions offline with another model.")
    replay.add_argument("dir", type=Path, help="a `bomi trial` output directory")
    replay.add_argument("--trial", type=positive_int, required=True, help="the trial's number (trials.jsonl)")
    replay.add_argument("--model", type=Path, help="re-score the decisions with this model instead (accuracy only)")
    replay.set_defaults(func=cmd_replay)


# ---------------------------------------------------------------------------------- bomi trial
def _check_out(out: Path, force: bool) -> None:
    if out.exists() and not out.is_dir():
        raise BomiError(f"{out}: --out must be a directory, this is a file")
    if out.exists() and not force:
        raise BomiError(f"{out}: directory exists, not writing into it (--force replaces a session's files in it)")
    if not out.parent.is_dir():
        raise BomiError(f"{out}: directory {out.parent} does not exist")
    if not os.access(out.parent, os.W_OK):
        raise BomiError(f"{out}: directory {out.parent} is not writable")


def _viewer(headless: bool, sim: ArmSim, keys=None):
    """The viewer (or headless, as `bomi live` decides); with the viewer's keys as the stick, the
    viewer (``_person_stick`` checked that it opens)."""
    from tasks.cli.live import _viewer as live_viewer
    if keys is None:
        return live_viewer(headless, sim)
    from tasks.live import PassiveViewer
    return PassiveViewer(sim.model, sim.data, key_callback=keys.key)


def cmd_trial(args: argparse.Namespace) -> int:
    out: Path = args.out
    _check_out(out, args.force)
    from tasks.participants.participant import check_against_profile, load_participant
    standin = load_participant(args.stand_in) if args.stand_in is not None else None
    if args.predict is not None:
        load_participant(args.predict)  # a bad name fails before the session
    profile_name = args.profile or (standin.profile if standin is not None else None)
    bomi = Controller.BOMI in args.controller
    if bomi and profile_name is None:
        raise BomiError("--profile: the BoMI needs a profile")
    if bomi and standin is None and args.port is None:
        raise BomiError("--port: a person's BoMI needs their base station's port (or --stand-in for a virtual one)")
    if bomi and args.port is not None and args.model is None:
        raise BomiError("--model: a person's BoMI needs a model trained for the profile (bomi record / bomi train)")
    profile = arm_profile(profile_name) if profile_name is not None else None
    if standin is not None and profile is not None:
        check_against_profile(standin, profile)
    if args.model is not None and profile is None:
        raise BomiError("--model: give the --profile it was trained for")
    if args.gamepad is not None and standin is not None:
        raise BomiError("--gamepad: the stand-in drives its own stick; a gamepad is for a person (--port)")
    model = None
    if args.model is not None:
        model = load_model(check_input(args.model, "model"))
        check_model_for(model, profile, args.model)
    operator = load_operator(check_input(args.operator_file, "--operator-file")) if standin is not None else None
    device = stream = None
    if Controller.JOYSTICK in args.controller and standin is None:
        device = _person_stick(args.gamepad, args.headless)
    if bomi and args.port is not None:  # a bad port fails before anything is written
        stream = StreamReader(SerialSource(args.port, baudrate=args.baud, retry=RetryPolicy(attempts=args.retries),
                                           parser=TappedParser()))
        try:
            stream.start()  # read from now on, so that the sender never waits (what arrives before the loop: dropped)
        except BaseException:
            if device is not None:
                device.close()
            raise
    if bomi and model is None:
        from tasks.episode import calibrated_model
        with _stage(f"{standin.name}: calibration through its stream (the protocol performed, recorded as bomi "
                    f"record does, then bomi train)", progress=True):
            model = calibrated_model(standin, profile, args.seed)
    out.mkdir(exist_ok=True)
    for name in FILES:  # --force: no file of an earlier session stays beside this one's
        (out / name).unlink(missing_ok=True)
    sessions: list[tuple[Session, dict]] = []  # each as soon as it exists: a lost input loses nothing
    first = 1
    try:
        for controller in args.controller:
            plan = TrialPlan(args.trials, args.countdown, args.time_limit, args.seed, first)
            if controller is Controller.BOMI:
                _bomi_session(args, plan, profile, model, standin, operator, stream, sessions)
            else:
                _joystick_session(args, plan, standin, operator, device, sessions)
            first += args.trials
            if sessions and sessions[-1][0].stopped:
                break  # the person closed the viewer: the session ends here
    finally:
        if device is not None:
            device.close()
        if stream is not None:
            stream.stop()
        records, logs = _score(sessions, standin is not None)
        _write(out, records, sessions, profile, model)
    predictions = _predictions(args) if args.predict is not None else []
    from tasks.trials.report import write_report
    note = (f"Stand-in {standin.name} (seed {args.seed}), simulated clock." if standin is not None
            else f"A person; stream {args.port}.")
    written = write_report(out, records, logs, predictions, note)
    for r in records:
        verdict = f"{r['completion_time']:.2f} s" if r["success"] else f"failed ({r['failure']})"
        acc = r.get("accuracy_all_decisions")
        print(f"trial {r['trial']} {r['operator']}: {verdict}, {r['mode_switches']} mode switches"
              + (f", accuracy {100 * acc:.1f} %" if acc is not None else ""))
    print(f"wrote {out / 'trials.jsonl'}, " + ", ".join(str(p) for p in written))
    return 0


def _score(sessions: list[tuple[Session, dict]], intent_known: bool) -> tuple[list[dict], dict]:
    """Every finished trial's record (trials.jsonl) and episode log (the figures)."""
    records, logs = [], {}
    for session, meta in sessions:
        for result in session.finished:
            log = episode_log(session.recorder, result, **meta["log"])
            logs[result.number] = log
            records.append(trial_record(log, result.number, intent_known))
    return records, logs


def _write(out: Path, records, sessions, profile, model) -> None:
    """Everything recorded so far (also after a lost input)."""
    from tasks.trials.dataset import write_session
    with open(out / "trials.jsonl", "w", encoding="utf-8") as f:
        for record in records:
            f.write(json.dumps(record) + "\n")
    for session, meta in sessions:
        write_session(out / f"{session.controller.value}.h5", session, meta["attrs"])
    if model is not None and any(s.controller is Controller.BOMI for s, _ in sessions):
        save_model(out / "model.json", model, overwrite=True)
        save_profile(out / "profile.toml", profile, overwrite=True)


def _bomi_session(args, plan: TrialPlan, profile, model, standin, operator, source, sessions) -> None:
    from tasks.live import Headless, StatusLine
    sim = ArmSim(layout=profile_layout(profile))
    chain = OnlineChain(model, profile)
    arm = TrialArm(sim, plan)
    who = standin.name if standin is not None else "person"
    meta = {"log": {"operator": "bomi", "participant": who, "controls": _controls_label(profile),
                    "class_names": tuple(c.function for c in sorted(profile.classes, key=lambda c: c.label)),
                    "neutral": 0, "amplitude": profile.amplitude},
            "attrs": {"profile": profile.name, "participant": who, "layout": sim.layout.name,
                      "classes": {str(c.label): f"{c.function} ({c.name})" for c in profile.classes},
                      "plan": vars(plan), "seed": args.seed}}
    try:
        if standin is not None:
            from tasks.trials.standin import BomiStandIn, StandInSource
            clock = SimulatedClock()
            person = BomiStandIn(arm, standin, profile, chain, operator, args.seed)
            source = StandInSource(person, clock)
            session = Session(Controller.BOMI, arm, TickRecorder(arm, source.parser, person, node1_id(chain)),
                              "simulated")
            sessions.append((session, meta))
            meta["log"]["allowance"] = meta["attrs"]["allowance"] = person.allowance
            with _simulated_time(f"{standin.name} bomi session", progress=True) as progress:
                def on_tick(tick) -> None:
                    person.heard(tick.decisions)
                    progress(clock.now)
                run_bomi(session, source, chain, display=TrialDisplay(Headless(), arm, _say), on_tick=on_tick,
                         clock=clock, sleep=clock.sleep)
            if arm.not_ready is not None:
                raise BomiError(f"{standin.name}: {arm.not_ready}")
        else:
            session = Session(Controller.BOMI, arm, TickRecorder(arm, source.parser, None, node1_id(chain)), "wall")
            sessions.append((session, meta))
            meta["attrs"]["allowance"] = 0
            status, display = TrialStatusLine(arm, StatusLine()), TrialDisplay(_viewer(args.headless, sim), arm, _say)
            try:
                source.discard()  # what arrived while getting ready is old: never acted upon, nor logged
                run_bomi(session, source, chain, display=display, status=status)
            finally:
                source.stop()
                status.close()
                display.close()
            if arm.not_ready is not None:
                raise BomiError(f"{args.port}: {arm.not_ready}")
            if source.error is not None or not session.arm.finished:
                why = "stream lost" if source.error is not None else "the viewer was closed"
                session.cut_short(why)
                _say(f"{why}: the session stops here, the running trial fails; what was recorded is written "
                     f"to {args.out}")
                if source.error is not None:
                    raise source.error
    finally:
        sim.close()


def _joystick_session(args, plan: TrialPlan, standin, operator, device, sessions) -> None:
    sim = ArmSim(layout=THREE_AXIS)
    arm = TrialArm(sim, plan, ready=True)
    who = standin.name if standin is not None else "person"
    meta = {"log": {"operator": "joystick", "participant": who, "controls": Controls().label},  # the JACO's stick
            "attrs": {"participant": who, "layout": sim.layout.name, "plan": vars(plan), "seed": args.seed}}
    try:
        if standin is not None:
            from tasks.live import Headless
            from tasks.trials.standin import JoystickStandIn
            clock = SimulatedClock()
            person = JoystickStandIn(arm, operator)
            session = Session(Controller.JOYSTICK, arm, TickRecorder(arm, watcher=person), "simulated")
            sessions.append((session, meta))
            with _simulated_time(f"{standin.name} joystick session", progress=True) as progress:
                run_joystick(session, person, display=TrialDisplay(Headless(), arm, _say), clock=clock,
                             sleep=clock.sleep, on_tick=progress)
        else:
            from tasks.trials.devices import ViewerKeys
            session = Session(Controller.JOYSTICK, arm, TickRecorder(arm), "wall")
            sessions.append((session, meta))
            keys = device if isinstance(device, ViewerKeys) else None
            display = TrialDisplay(_viewer(args.headless, sim, keys), arm, _say)
            try:
                run_joystick(session, device, display=display)
            except BomiError:
                session.cut_short("input lost")
                _say(f"the joystick was lost: the session stops here, the running trial fails; what was "
                     f"recorded is written to {args.out}")
                raise
            finally:
                display.close()
            if not arm.finished:
                session.cut_short("the viewer was closed")
                _say(f"the viewer was closed: the session stops here; what was recorded is written to {args.out}")
    finally:
        sim.close()


def _person_stick(index: int | None, headless: bool):
    """A person's joystick: gamepad ``index``; by default gamepad 0, else the viewer's keys."""
    import time

    from tasks.live import display_opens, has_display
    from tasks.trials.devices import Gamepad, ViewerKeys
    if index is not None:
        return Gamepad(index)
    try:
        return Gamepad(0)
    except BomiError as exc:
        if headless or not (has_display() and display_opens()):
            raise BomiError(f"the joystick condition needs a gamepad or the viewer's keys: {exc}, and "
                            f"{'--headless' if headless else 'no display opens'}") from None
        _say("no gamepad: the joystick is the viewer's keys (arrows F/B/L/R, Q/E twist, 1/2 buttons)")
        return ViewerKeys(time.monotonic)


def _controls_label(profile) -> str:
    """The layout and buttons a profile's classes give (``tasks.planner.Controls.label``)."""
    functions = {cls.function for cls in profile.classes}
    buttons = tuple(b for b in BUTTONS if b in functions)
    return Controls(profile_layout(profile), buttons).label if buttons else profile_layout(profile).name


def _predictions(args) -> list[tuple[dict, object]]:
    """The named virtual participant's simulated episodes (``bomi benchmark``'s), one per trial, on
    the trials' cube placements: (record, episode log) each."""
    from tasks.cli.task import EpisodeJob, run_job
    from tasks.episode import summarize
    out = []
    for controller in args.controller:
        for k in range(args.trials):
            log = run_job(EpisodeJob(controller.value, args.predict, args.seed + k, args.time_limit), progress=True)
            out.append((summarize(log), log))
    return out


# ---------------------------------------------------------------------------------- bomi replay
def cmd_replay(args: argparse.Namespace) -> int:
    from tasks.trials.replay import load_trial, replay_trial, rescore_trial
    logged = load_trial(args.dir, args.trial)
    data, profile, model, controller = logged.data, logged.profile, logged.model, logged.controller.value
    if args.model is not None:
        if profile is None:
            raise BomiError(f"--model: trial {args.trial} was a joystick trial: there are no decisions to re-score")
        other = load_model(check_input(args.model, "model"))
        check_model_for(other, profile, args.model)
        scored = rescore_trial(data, args.trial, profile, other)
        print(f"replay: trial {args.trial}: {scored.logged_decisions} logged decisions"
              + _accuracy_text(scored.logged_accuracy, scored.logged_accuracy_excused))
        print(f"replay: re-scored with {args.model}: {scored.decisions} decisions"
              + _accuracy_text(scored.accuracy, scored.accuracy_excused)
              + f"; {100 * scored.agreement:.2f} % of the logged decisions decided alike")
        if scored.accuracy is None:
            print("replay: no accuracy: a person did this trial and nobody logged what they intended")
        print(f"replay: offline only: these decisions never drove an arm; with {args.model} at the controls the "
              f"arm's path would have differed (and the person's corrections with it)")
        return 0
    result = replay_trial(data, args.trial, profile, model)
    same = "the same" if result.success == result.logged_success else "NOT the same"
    print(f"replay: trial {args.trial} ({controller}): {result.ticks} ticks replayed ({result.logged_ticks} logged), "
          f"{'success' if result.success else 'failure'}, {same} outcome as logged")
    print(f"replay: max hand deviation {result.max_deviation_m:.3g} m")
    return 0


def _accuracy_text(every: float | None, excused: float | None) -> str:
    if every is None:
        return ""
    return f", accuracy {100 * every:.2f} % over all decisions ({100 * excused:.2f} % with transitions excused)"
