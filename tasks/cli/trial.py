"""`bomi trial` (the paper's session: N trials per controller, scored, logged, reported) and
`bomi replay` (a logged trial re-run, or re-scored with another model). See tasks.trials."""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
from pathlib import Path

from bomi.chain import OnlineChain
from bomi.errors import BomiError
from bomi.files import check_input
from bomi.model_io import check_model_for, load_model
from bomi.serial_source import BASE_STATION_BAUD, RetryPolicy, SerialSource, StreamReader
from sim.env import ArmSim
from sim.joystick import THREE_AXIS
from tasks.cli import add_command
from tasks.cli.options import MAX_SEED, add_force, non_negative_int, non_negative_seconds, positive_int, seconds, seed
from tasks.experiments.jobs import simulated_time, stage
from tasks.experiments.stop import StopRequest
from tasks.experiments.trials import (Committer, controls_label, lock_session, predictions, remaining_plans, say,
                                     session_assist)
from tasks.operators.assist import ASSIST_HELP, Assist, assist_label, assist_option
from tasks.operators.params import DEFAULT_OPERATOR_FILE, load_operator
from tasks.stacking.vocabulary import Controls
from tasks.operators.stick import arm_profile, profile_layout
from tasks.stacking.channels import profile_controls
from tasks.trials.assisted import TrialAssistance
from tasks.trials.dataset import part_name, replace_atomically, session_files
from tasks.trials.session import (DEFAULT_COUNTDOWN_S, DEFAULT_TIME_LIMIT_S, DEFAULT_TRIALS, Controller, Session,
                                  SimulatedClock, TappedParser, TickRecorder, TrialArm, TrialDisplay, TrialPlan,
                                  TrialStatusLine, node1_id, run_bomi, run_joystick)

SETTINGS_FILE = "session.json"   # the session's settings, what --resume continues with
# the options a session is run with, as session.json keeps them (--out, --force, --resume aside)
SETTINGS = ("stand_in", "port", "controller", "profile", "model", "gamepad", "trials", "countdown", "time_limit",
            "seed", "predict", "operator_file", "headless", "baud", "retries", "assist")




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
    trial.add_argument("--assist", type=assist_option, help=ASSIST_HELP)
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
                       help="the stand-in's scripted user (TOML; default: the shipped tasks/operators/operator.toml)")
    trial.add_argument("--headless", action="store_true", help="no viewer window (default: a window when a "
                                                               "display is there)")
    trial.add_argument("--baud", type=positive_int, default=BASE_STATION_BAUD,
                       help="baud rate of a real port (default %(default)s)")
    trial.add_argument("--retries", type=non_negative_int, default=RetryPolicy.attempts,
                       help="reconnection attempts after the stream is lost (default %(default)s)")
    where = trial.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", type=Path, help="output directory (must not hold a session unless --force: the "
                                                "earlier session is then moved aside to DIR.old-TIME once this "
                                                "one has a finished trial)")
    where.add_argument("--resume", type=Path, metavar="DIR",
                       help="continue the interrupted session in DIR from its next trial, with its settings "
                            "(DIR/session.json; no other option)")
    add_force(trial)
    trial.set_defaults(func=cmd_trial)

    replay = add_command(
        subparsers, "replay",
        description="Re-run a logged trial of a `bomi trial` directory from its logged frames (BoMI) or stick "
                    "(joystick) through the chain and the simulated arm, and compare the hand's path and the "
                    "decisions with the logged ones (DIR/model.json and DIR/profile.toml must be the files the "
                    "trial ran with: their SHA-256 is in its record); with --model, re-score the trial's "
                    "decisions offline with another model.")
    replay.add_argument("dir", type=Path, help="a `bomi trial` output directory")
    replay.add_argument("--trial", type=positive_int, required=True, help="the trial's number (trials.jsonl)")
    replay.add_argument("--model", type=Path, help="re-score the decisions with this model instead (accuracy only)")
    replay.set_defaults(func=cmd_replay)


# ---------------------------------------------------------------------------------- bomi trial
def _holds_session(out: Path) -> bool:
    """Whether ``out`` holds anything but this command's hidden files (its lock, a staging directory)."""
    return out.is_dir() and any(not entry.name.startswith(".") for entry in out.iterdir())


def _check_out(out: Path, force: bool) -> None:
    if out.exists() and not out.is_dir():
        raise BomiError(f"{out}: --out must be a directory, this is a file")
    if _holds_session(out) and not force:
        raise BomiError(f"{out}: directory holds a session, not writing into it (--resume {out} continues it, "
                        f"--force moves it aside once a new session has a finished trial)")
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
    from tasks.trials.displays import PassiveViewer
    return PassiveViewer(sim.model, sim.data, key_callback=keys.key)




