"""Where a physics tick's time goes, at rest (the limit) and inside a joystick episode, by MuJoCo's
own timers, and what each physics setting of the scene costs.

    python benchmarks/physics_cost.py [--seed 0] [--rounds 3] [--rest-ticks 600]

Method: one joystick episode of virtual P1 (task seed ``--seed``, a development seed) is run once
with ``mj_step`` wrapped so that the full integration state (``mjSTATE_INTEGRATION``: qpos, qvel,
act, ctrl, warm start, ...) is recorded before every control tick.  The limit's ticks are recorded
the same way: the scene reset to home and advanced with no control, as ``side_by_side.py``'s
"physics alone" does.  Each scene variant then *replays* both sets of ticks: set the recorded
state, ``mj_step`` 8 substeps.  Every variant so pays for exactly the same states, the episode's
grasps, pushes and transports included, and no Python work runs between the steps (inside a real
episode the same calls cost about 10 % more: the task's Python evicts MuJoCo's data from cache).

Per variant and kind: CPU microseconds per control tick (``time.process_time`` around the replay,
the median over ``--rounds``), MuJoCo's stage timers (``data.timer``, fed by ``time.perf_counter``
through ``mujoco.set_mjcb_time`` in separate passes; wall clock, so only the ticks no other
process interrupted count: wall time of the tick's ``mj_step`` at most 1.05 times its CPU time;
the median over rounds), and solver statistics at the end of each tick (contacts,
constraint rows, solver iterations summed over islands).  Variants: the scene as shipped, the
settings before issue 30 (multiccd on, every finger pair tested), and candidates that were
measured but not adopted (see docs/sim.md).  Writes benchmarks/results/physics_cost.md and .json.
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path
from unittest import mock

import mujoco
import numpy as np

import sim.env
import sim.scene
from sim.env import ArmSim
from tasks.cli.task import EpisodeJob, run_job

RESULTS = Path(__file__).resolve().parent / "results"
STATE = mujoco.mjtState.mjSTATE_INTEGRATION
# A timed tick whose wall-clock mj_step exceeds this multiple of its CPU time was interrupted by
# another process (a shared machine): its stage timers are left out.
PREEMPTED = 1.05
TIMER = mujoco.mjtTimer
DISABLE = mujoco.mjtDisableBit
# (column, timer, timers nested inside it that get their own column): exclusive times.
STAGES = (
    ("kinematics + inertia", TIMER.mjTIMER_POSITION, (TIMER.mjTIMER_POS_COLLISION, TIMER.mjTIMER_POS_MAKE,
                                                       TIMER.mjTIMER_POS_PROJECT)),
    ("collision: broad", TIMER.mjTIMER_COL_BROAD, ()),
    ("collision: narrow", TIMER.mjTIMER_COL_NARROW, ()),
    ("constraint make", TIMER.mjTIMER_POS_MAKE, ()),
    ("constraint project", TIMER.mjTIMER_POS_PROJECT, ()),
    ("velocity", TIMER.mjTIMER_VELOCITY, ()),
    ("actuation", TIMER.mjTIMER_ACTUATION, ()),
    ("solver + noslip", TIMER.mjTIMER_CONSTRAINT, ()),
    ("advance", TIMER.mjTIMER_ADVANCE, ()),
)


@dataclass(frozen=True)
class Variant:
    name: str
    adopted: bool                                  # the shipped scene, or a setting it ships with
    finger_exclusions: bool = True                 # the scene's UNREACHABLE_FINGER_PAIRS excluded
    edit: Callable[[ArmSim], None] = lambda arm: None


def _flag(bit: DISABLE, on: bool) -> Callable[[ArmSim], None]:
    def edit(arm: ArmSim) -> None:
        if on:
            arm.model.opt.disableflags |= int(bit)
        else:
            arm.model.opt.disableflags &= ~int(bit)
    return edit


def _option(**values) -> Callable[[ArmSim], None]:
    def edit(arm: ArmSim) -> None:
        for name, value in values.items():
            setattr(arm.model.opt, name, value)
    return edit


def _no_arm_frictionloss(arm: ArmSim) -> None:
    arm.model.dof_frictionloss[arm.scene.arm_dof] = 0.0


VARIANTS = (
    Variant("scene as shipped (multiccd off, 11 finger pairs excluded)", True),
    Variant("before issue 30 (multiccd on, every finger pair tested)", False, False, _flag(DISABLE.mjDSBL_MULTICCD, False)),
    Variant("multiccd on, finger pairs excluded", False, True, _flag(DISABLE.mjDSBL_MULTICCD, False)),
    Variant("multiccd off, every finger pair tested", False, False),
    Variant("candidate: native CCD (dm_control's JACO disables it)", False, True, _flag(DISABLE.mjDSBL_NATIVECCD, False)),
    Variant("candidate: solver tolerance 1e-6 (from 1e-8)", False, True, _option(tolerance=1e-6)),
    Variant("candidate: noslip_tolerance 1e-4 (from 1e-6)", False, True, _option(noslip_tolerance=1e-4)),
    Variant("candidate: CG solver (from Newton)", False, True, _option(solver=mujoco.mjtSolver.mjSOL_CG)),
    Variant("candidate: islands off", False, True, _flag(DISABLE.mjDSBL_ISLAND, True)),
    Variant("candidate: warm start off", False, True, _flag(DISABLE.mjDSBL_WARMSTART, True)),
    Variant("not allowed (grasps slip): noslip off", False, True, _option(noslip_iterations=0)),
    Variant("model change, not adopted: arm joints' frictionloss 0", False, True, _no_arm_frictionloss),
)


def _state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    state = np.empty(mujoco.mj_stateSize(model, STATE))
    mujoco.mj_getState(model, data, state, STATE)
    return state


def record_episode(seed: int) -> tuple[np.ndarray, bool]:
    """The integration state before every control tick of a joystick episode of P1."""
    states, step = [], mujoco.mj_step

    def recording(model, data, nstep=1):
        states.append(_state(model, data))
        step(model, data, nstep=nstep)

    with mock.patch.object(sim.env.mujoco, "mj_step", recording):
        log = run_job(EpisodeJob("joystick", "P1", seed))
    return np.array(states), bool(log.success)


def record_rest(ticks: int) -> np.ndarray:
    """The limit's ticks: the scene at home, no control."""
    arm = ArmSim()
    arm.reset()
    states = []
    for _ in range(ticks):
        states.append(_state(arm.model, arm.data))
        mujoco.mj_step(arm.model, arm.data, nstep=arm.config.physics.substeps)
    return np.array(states)


