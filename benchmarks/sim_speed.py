"""Benchmark of the simulated arm: real-time factor, IK cost per tick, Cartesian speed per direction.

Writes ``benchmarks/results/sim_speed.md`` (tables), ``sim_speed.json`` (the record the tables
come from) and ``sim_speed.png`` (speed per direction). Runs pinned to one CPU core.

    python benchmarks/sim_speed.py [--repeats 3]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from importlib.metadata import version
from pathlib import Path

import mujoco
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from tqdm import tqdm

from sim.check import DirectionResult, enter_mode, measure
from sim.env import ArmSim
from sim.joystick import FINGER_DIRECTION, FUNCTIONS, JoystickState, Mode

RESULTS = Path(__file__).resolve().parent / "results"
OPPOSITE = {"F": "B", "B": "F", "R": "L", "L": "R", "Rr": "Lr", "Lr": "Rr"}


def workload() -> list[tuple[Mode, str]]:
    """One round: each function and its opposite in translation and wrist mode, then close/open."""
    moves = [(mode, f) for mode in (Mode.TRANSLATION, Mode.WRIST) for name in FUNCTIONS
             for f in (name, OPPOSITE[name])]
    return moves + [(Mode.FINGERS, f) for f in FINGER_DIRECTION]


def real_time_factor(sim: ArmSim, repeats: int) -> dict:
    """Simulated seconds per wall-clock second for the full loop (joystick, IK, 8 substeps), and IK ticks."""
    ik_wall: list[float] = []
    ik_cpu: list[float] = []
    solve = sim.controller.joint_velocities

    def timed_solve(*args):
        wall, cpu = time.perf_counter(), time.thread_time()
        result = solve(*args)
        ik_cpu.append(time.thread_time() - cpu)
        ik_wall.append(time.perf_counter() - wall)
        return result

    sim.controller.joint_velocities = timed_solve  # instance attribute shadows the method
    sim.reset()
    moves = workload() * repeats
    ticks_per_move = round(0.5 / sim.dt)
    try:
        start_wall, start_cpu, start_sim = time.perf_counter(), time.thread_time(), sim.time
        for mode, function in tqdm(moves, desc="real-time factor", unit="move"):
            enter_mode(sim, mode)
            for _ in range(ticks_per_move):
                sim.step(JoystickState({function: 1.0}))
        wall, cpu = time.perf_counter() - start_wall, time.thread_time() - start_cpu
        simulated = sim.time - start_sim
    finally:
        del sim.controller.joint_velocities
    record = {"simulated_s": simulated, "wall_s": wall, "cpu_s": cpu, "ticks": len(ik_wall),
              "real_time_factor": simulated / wall, "real_time_factor_cpu": simulated / cpu}
    for clock, samples in (("wall", ik_wall), ("cpu", ik_cpu)):
        us = np.array(samples) * 1e6
        record |= {f"ik_tick_us_{clock}_median": float(np.median(us)),
                   f"ik_tick_us_{clock}_p99": float(np.percentile(us, 99)),
                   f"ik_tick_us_{clock}_max": float(us.max())}
    return record


def physics_steps_per_second(sim: ArmSim, steps: int = 20000) -> dict:
    """Bare mj_step rate for the scene (arm, hand, cubes, contacts, noslip), arm holding still."""
    sim.reset()
    wall, cpu = time.perf_counter(), time.thread_time()
    mujoco.mj_step(sim.model, sim.data, nstep=steps)
    return {"wall": steps / (time.perf_counter() - wall), "cpu": steps / (time.thread_time() - cpu)}


def direction_speeds(sim: ArmSim) -> list[DirectionResult]:
    """Speed reached at full deflection from the home pose, per function, translation and wrist."""
    return [measure(sim, mode, function, deflection=1.0, seconds=1.0, settle=0.25)
            for mode in (Mode.TRANSLATION, Mode.WRIST)
            for function in tqdm(FUNCTIONS, desc=f"full deflection, {mode.value}", unit="direction")]


def speed_figure(results: list[DirectionResult], path: Path) -> None:
    figure = Figure(figsize=(8, 3.2), dpi=100)
    FigureCanvasAgg(figure)
    for axes, mode, unit in zip(figure.subplots(1, 2), ("translation", "wrist"), ("m/s", "rad/s")):
        rows = [r for r in results if r.mode == mode]
        axes.bar([r.function for r in rows], [r.achieved for r in rows], color="tab:blue", label="reached")
        axes.axhline(rows[0].commanded, color="tab:red", linestyle="--", label="commanded")
        axes.set_title(f"{mode} at full deflection")
        axes.set_ylabel(unit)
        axes.legend(loc="lower right", fontsize=8)
    figure.tight_layout()
    figure.savefig(path)


def markdown(record: dict) -> str:
    rtf, config, physics = record["loop"], record["config"], record["physics_steps_per_s"]
    lines = [
        "# Simulated JACO: speed benchmark",
        "",
        f"Machine: {record['machine']['cpu']}, {record['machine']['cpu_count']} cores shared with other work "
        f"(1-min load average {record['machine']['load_average_1min_before']:.2f} before the run), pinned to "
        f"{record['machine']['cores_used']} core; "
        f"Python {record['machine']['python']}; mujoco {record['versions']['mujoco']}, "
        f"dm-control {record['versions']['dm-control']}, pin {record['versions']['pin']}.",
        f"Scene: JACO arm + 3-finger hand + {config['cubes']} cubes; timestep {config['timestep']:.6f} s, "
        f"{config['substeps']} substeps per {config['control_hz']:.0f} Hz control tick.",
        "",
        "| measure | wall clock (shared machine) | CPU time of this thread (one core's cost) |",
        "|---|---|---|",
        f"| real-time factor, full loop (joystick + IK + physics; {rtf['simulated_s']:.1f} s simulated) | "
        f"{rtf['real_time_factor']:.1f}x ({rtf['wall_s']:.2f} s) | "
        f"{rtf['real_time_factor_cpu']:.1f}x ({rtf['cpu_s']:.2f} s) |",
        f"| bare physics, steps/s | {physics['wall']:.0f} ({physics['wall'] * config['timestep']:.1f}x real time) | "
        f"{physics['cpu']:.0f} ({physics['cpu'] * config['timestep']:.1f}x real time) |",
        *(f"| IK per control tick, {stat} | {rtf[f'ik_tick_us_wall_{stat}']:.1f} us | "
          f"{rtf[f'ik_tick_us_cpu_{stat}']:.1f} us |" for stat in ("median", "p99", "max")),
        "",
        "## Speed reached at full deflection from the home pose",
        "",
        "Steady part of a 1 s hold (after 0.25 s). The JACO's joint speed limits (36 deg/s joints 1-3, "
        "48 deg/s joints 4-6) cap some directions below the commanded speed: the whole joint-velocity "
        "vector is scaled down, so the hand stays on its path, slower.",
        "",
        "| mode | function | commanded | reached | reached/commanded | tracking error (mm) |",
        "|---|---|---|---|---|---|",
    ]
    for row in record["directions"]:
        unit = "m/s" if row["mode"] == "translation" else "rad/s"
        lines.append(f"| {row['mode']} | {row['function']} | {row['commanded']:.3f} {unit} | "
                     f"{row['achieved']:.3f} {unit} | {row['ratio']:.2f} | {1000 * row['tracking_error']:.1f} |")
    lines += ["", "Tracking error: translation, largest distance from the commanded line; wrist, largest "
              "displacement of the tool point while the hand turns.", ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="rounds of the real-time-factor workload")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    load_before = os.getloadavg()[0]
    sim = ArmSim()
    physics = physics_steps_per_second(sim)
    loop = real_time_factor(sim, args.repeats)
    directions = direction_speeds(sim)
    record = {
        "machine": {"cpu": platform.processor() or platform.machine(), "python": platform.python_version(),
                    "load_average_1min_before": load_before, "cpu_count": os.cpu_count(),
                    "cores_used": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None},
        "versions": {name: version(name) for name in ("mujoco", "dm-control", "pin", "numpy")},
        "config": {"source": str(sim.config.source), "timestep": sim.config.physics.timestep,
                   "substeps": sim.config.physics.substeps, "control_hz": sim.config.physics.control_hz,
                   "full_speed": sim.config.control.full_speed, "wrist_speed": sim.config.control.wrist_speed,
                   "cubes": len(sim.scene.cube_geoms)},
        "physics_steps_per_s": physics,
        "loop": loop,
        "directions": [vars(r) | {"ratio": r.ratio} for r in directions],
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "sim_speed.json").write_text(json.dumps(record, indent=2) + "\n")
    (RESULTS / "sim_speed.md").write_text(markdown(record))
    speed_figure(directions, RESULTS / "sim_speed.png")
    print(markdown(record))


if __name__ == "__main__":
    main()