def _settings_argv(args: argparse.Namespace) -> list[str]:
    """The session's options as a command line (paths made absolute, so that a resume from elsewhere reads them)."""
    argv = []
    for name in SETTINGS:
        value = getattr(args, name)
        if value is None or value is False:
            continue
        option = "--" + name.replace("_", "-")
        if value is True:
            argv.append(option)
            continue
        if name == "controller":
            value = ",".join(c.value for c in value)
        elif name == "assist":
            value = assist_label(value)
        elif isinstance(value, Path) or (name == "profile" and Path(value).is_file()):
            value = Path(value).resolve()
        argv += [option, str(value)]
    return argv


def _resumed(directory: Path) -> tuple[argparse.Namespace, list[dict]]:
    """The settings of the session in ``directory`` (checked as its command line is) and its trial records."""
    from tasks.cli import build_parser
    path = check_input(directory / SETTINGS_FILE, "--resume session settings")
    try:
        argv = json.loads(path.read_text(encoding="utf-8"))["argv"]
    except (ValueError, KeyError, TypeError) as exc:
        raise BomiError(f"{path}: not a session's settings ({exc})") from None
    if not isinstance(argv, list) or not all(isinstance(arg, str) for arg in argv):
        raise BomiError(f"{path}: argv: not a list of strings")
    args = build_parser([__name__]).parse_args(["trial", *argv, "--out", str(directory)])
    args.resume = directory
    if (directory / "model.json").is_file():   # the BoMI's model and profile as the session used them
        args.model, args.profile = directory / "model.json", str(directory / "profile.toml")
    records = []
    jsonl = directory / "trials.jsonl"
    if jsonl.exists():
        for n, line in enumerate(jsonl.read_text(encoding="utf-8").splitlines(), start=1):
            try:
                record = json.loads(line)
                records.append(record if isinstance(record["trial"], int) else {}["trial"])
            except (ValueError, KeyError, TypeError):
                raise BomiError(f"{jsonl}: line {n}: not a trial record") from None
    return args, records






def cmd_trial(args: argparse.Namespace) -> int:
    # SIGTERM, SIGHUP (a session manager, a closed terminal) and Ctrl-C end the session, always (tasks.experiments.stop)
    with StopRequest().installed() as stop:
        return _trial(args, stop)