def build(variant: Variant) -> ArmSim:
    with ExitStack() as stack:
        if not variant.finger_exclusions:
            stack.enter_context(mock.patch.object(sim.scene, "UNREACHABLE_FINGER_PAIRS", ()))
        arm = ArmSim()
    variant.edit(arm)
    return arm


def _timers(data: mujoco.MjData) -> np.ndarray:
    return np.array([data.timer[i].duration for i in range(TIMER.mjNTIMER)])


def replay(arm: ArmSim, states: np.ndarray, timed: bool) -> dict:
    """Every recorded tick once: CPU us per tick, solver statistics and, if ``timed``, the stage
    timers per tick (wall clock, over the ticks no other process interrupted: see ``PREEMPTED``)."""
    model, data, substeps = arm.model, arm.data, arm.config.physics.substeps
    stats, kept, timers = np.zeros(3), 0, np.zeros(TIMER.mjNTIMER)
    mujoco.set_mjcb_time(time.perf_counter if timed else None)
    try:
        start = time.process_time()
        for state in states:
            mujoco.mj_setState(model, data, state, STATE)
            if timed:
                before, cpu = _timers(data), time.process_time()
            mujoco.mj_step(model, data, nstep=substeps)
            if timed:
                spent, cpu = _timers(data) - before, time.process_time() - cpu
                if spent[TIMER.mjTIMER_STEP] <= PREEMPTED * cpu:
                    timers, kept = timers + spent, kept + 1
            stats += (data.ncon, data.nefc, data.solver_niter[:max(1, data.nisland)].sum())
        cpu = time.process_time() - start
    finally:
        mujoco.set_mjcb_time(None)
    n = len(states)
    out = {"cpu_us": cpu / n * 1e6, **dict(zip(("ncon", "nefc", "solver_iterations"), (stats / n).tolist()))}
    if timed:
        per_tick = timers / max(kept, 1) * 1e6
        out["stages"] = {name: per_tick[timer] - sum(per_tick[inner] for inner in nested)
                         for name, timer, nested in STAGES} | {"mj_step (timed)": per_tick[TIMER.mjTIMER_STEP]}
        out["kept"] = kept / n
    return out


def measure(variant: Variant, kinds: dict[str, np.ndarray], rounds: int) -> dict:
    arm = build(variant)
    out = {}
    for kind, states in kinds.items():
        plain = [replay(arm, states, timed=False) for _ in range(rounds)]
        timed = [replay(arm, states, timed=True) for _ in range(rounds)]
        out[kind] = {"cpu_us": statistics.median(r["cpu_us"] for r in plain),
                     "stages": {name: statistics.median(r["stages"][name] for r in timed) for name in timed[0]["stages"]},
                     "timed_ticks_kept": statistics.median(r["kept"] for r in timed),
                     **{key: plain[0][key] for key in ("ncon", "nefc", "solver_iterations")}}
    arm.close()
    return out


