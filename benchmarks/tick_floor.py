"""What an episode would cost with its layers taken away, against the physics-only limit: the
floor each layer leaves, and so which layers a share-of-the-limit bar (issue 30) needs compiled.

    python benchmarks/tick_floor.py [--seeds 975 976 977] [--repeats 2] [--every 30]

Each seed's joystick and BoMI episodes of virtual P1 (``bomi run-task``'s ``run_job``) run once
whole, their arm's every tick taped (the joystick state it was given, the twist its joystick made
of it, the actuator controls the tick set); then the same task seed is replayed on the same arm
from its reset, layer by layer, each replay checked to end in the recorded episode's final state to
the bit (the same simulation, not a similar one):

- **physics**: each tick's recorded controls written to ``data.ctrl``, ``mj_step`` of the tick's
  substeps (the episode's own physics, nothing else);
- **+ IK**: ``ArmSim.step_twist`` of the recorded twist (the differential IK, Pinocchio, the finger
  servo, then the physics);
- **+ joystick**: ``ArmSim.step`` of the recorded joystick state (the arm's joystick: modes,
  buttons, speeds);
- **+ task**: the task's ``view`` before and ``outcome`` after each such step, as the loop calls them;
- **episode**: the whole ``run_job`` (for the BoMI, calibration and training included): the above
  plus the scripted user's planner, the channel (for the BoMI, the participant's synthesis, frames,
  chain) and the loop's own work.

Charged as ``benchmarks/side_by_side.py`` charges its kinds: CPU seconds, one process pinned to one
core, after one untimed episode of each kind; the limit is the scene at rest stepped by ``mj_step``
alone (``side_by_side``'s ``physics_alone``). Here the limit runs interleaved with each layer: after
every ``--every`` control ticks of the layer, as many ticks of the limit on a second arm, their CPU
taken out of the layer's and charged to the limit. A shared machine's speed changes within
seconds (the limit's separate runs read 34-68x real time within minutes, and a layer paired
with a run of the limit just before it still read shares 0.4-0.8 for the same replay); chunks half
a second of simulated time apart see the same machine. The share of the limit a layer reaches is
the best an episode could reach were everything it leaves out free. Writes
benchmarks/results/tick_floor.md and .json.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import mujoco
import numpy as np

from side_by_side import BARS, BOMI, JOY, checkout_commit, pin_to_one_core, write_results
from sim.env import ArmSim
from sim.joystick import JoystickState
from tasks.cli.task import EpisodeJob, run_job
from tasks.stacking.task import StackingTask, TaskConfig

LAYERS = ("physics", "+ IK", "+ joystick", "+ task", "episode")
KINDS = {"joystick": JOY, "bomi": BOMI}


class Tape:
    """Every ``ArmSim.step`` of an episode: the state, the twist its joystick made, the controls set."""

    def __init__(self) -> None:
        self.states: list[JoystickState] = []
        self.twists: list[tuple[list[float], list[float], float]] = []
        self.ctrl: list[np.ndarray] = []
        self.arm: ArmSim | None = None
        self._step = ArmSim.step

    def __enter__(self) -> Tape:
        step, tape = self._step, self

        def taped(arm: ArmSim, state: JoystickState):
            command = step(arm, state)
            tape.arm = arm
            tape.states.append(state)
            tape.twists.append((list(command.linear), list(command.angular), command.finger))
            tape.ctrl.append(arm.data.ctrl.copy())
            return command

        ArmSim.step = taped
        return self

    def __exit__(self, *exc) -> None:
        ArmSim.step = self._step


class InterleavedLimit:
    """The physics-only limit run in chunks between a layer's ticks: after every ``every`` ticks,
    ``every`` ticks' worth of ``mj_step`` on a second arm at rest (reset, untimed, each ``physics_s``
    simulated seconds, as ``side_by_side.physics_alone`` runs it), so that the limit and the layer
    see the same machine within a fraction of a second. ``cpu``: the chunks' own CPU seconds;
    ``excluded``: everything ``tick`` spent (to take out of the layer's)."""

    def __init__(self, arm: ArmSim, every: int, physics_s: float) -> None:
        self.arm, self.every, self.physics_s = arm, every, physics_s
        self.cpu = self.excluded = self.sim_s = 0.0
        self._ticks = 0
        arm.reset()

    def tick(self) -> None:
        self._ticks += 1
        if self._ticks % self.every:
            return
        started = time.process_time()
        arm = self.arm
        if arm.data.time >= self.physics_s:
            arm.reset()
        model, data, substeps = arm.model, arm.data, arm.config.physics.substeps
        cpu = time.process_time()
        for _ in range(self.every):
            mujoco.mj_step(model, data, nstep=substeps)
        now = time.process_time()
        self.cpu += now - cpu
        self.excluded += now - started
        self.sim_s += self.every * arm.dt

    @property
    def x_real_time(self) -> float:
        return self.sim_s / self.cpu


def replay(tape: Tape, seed: int, layer: str, final_qpos: np.ndarray, limit: InterleavedLimit) -> float:
    """CPU seconds of ``layer`` over the taped ticks, from the task's reset, the limit's chunks taken
    out; checks the end state."""
    arm = tape.arm
    task = StackingTask(arm, TaskConfig())
    task.reset(seed)
    model, data, substeps, between = arm.model, arm.data, arm.config.physics.substeps, limit.tick

    def physics(ctrl: np.ndarray) -> None:
        data.ctrl[:] = ctrl
        mujoco.mj_step(model, data, nstep=substeps)

    def task_tick(state: JoystickState) -> None:
        task.view()
        arm.step(state)
        task.outcome()

    loops: dict[str, Callable[[], None]] = {
        "physics": lambda: [(physics(c), between()) for c in tape.ctrl],
        "+ IK": lambda: [(arm.step_twist(*twist), between()) for twist in tape.twists],
        "+ joystick": lambda: [(arm.step(state), between()) for state in tape.states],
        "+ task": lambda: [(task_tick(state), between()) for state in tape.states],
    }
    excluded, cpu = limit.excluded, time.process_time()
    loops[layer]()
    spent = time.process_time() - cpu - (limit.excluded - excluded)
    if not np.array_equal(data.qpos, final_qpos):
        raise RuntimeError(f"seed {seed}: the '{layer}' replay did not end where the episode did")
    return spent


def episode(operator: str, seed: int, limit: InterleavedLimit) -> float:
    """CPU seconds of the whole ``run_job``, the limit's chunks (after the arm's steps) taken out."""
    step = ArmSim.step

    def interleaved(arm: ArmSim, state: JoystickState):
        command = step(arm, state)
        limit.tick()
        return command

    ArmSim.step = interleaved
    try:
        excluded, cpu = limit.excluded, time.process_time()
        run_job(EpisodeJob(operator, "P1", seed))
        return time.process_time() - cpu - (limit.excluded - excluded)
    finally:
        ArmSim.step = step


def measure(operator: str, seed: int, repeats: int, limit_arm: ArmSim, every: int, physics_s: float) -> dict:
    """Each of LAYERS run ``repeats`` times for one episode, each run with the limit interleaved:
    (the layer's CPU seconds, the limit's x real time over the same run) per run."""
    with Tape() as tape:  # taped once, untimed
        run_job(EpisodeJob(operator, "P1", seed))
    final_qpos = tape.arm.data.qpos.copy()
    runs: dict[str, list[tuple[float, float]]] = {layer: [] for layer in LAYERS}
    for _ in range(repeats):
        for layer in LAYERS:
            limit = InterleavedLimit(limit_arm, every, physics_s)
            cpu = (episode(operator, seed, limit) if layer == "episode"
                   else replay(tape, seed, layer, final_qpos, limit))
            runs[layer].append((cpu, limit.x_real_time))
    return {"runs": runs, "sim_s": len(tape.states) * tape.arm.dt, "ticks": len(tape.states)}


def shares(run: dict, layer: str) -> list[float]:
    """The layer's share of the limit in each of its runs (against the limit interleaved with it)."""
    return [run["sim_s"] / cpu / limit_x for cpu, limit_x in run["runs"][layer]]


def markdown(record: dict) -> str:
    args = record["args"]
    limits = [x for op in KINDS for r in record["runs"][op] for layer in LAYERS for _, x in r["runs"][layer]]
    limit_tick_us = 1e6 * record["tick_s"] / statistics.median(limits)  # a control tick of the limit, at its median speed
    lines = [f"# The floor each layer leaves (seeds {', '.join(map(str, args['seeds']))}, one process on one core)", "",
             f"`python benchmarks/tick_floor.py --seeds {' '.join(map(str, args['seeds']))} --repeats {args['repeats']} "
             f"--every {args['every']}` at commit {record['commit']}; 1-min load average {record['load_before']:.2f} before, "
             f"{record['load_after']:.2f} after. Each layer is a replay of the recorded episode, on the same arm from the "
             "task's reset, ending in its final state to the bit (see the script's docstring), with the limit (the "
             f"scene's physics alone at rest) interleaved: {args['every']} ticks of it after every {args['every']} ticks "
             f"of the layer, its CPU taken out of the layer's. The limit read {min(limits):.1f}-{max(limits):.1f}x real "
             f"time over the runs (median {statistics.median(limits):.1f}). Share: the median over seeds and runs "
             f"({args['repeats']} a seed; per seed: the median of its runs). A tick costs: a control tick "
             f"({record['tick_s'] * 1e3:.1f} ms simulated) of the limit at its median speed ({limit_tick_us:.0f} us) "
             "divided by the share; adds: what the layer adds to the one above it.", ""]
    for operator, kind in KINDS.items():
        bar = BARS[kind][0]
        lines += [f"## {kind} (bar: >= {bar} of the limit)", "",
                  "| layer | share of the limit | per seed | a tick costs (us) | adds (us/tick) |", "|---|---|---|---|---|"]
        runs, above = record["runs"][operator], None
        cost = {}
        for layer in LAYERS:
            share = statistics.median(x for r in runs for x in shares(r, layer))
            cost[layer] = limit_tick_us / share
            adds = "" if above is None else f"{cost[layer] - above:.0f}"
            lines.append(f"| {layer} | {share:.2f} | " + ", ".join(f"{statistics.median(shares(r, layer)):.2f}" for r in runs)
                         + f" | {cost[layer]:.0f} | {adds} |")
            above = cost[layer]
        allowed = limit_tick_us / bar - cost["+ task"]
        spent = cost["episode"] - cost["+ task"]
        above_task = f"the scripted user's planner, the channel, the loop{', the set-up' if operator == 'bomi' else ''}"
        verdict = f"a cut of {1 - allowed / spent:.0%}" if 0 <= allowed < spent else "within it" if allowed >= spent else (
            "out of reach whatever they cost: the layers below already exceed the bar")
        lines += ["", f"The bar allows a tick {limit_tick_us / bar:.0f} us: {allowed:.0f} us for what the '+ task' layer "
                  f"leaves out ({above_task}), which costs {spent:.0f} us now: {verdict}.", ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[975, 976, 977], help="task seeds (development: 0-999)")
    parser.add_argument("--repeats", type=int, default=2, help="runs of each layer a seed")
    parser.add_argument("--every", type=int, default=30, help="control ticks between two chunks of the limit")
    parser.add_argument("--physics-s", type=float, default=20.0,
                        help="simulated seconds of the limit's scene at rest before it is reset")
    parser.add_argument("--out", default="tick_floor", help="results file name (benchmarks/results/OUT.md, .json)")
    args = parser.parse_args()
    pin_to_one_core()
    load_before = os.getloadavg()[0]
    limit_arm = ArmSim()
    for operator in KINDS:  # steady state: files parsed, scene compiled, kernels loaded
        measure(operator, args.seeds[0], 1, limit_arm, args.every, args.physics_s)
    runs: dict[str, list[dict]] = {operator: [] for operator in KINDS}
    for seed in args.seeds:
        for operator in KINDS:
            runs[operator].append(measure(operator, seed, args.repeats, limit_arm, args.every, args.physics_s))
        print(f"seed {seed}: " + "; ".join(f"{op} " + ", ".join(
            f"{layer} {statistics.median(shares(runs[op][-1], layer)):.2f}" for layer in LAYERS) for op in KINDS), flush=True)
    record = {"args": vars(args), "commit": checkout_commit(), "load_before": load_before,
              "load_after": os.getloadavg()[0], "tick_s": limit_arm.dt, "runs": runs}
    write_results(args.out, record, markdown(record))


if __name__ == "__main__":
    main()