def _trial(args: argparse.Namespace, stop: StopRequest) -> int:
    previous: list[dict] = []
    if args.resume is not None:
        if args.force:
            raise BomiError("--force: --resume continues a session, it replaces nothing")
        if not args.resume.is_dir():
            raise BomiError(f"{args.resume}: not a directory (a `bomi trial` output directory)")
        args, previous = _resumed(args.resume)
    out: Path = args.out
    if args.seed + args.trials - 1 > MAX_SEED:      # each controller's k-th trial: seed + k - 1
        raise BomiError(f"--seed: the session's last trial would have seed {args.seed + args.trials - 1}, "
                        f"above {MAX_SEED}")
    if args.resume is None:
        _check_out(out, args.force)
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)    # a file-size limit: EFBIG (one line), not a dead process
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
    plans = remaining_plans(args.controller, args.trials, args.countdown, args.time_limit, args.seed,
                            len(previous))
    if not plans:
        raise BomiError(f"{out}: every trial of this session has finished; nothing to resume")
    if standin is not None and profile is not None:
        check_against_profile(standin, profile)
    if args.model is not None and profile is None:
        raise BomiError("--model: give the --profile it was trained for")
    if bomi and standin is not None and not profile_controls(profile).buttons \
            and Assist.AUTO_MODE not in session_assist(Controller.BOMI, args.assist, profile):
        raise BomiError(f"--assist: profile {profile.name}'s controls change mode only by the automatic mode "
                        f"switching: the stand-in needs --assist {Assist.AUTO_MODE.value}")
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
    try:
        lock = lock_session(out)  # before calibration: a second session on this directory is refused here
    except BomiError:
        if device is not None:
            device.close()
        if stream is not None:
            stream.stop()
        raise
    # --force over a session: written beside it until the new session has a finished trial
    target = out / f".new-{os.getpid()}" if args.resume is None and _holds_session(out) else out
    try:
        if args.resume is None:
            target.mkdir(exist_ok=True)
            settings = json.dumps({"argv": _settings_argv(args)}, indent=1) + "\n"
            replace_atomically(target / SETTINGS_FILE, lambda partial: partial.write_text(settings, "utf-8"))
        if bomi and model is None:
            from tasks.stacking.channels import calibrated_model
            with stage(f"{standin.name}: calibration through its stream (the protocol performed, recorded as bomi "
                        f"record does, then bomi train)", progress=True):
                model = calibrated_model(standin, profile, args.seed)
        sessions: list[tuple[Session, dict]] = []  # each as soon as it exists: a lost input loses nothing
        writer = Committer(out, target, sessions, profile, model, standin is not None, previous)

        def after_tick(*_) -> None:
            stop.check()  # every tick: a signal whose raise was swallowed still ends the session
            writer.after_tick()

        lost: BomiError | None = None   # the input that cut the session short: raised once it is reported
        try:
            for controller, plan in plans:
                stop.check()
                part = len(session_files(out, controller.value)) + 1
                meta = {"file": part_name(controller.value, part)}
                if controller is Controller.BOMI:
                    _bomi_session(args, plan, profile, model, standin, operator, stream, sessions, meta, after_tick)
                else:
                    _joystick_session(args, plan, standin, operator, device, sessions, meta, after_tick)
                if sessions and sessions[-1][0].stopped:
                    break  # the person closed the viewer: the session ends here
        except BomiError as exc:
            if not (sessions and sessions[-1][0].stopped):
                raise
            lost = exc  # a lost stream or joystick cut the session short: its trials are reported too
        finally:
            with stop.shielded():  # a second signal does not cut the closing and the writing of the trials
                if device is not None:
                    device.close()
                if stream is not None:
                    stream.stop()
                records, logs = writer.commit()  # a trial cut short by a lost input is written too
        if lost is not None and not records:
            raise lost  # no trial of this run ended: nothing to report
        records = previous + records
        predicted = (predictions(args.controller, args.trials, args.predict, args.seed, args.time_limit)
                     if args.predict is not None else [])
        from tasks.trials.report import write_report
        note = (f"Stand-in {standin.name} (seed {args.seed}), simulated clock." if standin is not None
                else f"A person; stream {args.port}.")
        stop.check()
        written = write_report(out, records, logs, predicted, note)
        for r in records:
            verdict = f"{r['completion_time']:.2f} s" if r["success"] else f"failed ({r['failure']})"
            acc = r.get("accuracy_all_decisions")
            print(f"trial {r['trial']} {r['operator']}: {verdict}, {r['mode_switches']} mode switches"
                  + (f", accuracy {100 * acc:.1f} %" if acc is not None else ""))
        print(f"wrote {out / 'trials.jsonl'}, " + ", ".join(str(p) for p in written))
        if lost is not None:
            raise lost
        return 0
    finally:
        with stop.shielded():
            if target != out and target.exists():  # no trial finished: the earlier session stays as it was
                shutil.rmtree(target, ignore_errors=True)
                say(f"no trial finished: the earlier session in {out} is kept as it was")
            os.close(lock)




def _bomi_session(args, plan: TrialPlan, profile, model, standin, operator, source, sessions, meta: dict,
                  after_tick) -> None:
    from tasks.trials.displays import Headless, StatusLine
    sim = ArmSim(layout=profile_layout(profile))
    chain = OnlineChain(model, profile)
    arm = TrialArm(sim, plan)
    assist = TrialAssistance(session_assist(Controller.BOMI, args.assist, profile), arm, sim.layout,
                             profile_controls(profile).buttons)
    who = standin.name if standin is not None else "person"
    meta.update({"log": {"operator": "bomi", "participant": who, "controls": controls_label(profile),
                         "class_names": tuple(c.function for c in sorted(profile.classes, key=lambda c: c.label)),
                         "neutral": 0, "amplitude": profile.amplitude},
                 "attrs": {"profile": profile.name, "participant": who, "layout": sim.layout.name,
                           "classes": {str(c.label): f"{c.function} ({c.name})" for c in profile.classes},
                           "plan": vars(plan), "seed": args.seed, "assist": assist.label},
                 "assistance": assist})
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
            with simulated_time(f"{standin.name} bomi session", progress=True) as progress:
                def on_tick(tick) -> None:
                    person.heard(tick.decisions)
                    progress(clock.now)
                    after_tick()
                run_bomi(session, source, chain, display=TrialDisplay(Headless(), arm, say), on_tick=on_tick,
                         clock=clock, sleep=clock.sleep, assist=assist)
            if arm.not_ready is not None:
                raise BomiError(f"{standin.name}: {arm.not_ready}")
        else:
            session = Session(Controller.BOMI, arm, TickRecorder(arm, source.parser, None, node1_id(chain)), "wall")
            sessions.append((session, meta))
            meta["attrs"]["allowance"] = 0
            status, display = TrialStatusLine(arm, StatusLine()), TrialDisplay(_viewer(args.headless, sim), arm, say)
            try:
                source.discard()  # what arrived while getting ready is old: never acted upon, nor logged
                run_bomi(session, source, chain, display=display, status=status, on_tick=after_tick, assist=assist)
            finally:
                source.stop()
                status.close()
                display.close()
            if arm.not_ready is not None:
                raise BomiError(f"{args.port}: {arm.not_ready}")
            if source.error is not None or not session.arm.finished:
                why = "stream lost" if source.error is not None else "the viewer was closed"
                session.cut_short(why)
                say(f"{why}: the session stops here, the running trial fails; what was recorded is written "
                     f"to {args.out}")
                if source.error is not None:
                    raise source.error
    finally:
        sim.close()


