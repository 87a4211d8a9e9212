"""``bomi sim-check`` and ``bomi render``: the simulated arm from the command line."""
from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bomi.files import atomic_output, check_input, write_text
from sim.check import DirectionResult, check_all, verdict
from sim.config import DEFAULT_CONFIG, MODELS_DIR, load_config
from sim.env import ArmSim
from sim.errors import SimError
from sim.joystick import JoystickState, script_states
from sim.render import VideoWriter, describe, write_png
from tasks.cli import add_command
from tasks.cli.options import add_force, check_outputs, positive_float, seconds

# The scripted motion of ``bomi render``: pick the first cube up at A and put it down at B, with
# the stick alone. (seconds, stick state) segments; a segment's buttons are pressed once, at its
# first tick, while its functions are held throughout.
PRESS_B1 = (0.1, JoystickState(pressed=frozenset({"B1"})))
PRESS_B2 = (0.1, JoystickState(pressed=frozenset({"B2"})))
DEMO_SCRIPT: tuple[tuple[float, JoystickState], ...] = (
    (0.5, JoystickState()),
    (0.7, JoystickState({"R": 1.0})),          # x- 14 cm: above the first cube
    (0.3, JoystickState({"B": 0.5})),          # y+ 3 cm
    (0.95, JoystickState({"Lr": 1.0})),        # down 19 cm
    PRESS_B1, PRESS_B1,                        # translation -> wrist -> fingers
    (1.5, JoystickState({"F": 1.0})),          # close
    PRESS_B1,                                  # fingers -> translation
    (1.0, JoystickState({"Rr": 0.5})),         # lift 10 cm
    (1.4, JoystickState({"L": 1.0})),          # x+ 28 cm: over B
    (0.6, JoystickState({"F": 0.5})),          # y- 6 cm
    (0.8, JoystickState({"Lr": 0.5})),         # down 8 cm
    PRESS_B2,                                  # translation -> fingers
    (1.2, JoystickState({"B": 1.0})),          # open
    PRESS_B1,                                  # fingers -> translation
    (1.0, JoystickState({"Rr": 1.0})),         # up
    (0.5, JoystickState()),
)


def register(subparsers: argparse._SubParsersAction) -> None:
    check = add_command(subparsers, "sim-check")
    _common_options(check)
    check.add_argument("--deflection", type=positive_float, default=1.0, help="stick deflection in (0, 1] (default %(default)s)")
    check.add_argument("--seconds", type=seconds, default=1.0,
                       help="seconds each function is held, above 0.5 (default %(default)s)")
    check.add_argument("--json", type=Path, help="also write the results as JSON here")
    add_force(check)
    check.set_defaults(func=run_check)

    render = add_command(subparsers, "render")
    _common_options(render)
    render.add_argument("--out", type=Path, required=True, help="MP4 file to write")
    render.add_argument("--png", type=Path, help="also write the last frame as PNG here")
    add_force(render)
    render.set_defaults(func=run_render)


def _common_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG,
                        help="simulation TOML (default: the shipped models/sim.toml)")
    parser.add_argument("--models", type=Path, default=MODELS_DIR,
                        help="directory of the MJCF model files (default: the shipped models/)")


def _check_sim_inputs(args: argparse.Namespace) -> None:
    check_input(args.config, "simulation config")
    if not args.models.is_dir():
        raise SimError(f"{args.models}: --models must be a directory of MJCF files")


def run_check(args: argparse.Namespace) -> int:
    if not 0 < args.deflection <= 1 or args.seconds <= 0.5:
        raise SimError("sim-check: --deflection must be in (0, 1] and --seconds above 0.5")
    outputs = check_outputs({"--json": (args.json, (".json",))}, force=args.force)
    _check_sim_inputs(args)
    sim = ArmSim(load_config(args.config), args.models)
    results = check_all(sim, args.deflection, args.seconds)
    print(sim_check_table(results))
    if outputs["--json"]:
        records = [{key: _json_number(value) for key, value in (asdict(r) | {"ratio": r.ratio, "verdict": verdict(r)}).items()}
                   for r in results]
        write_text(outputs["--json"], json.dumps(records, indent=2), overwrite=args.force)
    return 0


SPEED_UNITS = {"translation": "m/s", "sideways": "m/s", "height": "m/s", "wrist": "rad/s", "fingers": "1/s"}


def sim_check_table(results: list[DirectionResult]) -> str:
    """One row per function (unit before the numbers, tracking error in mm, a verdict), then a note on
    the rows that a joint speed limit caps."""
    header = (f"{'mode':<12}{'function':<9}{'unit':<7}{'commanded':>10}{'achieved':>10}{'ratio':>7}"
              f"{'tracking error (mm)':>26}  verdict")
    lines = [header, "-" * len(header)]
    for r in results:
        error = "" if np.isnan(r.tracking_error) else (
            f"{1000 * r.tracking_error:.1f} {'off the line' if SPEED_UNITS[r.mode] == 'm/s' else 'tool drift'}")
        lines.append(f"{r.mode:<12}{r.function:<9}{SPEED_UNITS[r.mode]:<7}{r.commanded:>10.3f}{r.achieved:>10.3f}"
                     f"{r.ratio:>7.2f}{error:>26}  {verdict(r)}")
    capped = [r for r in results if verdict(r).startswith("capped")]
    if capped:
        lines += ["", "capped: " + ", ".join(f"{r.mode} {r.function}" for r in capped) + ". At this deflection "
                  "from the home pose a joint would have to turn faster than its speed limit (the actuators' "
                  "ranges, the real JACO's); the controller then scales all joint velocities by one factor, so the "
                  "hand keeps its straight path, only slower (a ratio r: the busiest joint would have needed 1/r "
                  "times its limit). Wrist F/B tip the hand about x: the JACO's wrist is bent (joints 4-6 do not "
                  "meet at one point), so with the hand pointing down joint 5 must turn faster than the hand and "
                  "joint 3 swing the wrist around the fingertips. See docs/sim.md."]
    return "\n".join(lines)


def run_render(args: argparse.Namespace) -> int:
    outputs = check_outputs({"--out": (args.out, (".mp4",)), "--png": (args.png, (".png",))}, force=args.force)
    _check_sim_inputs(args)
    sim = ArmSim(load_config(args.config), args.models)
    control_hz = sim.config.physics.control_hz
    ticks_per_frame = max(1, round(control_hz / sim.config.render.fps))
    total = sum(round(seconds * control_hz) for seconds, _ in DEMO_SCRIPT)
    frame = None

    def write_video(tmp: Path) -> None:
        nonlocal frame
        with VideoWriter(tmp, fps=control_hz / ticks_per_frame) as video:
            for tick, state in enumerate(tqdm(script_states(DEMO_SCRIPT, control_hz), total=total,
                                              desc="render", unit="tick")):
                sim.step(state)
                if tick % ticks_per_frame == 0:
                    frame = sim.render(describe(sim.mode, state, sim.layout))
                    video.append(frame)

    try:
        with atomic_output(outputs["--out"], overwrite=args.force) as temp:
            write_video(temp)
        if outputs["--png"]:
            with atomic_output(outputs["--png"], overwrite=args.force) as temp:
                write_png(temp, frame)
    finally:
        sim.close()
    print(f"wrote {args.out}" + (f" and {args.png}" if args.png else "")
          + f" ({sim.time:.1f} s simulated, mode switches {sim.mode_switches}, button presses {sim.button_presses})")
    return 0


def _json_number(value):
    """NaN is not JSON: write null."""
    return None if isinstance(value, float) and np.isnan(value) else value
