"""The arm's IK tick alone: CPU microseconds a call of ``CartesianVelocityController.joint_velocities``
in steady state, and the one-off cost of its compiled kernels (``bomi.compiled``).

    python benchmarks/ik_tick.py [--repeats 5] [--out ik_tick]

- **replay**: the (q, linear, angular) of every control tick of the joystick demo carry
  (``bomi sim``'s script: moves, a grasp, walls), recorded once, then replayed through the
  controller from the run's start ``--repeats`` times; the least CPU time per call is charged
  (the calls' own cost, as ``timeit`` takes it).  Real states, every common branch.
- **fixed**: one state called over and over: holding still, moving at 0.1 m/s, moving and turning.
- **first tick**: a fresh process building the arm and running one tick, its CPU seconds, with
  the kernels compiled into an empty cache (``NUMBA_CACHE_DIR``), loaded from that cache, and
  interpreted (``BOMI_NO_JIT=1``): compiled minus interpreted is the compile, loaded minus
  interpreted the cache load (once a process).

Writes benchmarks/results/<out>.md and .json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bomi.compiled import COMPILED
from sim.env import ArmSim
from sim.joystick import script_states
from tasks.cli.sim import DEMO_SCRIPT

RESULTS = Path(__file__).resolve().parent / "results"
FIRST_TICK = ("import time; start = time.process_time(); from sim.env import ArmSim; import numpy as np; "
              "arm = ArmSim(); arm.controller.joint_velocities(arm.arm_qpos, np.array([0.1, 0.0, 0.0]), "
              "np.zeros(3)); print(time.process_time() - start)")


def recorded_ticks(arm: ArmSim) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """The start pose and each tick's controller inputs along the demo carry."""
    arm.reset()
    start, ticks = arm.arm_qpos, []
    solve = arm.controller.joint_velocities

    def recorded(q, linear, angular):
        ticks.append((q.copy(), np.array(linear, float), np.array(angular, float)))
        return solve(q, linear, angular)
    arm.controller.joint_velocities = recorded  # instance attribute shadows the method
    try:
        for state in script_states(DEMO_SCRIPT, arm.config.physics.control_hz):
            arm.step(state)
    finally:
        del arm.controller.joint_velocities
    return start, ticks


def replay_us(arm: ArmSim, start: np.ndarray, ticks, repeats: int) -> float:
    controller, best = arm.controller, float("inf")
    for _ in range(repeats):
        controller.reset(start)
        begin = time.process_time()
        for q, linear, angular in ticks:
            controller.joint_velocities(q, linear, angular)
        best = min(best, time.process_time() - begin)
    return best / len(ticks) * 1e6


def fixed_us(arm: ArmSim, linear, angular, calls: int, repeats: int) -> float:
    controller, q = arm.controller, arm.home_q
    linear, angular, best = np.array(linear, float), np.array(angular, float), float("inf")
    for _ in range(repeats):
        controller.reset(q)
        begin = time.process_time()
        for _ in range(calls):
            controller.joint_velocities(q, linear, angular)
        best = min(best, time.process_time() - begin)
    return best / calls * 1e6


def first_tick_s(env: dict) -> float:
    out = subprocess.run([sys.executable, "-c", FIRST_TICK], env=os.environ | env, capture_output=True,
                         text=True, check=True)
    return float(out.stdout.split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="replays / loops a measure, the least charged")
    parser.add_argument("--out", default="ik_tick", help="results file name under benchmarks/results/")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    arm = ArmSim()
    start, ticks = recorded_ticks(arm)
    record = {"compiled": COMPILED, "ticks": len(ticks),
              "replay_us": replay_us(arm, start, ticks, args.repeats)}
    for name, linear, angular in (("holding", (0, 0, 0), (0, 0, 0)), ("moving", (0.1, 0, 0), (0, 0, 0)),
                                  ("moving_turning", (0.1, 0, 0), (0, 0, 0.3))):
        record[f"{name}_us"] = fixed_us(arm, linear, angular, 2000, args.repeats)
    arm.close()
    if COMPILED:
        with tempfile.TemporaryDirectory() as cache:
            record["first_tick_compiling_s"] = first_tick_s({"NUMBA_CACHE_DIR": cache})
            record["first_tick_cached_s"] = first_tick_s({"NUMBA_CACHE_DIR": cache})
        record["first_tick_interpreted_s"] = first_tick_s({"BOMI_NO_JIT": "1"})
    RESULTS.joinpath(f"{args.out}.json").write_text(json.dumps(record, indent=2) + "\n")
    lines = [f"# The IK tick alone (`python benchmarks/ik_tick.py --repeats {args.repeats} --out {args.out}`)", "",
             f"Kernels compiled: {'yes' if COMPILED else 'no (numba absent or BOMI_NO_JIT set)'}. CPU microseconds "
             f"a `joint_velocities` call, the least of {args.repeats} runs.", "",
             "| states | us a call |", "|---|---|",
             f"| replay of the demo carry's {len(ticks)} ticks | {record['replay_us']:.2f} |",
             f"| fixed: holding still | {record['holding_us']:.2f} |",
             f"| fixed: moving 0.1 m/s | {record['moving_us']:.2f} |",
             f"| fixed: moving and turning 0.3 rad/s | {record['moving_turning_us']:.2f} |"]
    if COMPILED:
        lines += ["", "A fresh process building the arm and running one tick, CPU s: "
                  f"compiling the kernels {record['first_tick_compiling_s']:.2f}, loading them from the cache "
                  f"{record['first_tick_cached_s']:.2f}, interpreted {record['first_tick_interpreted_s']:.2f}."]
    RESULTS.joinpath(f"{args.out}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