def markdown(record: dict) -> str:
    rows, first = record["variants"], record["variants"][0]
    base = next(r for r in rows if r["name"].startswith("before"))
    lines = [f"# Physics cost per control tick: at rest (the limit) and inside a joystick episode",
             "", f"`python benchmarks/physics_cost.py --seed {record['seed']} --rounds {record['rounds']} "
             f"--rest-ticks {record['rest_ticks']}` at commit {record['commit']}. {record['machine']}",
             "", f"Replayed ticks: {record['episode_ticks']} of the joystick episode of P1, task seed "
             f"{record['seed']} (success: {record['success']}), and {record['rest_ticks']} at rest. One control "
             "tick = 8 `mj_step` substeps of 1/480 s. CPU = `time.process_time`, median over rounds; stages = "
             "MuJoCo's timers (wall clock over the ticks no other process interrupted, "
             f"{first['episode']['timed_ticks_kept']:.0%} of the episode's and {first['rest']['timed_ticks_kept']:.0%} "
             "of the rest's for the shipped scene; median over rounds). See the script's docstring.", "",
             "Every row but the first two changes one thing of the shipped scene (on top of multiccd off and the "
             "finger exclusions). The replay sets the recorded state before each tick, so its limit (x real time) "
             "reads a little below `side_by_side.py`'s uninterrupted run. Solver iterations: Newton's and noslip's "
             "(5 per island), summed over the islands, at the end of each tick.", "",
             "## Cost per variant (CPU us per control tick)", "",
             "| variant | adopted | at rest (the limit) | limit x real time | episode | episode / rest | "
             "episode vs before | contacts (episode) | rows | solver iterations (episode / rest) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        rest, episode = r["rest"], r["episode"]
        lines.append(
            f"| {r['name']} | {'yes' if r['adopted'] else 'no'} | {rest['cpu_us']:.0f} | "
            f"{1e6 / 60 / rest['cpu_us']:.1f} | {episode['cpu_us']:.0f} | {episode['cpu_us'] / rest['cpu_us']:.2f} | "
            f"{episode['cpu_us'] / base['episode']['cpu_us'] - 1:+.0%} | {episode['ncon']:.1f} | {episode['nefc']:.1f} | "
            f"{episode['solver_iterations']:.1f} / {rest['solver_iterations']:.1f} |")
    stages = list(first["rest"]["stages"])
    lines += ["", "## Where a tick's time goes (MuJoCo timers, us per control tick, exclusive)", "",
              "| stage | " + " | ".join(f"{k}: {r['name'].split(' (')[0]}" for r in (first, base)
                                         for k in ("rest", "episode")) + " |",
              "|---|" + "---|" * 4]
    for stage in stages:
        lines.append(f"| {stage} | " + " | ".join(f"{r[k]['stages'][stage]:.0f}" for r in (first, base)
                                                 for k in ("rest", "episode")) + " |")
    return "\n".join(lines) + "\n"


def replay_arguments(description: str, rounds: int, rounds_help: str) -> argparse.Namespace:
    """``--seed``, ``--rounds`` and ``--rest-ticks`` of a replay benchmark, checked (one line, exit 2)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--seed", type=int, default=0, help="the joystick episode's task seed (development: 0-999)")
    parser.add_argument("--rounds", type=int, default=rounds, help=rounds_help)
    parser.add_argument("--rest-ticks", type=int, default=600, help="control ticks at rest to replay")
    args = parser.parse_args()
    for name in ("rounds", "rest_ticks"):
        if getattr(args, name) < 1:
            parser.exit(2, f"bomi: error: --{name.replace('_', '-')}: must be at least 1, got {getattr(args, name)}\n")
    if not 0 <= args.seed <= 999:
        parser.exit(2, f"bomi: error: --seed: a development task seed is 0-999, got {args.seed}\n")
    return args


def main() -> None:
    args = replay_arguments(__doc__.split("\n\n")[0], 3, "replays per variant and kind")
    episode, success = record_episode(args.seed)
    kinds = {"rest": record_rest(args.rest_ticks), "episode": episode}
    variants = []
    for variant in VARIANTS:
        variants.append({"name": variant.name, "adopted": variant.adopted} | measure(variant, kinds, args.rounds))
        print(f"{variant.name}: rest {variants[-1]['rest']['cpu_us']:.0f}, episode "
              f"{variants[-1]['episode']['cpu_us']:.0f} us/tick", flush=True)
    record = {"seed": args.seed, "rounds": args.rounds, "rest_ticks": args.rest_ticks, "episode_ticks": len(episode),
              "success": success, "variants": variants}
    write_results("physics_cost", record, markdown)


def write_results(name: str, record: dict, markdown: Callable[[dict], str]) -> None:
    """``record`` with the commit and the machine, as benchmarks/results/NAME.json and NAME.md (printed too)."""
    record["commit"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                      cwd=Path(__file__).parent).stdout.strip()
    record["machine"] = f"{platform.machine()}, Python {platform.python_version()}, mujoco {version('mujoco')}."
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{name}.json").write_text(json.dumps(record, indent=1))
    (RESULTS / f"{name}.md").write_text(markdown(record))
    print(markdown(record))


if __name__ == "__main__":
    main()
