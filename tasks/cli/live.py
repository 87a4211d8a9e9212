"""`bomi live`: the simulated arm driven by a live base-station stream (see tasks.trials.live)."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from bomi.chain import OnlineChain, recording_neutral
from bomi.files import check_input, check_output
from bomi.model_io import check_model_for, load_model
from bomi.recording import read_recording
from bomi.serial_source import BASE_STATION_BAUD, RetryPolicy, SerialSource, StreamReader
from sim.env import ArmSim
from sim.joystick import BUTTONS
from tasks.operators.assist import ASSIST_HELP, Assistance, assist_option, profile_assist
from tasks.cli import add_command
from tasks.cli.options import non_negative_int, positive_int, seconds
from tasks.stacking.env import StackingEnv
from tasks.trials.displays import (Displays, Headless, PassiveViewer, StatusLine, TickLog, VideoDisplay, display_opens,
                                   has_display, open_log)
from tasks.trials.live import FreeArm, run_live
from tasks.operators.stick import arm_profile, profile_layout


def register(subparsers: argparse._SubParsersAction) -> None:
    live = add_command(
        subparsers, "live",
        description="Frames -> BoMI chain -> joystick -> simulated JACO at 60 Hz, in MuJoCo's viewer (or "
                    "headless). Nothing moves until every node's orientation filter has settled (status: warming "
                    "up, hold still); neutral offsets then come from the next samples (hold still) unless "
                    "--neutral-from gives a recording. The arm stays at rest when no frame arrives for 100 ms, "
                    "when a node's signal is implausible (until it has been plausible again for 1.6 s), and "
                    "during a backlog; a button class acts only once held for the profile's [live] "
                    "button_hold_s. After a break in the stream (a reconnection, 1 s without a node's frames, a packet counter "
                    "that jumps) the stream may come from another sitting: the warm-up and the neutral are retaken "
                    "(also over --neutral-from), the arm at rest until then. See tasks/trials/live.py.")
    live.add_argument("--port", required=True, metavar="PORT_OR_URL",
                      help="serial port, pty path or pyserial URL (socket://, loop://)")
    live.add_argument("--profile", required=True, help="profile (name of a shipped one, or a TOML file)")
    live.add_argument("--model", required=True, type=Path, help="model file (.json/.npz) trained for the profile")
    live.add_argument("--headless", action="store_true",
                      help="no viewer window (default: a window when a display is there)")
    live.add_argument("--duration", type=seconds, help="stop after this many seconds (default: until Ctrl-C or the "
                                                     "viewer closes)")
    live.add_argument("--video", type=Path, help="also film the arm (fixed camera, status line as caption) to "
                                                 "this MP4 (must not exist; default: none)")
    live.add_argument("--log", type=Path, help="JSON-lines log of every control tick (must not exist; default: none)")
    live.add_argument("--neutral-from", type=Path, metavar="RECORDING",
                      help="take the neutral offsets from the first samples of this recording "
                           "(default: from the stream's first samples, hold still); they hold until the first "
                           "break in the stream, after which the neutral is taken from the stream")
    live.add_argument("--baud", type=positive_int, default=BASE_STATION_BAUD,
                      help="baud rate of a real port (default %(default)s)")
    live.add_argument("--retries", type=non_negative_int, default=RetryPolicy.attempts,
                      help="reconnection attempts after the stream is lost (default %(default)s)")
    live.add_argument("--assist", type=assist_option, help=ASSIST_HELP)
    live.set_defaults(func=run)


def _print_neutral(offsets: dict) -> None:
    text = ", ".join(f"node {node}: ({', '.join(f'{v:.2f}' for v in offset)})" for node, offset in offsets.items())
    print(f"live: neutral offsets (pitch, roll, yaw deg) {text}", file=sys.stderr, flush=True)


def _viewer(headless: bool, sim: ArmSim) -> Headless | PassiveViewer:
    if headless:
        return Headless()
    if not has_display():
        print("live: no display (DISPLAY and WAYLAND_DISPLAY are unset): running headless", file=sys.stderr)
        return Headless()
    if not display_opens():
        where = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
        print(f"live: cannot open the display {where}: running headless", file=sys.stderr)
        return Headless()
    return PassiveViewer(sim.model, sim.data)


def run(args: argparse.Namespace) -> int:
    if args.log is not None:
        check_output(args.log, what="--log", forceable=False)
    if args.video is not None:
        check_output(args.video, what="--video", suffixes=(".mp4",), forceable=False)
    profile = arm_profile(args.profile)
    model = load_model(check_input(args.model, "model"))
    check_model_for(model, profile, args.model)
    chain = OnlineChain(model, profile)
    neutral = None
    if args.neutral_from is not None:
        offsets = recording_neutral(read_recording(args.neutral_from), model.spec.nodes, profile.neutral_samples)
        neutral = dict(zip(model.spec.nodes, offsets.tolist()))
    options = args.assist if args.assist is not None else profile_assist(profile)
    source = StreamReader(SerialSource(args.port, baudrate=args.baud, retry=RetryPolicy(attempts=args.retries)))
    sim = ArmSim(layout=profile_layout(profile))  # the layout the profile's classes drive
    arm = FreeArm(StackingEnv(sim))  # the one loop's env, without a task: the arm at home, the cubes at A
    assist = None
    if options:  # sees the arm and the scene's cubes and target, as on the table
        functions = {cls.function for cls in profile.classes}  # no button: a rest held on refuses a mode
        assistance = Assistance(options, sim.layout, tuple(b for b in BUTTONS if b in functions))
        assist = lambda state: assistance.step(arm.env.task.view(), state, sim)  # noqa: E731
    status, log, displays = StatusLine(), None, []
    try:
        displays.append(_viewer(args.headless, sim))
        # the port opens once the scene and the viewer are ready, the loop right after: a sender that
        # starts with its reader (the emulator) is read from its first frame, and none has to wait;
        # a bad port fails before any file is written
        source.start()
        log = TickLog(open_log(args.log), str(args.log)) if args.log is not None else None
        if args.video is not None:
            displays.append(VideoDisplay(sim, args.video))
        source.discard()   # what arrived while the log and the film opened is old: never acted upon
        summary = run_live(source, chain, arm, duration_s=args.duration, neutral=neutral, log=log,
                           status=status, display=Displays(displays), on_neutral=_print_neutral, assist=assist)
    finally:
        source.stop()
        status.close()
        if log is not None:
            log.close()
        Displays(displays).close()
        sim.close()
    print(f"live: {summary.ticks} ticks, {summary.frames} frames, {summary.decisions} decisions, "
          f"{summary.dropped} dropped by the sanitizer, {summary.skipped} skipped as backlog, watchdog stopped "
          f"the arm {summary.watchdog_trips} time(s) ({summary.stale_ticks} ticks), safety-key standby "
          f"{summary.standby_ticks} ticks, held by the gate {sum(summary.holds.values())} ticks{_holds(summary.holds)}, "
          f"{summary.rezeros} re-zero(s) and {summary.recalibrations} recalibration(s) at the person's long press, "
          f"{summary.overruns} control period(s) missed, {sim.automatic_switches} automatic mode switch(es); "
          f"{source.parser.summary()}")
    if args.video is not None:
        film = displays[-1]
        print(f"wrote {args.video} ({film.frames} film frames, {film.dropped} dropped to keep the control rate)")
    if source.error is not None:
        raise source.error
    return 0


def _holds(holds) -> str:
    return f" ({', '.join(f'{reason}: {n}' for reason, n in holds.most_common(3))})" if holds else ""