def _joystick_session(args, plan: TrialPlan, standin, operator, device, sessions, meta: dict, after_tick) -> None:
    sim = ArmSim(layout=THREE_AXIS)
    arm = TrialArm(sim, plan, ready=True)
    controls = Controls()  # the JACO's joystick
    assist = TrialAssistance(session_assist(Controller.JOYSTICK, args.assist, None), arm, sim.layout, controls.buttons)
    who = standin.name if standin is not None else "person"
    meta.update({"log": {"operator": "joystick", "participant": who, "controls": controls.label},
                 "attrs": {"participant": who, "layout": sim.layout.name, "plan": vars(plan), "seed": args.seed,
                           "assist": assist.label},
                 "assistance": assist})
    try:
        if standin is not None:
            from tasks.trials.displays import Headless
            from tasks.trials.standin import JoystickStandIn
            clock = SimulatedClock()
            person = JoystickStandIn(arm, operator)
            session = Session(Controller.JOYSTICK, arm, TickRecorder(arm, watcher=person), "simulated")
            sessions.append((session, meta))
            with simulated_time(f"{standin.name} joystick session", progress=True) as progress:
                def on_tick(now: float) -> None:
                    progress(now)
                    after_tick()
                run_joystick(session, person, display=TrialDisplay(Headless(), arm, say), clock=clock,
                             sleep=clock.sleep, on_tick=on_tick, assist=assist)
        else:
            from tasks.trials.devices import ViewerKeys
            session = Session(Controller.JOYSTICK, arm, TickRecorder(arm), "wall")
            sessions.append((session, meta))
            keys = device if isinstance(device, ViewerKeys) else None
            display = TrialDisplay(_viewer(args.headless, sim, keys), arm, say)
            try:
                run_joystick(session, device, display=display, on_tick=after_tick, assist=assist)
            except BomiError:
                session.cut_short("input lost")
                say(f"the joystick was lost: the session stops here, the running trial fails; what was "
                     f"recorded is written to {args.out}")
                raise
            finally:
                display.close()
            if not arm.finished:
                session.cut_short("the viewer was closed")
                say(f"the viewer was closed: the session stops here; what was recorded is written to {args.out}")
    finally:
        sim.close()


def _person_stick(index: int | None, headless: bool):
    """A person's joystick: gamepad ``index``; by default gamepad 0, else the viewer's keys."""
    import time

    from tasks.trials.displays import display_opens, has_display
    from tasks.trials.devices import Gamepad, ViewerKeys
    if index is not None:
        return Gamepad(index)
    try:
        return Gamepad(0)
    except BomiError as exc:
        if headless or not (has_display() and display_opens()):
            raise BomiError(f"the joystick condition needs a gamepad or the viewer's keys: {exc}, and "
                            f"{'--headless' if headless else 'no display opens'}") from None
        say("no gamepad: the joystick is the viewer's keys (arrows F/B/L/R, Q/E twist, 1/2 buttons)")
        return ViewerKeys(time.monotonic)






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
    if profile is not None:
        print(f"replay: trial {args.trial}: model {args.dir / 'model.json'}, sha256 {logged.model_sha256} as logged"
              if logged.model_sha256 is not None else
              f"replay: trial {args.trial}: the record keeps no model hash (a session from an older bomi): the model "
              f"cannot be checked, only the decisions it makes against the logged ones")
    result = replay_trial(data, args.trial, profile, model)
    same = "the same" if result.success == result.logged_success else "NOT the same"
    print(f"replay: trial {args.trial} ({controller}): {result.ticks} ticks replayed ({result.logged_ticks} logged), "
          f"{'success' if result.success else 'failure'}, {same} outcome as logged")
    print(f"replay: max hand deviation {result.max_deviation_m:.3g} m")
    if (decisions := result.decisions) is not None:
        verdict = ("the same as logged (labels, gamma and nu to the bit)" if decisions.same else
                   f"NOT the same as logged: {decisions.alike} alike; first difference: {decisions.first_difference}")
        print(f"replay: decisions: {decisions.replayed} replayed, {decisions.logged} logged, {verdict}")
    return 0


def _accuracy_text(every: float | None, excused: float | None) -> str:
    if every is None:
        return ""
    return f", accuracy {100 * every:.2f} % over all decisions ({100 * excused:.2f} % with transitions excused)"
