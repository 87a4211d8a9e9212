"""Speed: the README's row "episode speed per CPU second, of the physics-only limit / x dm_control".
Our scene's physics alone (the limit), dm_control's own JACO stacking task in steady state, and
our joystick and BoMI episodes, in one process on one core, the kinds interleaved round after
round; then a profile of where a control tick's time goes (the calibration, the channel, the
planner, the IK, the physics: the per-stage figures the earlier one-off speed studies measured
apart, docs/scaling.md).

    python benchmarks/speed.py [--rounds 3] [--first-seed 0] [--profile-seed 0]

How each kind is charged (x real time = simulated seconds per second, of wall clock and of this
process's CPU time, ``time.process_time``):

- **physics alone (the limit)**: our scene (``ArmSim``: arm, hand, cubes, contacts), reset to the
  home pose, advanced by ``mj_step`` at its own step (1/480 s), 8 substeps per call as the episode
  calls it, no controller, no task, no Python work between calls: ``--physics-s`` simulated seconds,
  ``--physics-repeats`` times a round, the least disturbed (least CPU) charged: a run of 0.3 s is
  short enough for one burst of other work on the machine to slow it by half (a single run read
  46x where its repeats read 69-74x), which would flatter every ratio to it; the least of repeats
  is the conservative reading (the limit's own cost, as ``timeit`` takes it).
- **dm_control** ``stack_2_bricks_features`` with uniform random actions, in steady state: its
  environment is built once (timed apart: ``build``), each round is ``reset()`` + the episode.
- **ours: joystick / BoMI episode** of virtual P1 (``bomi run-task``'s ``run_job``), everything
  included: reading the participant, profile and operator files, the BoMI's calibration session
  (the participant performs the protocol, its frames are parsed, fused and recorded) and the LDA's
  training, and the task to its end.  Shown apart as well: the set-up (all before the first control
  tick) and the task loop alone.  Steady state as in a sweep worker: one untimed episode of each
  kind first, so what every episode of a participant shares (parsed files, compiled scene) is
  cached exactly as on a worker that has run one episode before.  Each round runs another task
  seed (``--first-seed`` + round), the same seed for both of our operators.
- **the episode's own physics**: the ``mj_step`` calls inside our task loop, timed alone: a
  grasping, moving arm costs more per step than the arm at rest, so this is the ceiling of an
  episode whose every other cost were zero.

Ratios are formed within a round (the same load for all kinds) and their median is reported.
The bars (issue 30): joystick >= 0.5 of the limit and >= 1.0x dm_control; BoMI, calibration
included, >= 0.3 of the limit and >= 0.5x dm_control.  The profile (cProfile, one BoMI and one
joystick episode of ``--profile-seed``, after the rounds; CPU time) charges every function's own time to a
stage (a library call to the stage of our code that called it) and gives microseconds per control
tick; cProfile slows Python calls, so its totals exceed the unprofiled ones: read its shares.
Writes benchmarks/results/side_by_side.md and .json.
"""
from __future__ import annotations

import argparse
import cProfile
import json
import os
import platform
import pstats
import statistics
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import replace
from importlib.metadata import version
from pathlib import Path

import mujoco
import numpy as np
from dm_control import manipulation

import sim.env
import tasks.stacking.episode
from bomi.chain import OnlineChain
from bomi.frames import FrameParser
from sim.controller import CartesianVelocityController
from sim.env import ArmSim
from tasks.experiments.jobs import HUMAN_ON, EpisodeJob, job_assist, run_job
from tasks.stacking.channels import JoystickChannel, calibrated_channel, profile_controls
from tasks.stacking.episode import run_episode
from tasks.participants.participant import VirtualParticipant, load_participant
from tasks.operators.planner import ScriptedUser
from tasks.operators.params import load_operator
from tasks.stacking.task import StackingTask, TaskConfig
from tasks.operators.stick import arm_profile

RESULTS = Path(__file__).resolve().parent / "results"
PHYSICS, DM, JOY, BOMI = ("physics alone (our scene, mj_step, no control): the limit",
                          "dm_control stack_2_bricks_features, random actions, steady state",
                          "ours: joystick episode (P1), set-up included",
                          "ours: BoMI episode (P1), calibration and training included")
BARS = {JOY: (0.5, 1.0), BOMI: (0.3, 0.5)}  # (share of the limit, ratio to dm_control)


class StepClock:
    """Times the ``mj_step`` calls ``sim.env`` makes (the episode's own physics)."""

    def __init__(self) -> None:
        self.wall = self.cpu = 0.0
        self._step = mujoco.mj_step

    def __enter__(self) -> StepClock:
        step = self._step

        def timed(*args, **kwargs):
            wall, cpu = time.perf_counter(), time.process_time()
            step(*args, **kwargs)
            self.cpu += time.process_time() - cpu
            self.wall += time.perf_counter() - wall

        sim.env.mujoco.mj_step = timed
        return self

    def __exit__(self, *exc) -> None:
        sim.env.mujoco.mj_step = self._step


def clocked(run: Callable[[], dict]) -> dict:
    wall, cpu = time.perf_counter(), time.process_time()
    out = run()
    return out | {"wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu}


def physics_alone(arm: ArmSim, seconds: float, repeats: int) -> dict:
    substeps = arm.config.physics.substeps
    calls = round(seconds / (arm.model.opt.timestep * substeps))
    model, data, step = arm.model, arm.data, mujoco.mj_step

    def run() -> dict:
        for _ in range(calls):
            step(model, data, nstep=substeps)
        return {}

    runs = []
    for _ in range(repeats):
        arm.reset()
        runs.append(clocked(run))
    return min(runs, key=lambda r: r["cpu_s"]) | {"sim_s": calls * substeps * arm.model.opt.timestep,
                                                  "repeats_cpu_s": [r["cpu_s"] for r in runs]}


def dm_control_episode(env, seed: int) -> dict:
    spec, rng = env.action_spec(), np.random.default_rng(seed)

    def run() -> dict:
        step = env.reset()
        while not step.last():
            step = env.step(rng.uniform(spec.minimum, spec.maximum))
        return {}

    return clocked(run) | {"sim_s": float(env.physics.data.time)}


def our_episode(operator: str, seed: int, overrides: tuple = ()) -> dict:
    """One episode of virtual P1 (``overrides``: the job's, e.g. the human operator model on)."""
    with StepClock() as physics:
        out = clocked(lambda: {"log": run_job(EpisodeJob(operator, "P1", seed, overrides=overrides))})
    log = out.pop("log")
    return out | {"sim_s": float(log.t[-1] + (log.t[1] - log.t[0])), "loop_wall_s": log.wall_time,
                  "loop_cpu_s": log.cpu_time, "setup_wall_s": out["wall_s"] - log.wall_time,
                  "setup_cpu_s": out["cpu_s"] - log.cpu_time, "physics_wall_s": physics.wall,
                  "physics_cpu_s": physics.cpu, "ticks": len(log.t), "success": bool(log.success)}


# ------------------------------------------------------------------------------------- profile
STAGES = (  # (stage, path fragment, function names or None for any); first match wins
    ("mj_step (physics)", "mj_step", None),
    ("vote", "bomi/classifier.py", ("push",)),
    ("LDA (fit, posteriors)", "bomi/classifier.py", None),
    ("frames (parse)", "bomi/frames.py", None),
    ("fusion", "bomi/fusion.py", None),
    ("windows + features", "bomi/features.py", None),
    ("chain (streaming glue)", "bomi/chain.py", None),
    ("chain (streaming glue)", "tasks/participants/receiver.py", None),
    ("synthesis (virtual participant, link)", "tasks/participants/", None),
    ("IK (DLS, Pinocchio)", "sim/controller.py", None),
    ("IK (DLS, Pinocchio)", "sim/kinematics.py", None),
    ("arm (joystick, actuators, read-outs)", "sim/", None),
    ("operator / planner", "tasks/operators/planner.py", None),
    ("operator / planner", "tasks/operators/human.py", None),
    ("operator / planner", "tasks/operators/stick.py", None),
    ("task (view, outcome)", "tasks/stacking/task.py", None),
    ("episode loop, BoMI channel", "tasks/stacking/episode.py", None),
    ("assistance", "tasks/operators/assist.py", None),
)


def _own_stage(func: tuple[str, int, str]) -> str | None:
    path, _, name = func
    where = f"{path}:{name}"
    for stage, fragment, names in STAGES:
        if fragment in where and (names is None or name in names):
            return stage
    return None


def stage_times(stats: pstats.Stats) -> dict[str, float]:
    """Every function's own time charged to a stage: our code by its module, a library function
    shared out over its callers in proportion to the time each spent in it, up to our code."""
    raw = stats.stats  # func -> (cc, nc, tt, ct, callers{func: (cc, nc, tt, ct)})
    memo: dict = {}

    def shares(func, depth=0) -> dict[str, float]:
        """Fractions of ``func``'s time per stage."""
        if func in memo:
            return memo[func]
        own = _own_stage(func)
        if own is not None or depth > 50:
            memo[func] = {own or "other": 1.0}
            return memo[func]
        memo[func] = {"other": 1.0}  # a cycle meets this placeholder
        callers = raw[func][4]
        total = sum(c[3] for c in callers.values())
        out: dict[str, float] = defaultdict(float)
        if total <= 0:
            out["other"] = 1.0
        for caller, c in callers.items():
            if total > 0:
                for stage, f in shares(caller, depth + 1).items():
                    out[stage] += f * c[3] / total
        memo[func] = dict(out)
        return memo[func]

    times: dict[str, float] = defaultdict(float)
    for func, (_, _, tt, _, _) in raw.items():
        for stage, f in shares(func).items():
            times[stage] += tt * f
    return dict(times)


def profile_episode(operator: str, seed: int) -> dict:
    """``run_job``'s steps, the set-up and the task loop profiled apart."""
    job = EpisodeJob(operator, "P1", seed)
    setup, loop = cProfile.Profile(time.process_time), cProfile.Profile(time.process_time)  # CPU, not wall
    setup.enable()
    params = load_participant(job.participant)
    profile = arm_profile(params.profile)
    channel = (JoystickChannel(profile_controls(profile)) if operator == "joystick" else
               calibrated_channel(params, seed, replace(profile.post, vote_length=job.vote_length), profile))
    operator_params = load_operator(job.operator_file)
    setup.disable()
    loop.enable()
    log = run_episode(channel, operator=operator, participant="P1", seed=seed, operator_file=operator_params,
                      task_config=TaskConfig(time_limit=job.time_limit), assist=job_assist(job, profile))
    loop.disable()
    ticks = len(log.t)
    out = {"ticks": ticks}
    for name, prof in (("setup", setup), ("loop", loop)):
        times = stage_times(pstats.Stats(prof))
        out[name] = {stage: s for stage, s in sorted(times.items(), key=lambda kv: -kv[1])}
    out["loop_us_per_tick"] = {stage: 1e6 * s / ticks for stage, s in out["loop"].items()}
    return out


INSTRUMENTED = (  # (stage, owner, method): the calls of a control tick timed one by one, none inside another
    ("operator / planner (stick_intent)", ScriptedUser, "stick_intent"),
    ("task: view", StackingTask, "view"),
    ("task: outcome", StackingTask, "outcome"),
    ("IK (joint_velocities)", CartesianVelocityController, "joint_velocities"),
    ("synthesis (participant deliveries)", VirtualParticipant, "deliveries"),
    ("frames (parser, frame by frame)", FrameParser, "feed"),
    ("frames (parser, a chunk at once)", FrameParser, "feed_whole"),
    ("chain: fusion, window, features, LDA, vote (push_frame, frame by frame)", OnlineChain, "push_frame"),
    ("chain: fusion, window, features, LDA, vote (push_many, a chunk at once)", OnlineChain, "push_many"),
)


def instrumented_episode(operator: str, seed: int) -> dict:
    """CPU seconds per control tick of the task loop in each of the ``INSTRUMENTED`` calls and in
    ``mj_step``, the rest (the loop's own work, the channel, the arm's joystick and actuators) apart.
    One ``process_time`` pair per call (about a microsecond): close to the unprofiled cost."""
    job = EpisodeJob(operator, "P1", seed)
    spent: dict[str, float] = defaultdict(float)

    def timed(stage: str, method):
        def call(*args, **kwargs):
            cpu = time.process_time()
            try:
                return method(*args, **kwargs)
            finally:
                spent[stage] += time.process_time() - cpu
        return call

    setup = (("calibration session (synthesis)", "calibration_session"), ("its recording (parse, fuse)", "session_recording"),
             ("LDA training", "train"), ("channel (warm-up, neutral calibration)", "BomiChannel"))
    originals = [(tasks.stacking.episode, name, getattr(tasks.stacking.episode, name)) for _, name in setup]
    for (stage, name), (_, _, method) in zip(setup, originals):
        setattr(tasks.stacking.episode, name, timed(stage, method))
    cpu = time.process_time()
    try:
        params = load_participant(job.participant)
        profile = arm_profile(params.profile)
        channel = (JoystickChannel(profile_controls(profile)) if operator == "joystick" else
                   calibrated_channel(params, seed, replace(profile.post, vote_length=job.vote_length), profile))
    finally:
        for owner, name, method in originals:
            setattr(owner, name, method)
    setup_s = dict(spent) | {"set-up, all": time.process_time() - cpu}
    spent.clear()
    originals = [(owner, name, getattr(owner, name)) for _, owner, name in INSTRUMENTED]
    for (stage, owner, name), (_, _, method) in zip(INSTRUMENTED, originals):
        setattr(owner, name, timed(stage, method))
    try:
        with StepClock() as physics:
            log = run_episode(channel, operator=operator, participant="P1", seed=seed,
                              operator_file=load_operator(job.operator_file),
                              task_config=TaskConfig(time_limit=job.time_limit), assist=job_assist(job, profile))
    finally:
        for owner, name, method in originals:
            setattr(owner, name, method)
    ticks = len(log.t)
    out = {"mj_step (physics)": physics.cpu} | dict(spent)
    out["the rest (loop, channel, arm's joystick and actuators)"] = log.cpu_time - sum(out.values())
    return {"ticks": ticks, "loop_cpu_s": log.cpu_time, "us_per_tick": {k: 1e6 * v / ticks for k, v in out.items()},
            "setup_cpu_s": setup_s}


# ------------------------------------------------------------------------ running a benchmark
def pin_to_one_core() -> None:
    """This process on one core (the bars are per core), where the platform allows it."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def checkout_commit() -> str:
    """The short commit of this checkout (what a results file was made at)."""
    return os.popen(f"git -C {Path(__file__).resolve().parent} rev-parse --short HEAD").read().strip()


def write_results(name: str, record: dict, text: str) -> None:
    """``record`` as benchmarks/results/NAME.json and its table ``text`` as NAME.md; the table printed."""
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{name}.md").write_text(text, encoding="utf-8")
    (RESULTS / f"{name}.json").write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    print(text)


# ---------------------------------------------------------------------------------------- main
def ratios(rounds: list[dict[str, dict]], clock: str) -> dict[str, dict[str, float]]:
    """Per kind: median over rounds of (its x real time / the limit's) and (/ dm_control's), same round."""
    out = {}
    for kind in rounds[0]:
        x = [r[kind]["sim_s"] / r[kind][f"{clock}_s"] for r in rounds]
        limit = [r[PHYSICS]["sim_s"] / r[PHYSICS][f"{clock}_s"] for r in rounds]
        dm = [r[DM]["sim_s"] / r[DM][f"{clock}_s"] for r in rounds]
        out[kind] = {"x": statistics.median(x), "of_limit": statistics.median(a / b for a, b in zip(x, limit)),
                     "of_dm_control": statistics.median(a / b for a, b in zip(x, dm))}
    return out


def markdown(record: dict) -> str:
    args, rounds, wall, cpu = record["args"], record["rounds"], record["ratios"]["wall"], record["ratios"]["cpu"]
    m = record["machine"]
    lines = [
        f"# Episode speed, measured fairly ({args['rounds']} rounds, seeds {args['first_seed']}-"
        f"{args['first_seed'] + args['rounds'] - 1}, one process pinned to one core"
        f"{'; our operators with the human model' if args.get('human') else ''})", "",
        f"`python benchmarks/speed.py --rounds {args['rounds']} --first-seed {args['first_seed']}"
        f"{' --no-profile' if args['no_profile'] else ''}{' --human' if args.get('human') else ''}"
        f" --out {args['out']}` at commit "
        f"{record['commit']}. Machine: {m['cpu']}, {m['cpu_count']} cores shared with other work; 1-min load "
        f"average {m['load_before']:.2f} before, {m['load_after']:.2f} after the run. Python {m['python']}, "
        f"mujoco {record['versions']['mujoco']}, dm-control {record['versions']['dm-control']}, "
        f"pin {record['versions']['pin']}, numpy {record['versions']['numpy']}.", "",
        "How each kind is charged: see the script's docstring. In short: physics alone = `mj_step` of our scene, "
        f"arm at rest, no control (the limit; the least CPU of {args.get('physics_repeats', 1)} runs a round); "
        "dm_control = `reset()` + a 10 s episode of random actions, the "
        f"environment built once ({record['dm_control_build_s']:.2f} s, not charged); ours = `run_job` whole "
        "(files, the BoMI's calibration session and LDA training, the task), after one untimed episode of each "
        "kind (steady state, as a sweep worker). Ratios within a round, medians over rounds.", "",
        "| kind | x real time (wall) | of the limit (wall) | x dm_control (wall) | x real time (CPU) "
        "| of the limit (CPU) | x dm_control (CPU) | bar (of limit, x dm_control) |",
        "|---|---|---|---|---|---|---|---|"]
    for kind in wall:
        bar = BARS.get(kind)
        bar_text = "" if bar is None else (
            f">= {bar[0]}, >= {bar[1]}: {'met' if cpu[kind]['of_limit'] >= bar[0] and cpu[kind]['of_dm_control'] >= bar[1] else 'missed'} (CPU)")
        lines.append(f"| {kind} | {wall[kind]['x']:.1f} | {wall[kind]['of_limit']:.2f} | {wall[kind]['of_dm_control']:.2f} "
                     f"| {cpu[kind]['x']:.1f} | {cpu[kind]['of_limit']:.2f} | {cpu[kind]['of_dm_control']:.2f} | {bar_text} |")
    lines += ["", "Our episodes apart (medians over rounds, CPU seconds; x real time of the task loop alone and of "
              "the episode's own `mj_step` calls alone). The episode's own physics as a share of the limit is the "
              "ceiling of an episode whose every other cost were zero; the last column is what the bar leaves "
              "for all the rest (set-up, control, participant, chain) per control tick:", "",
              "| kind | simulated (s) | ticks | set-up (s) | task loop (s) | loop x real time | episode's own physics (s) "
              "| its x real time | its share of the limit (ceiling) | physics share of the loop "
              "| left for the rest at the bar (us/tick) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    limit_x = [r[PHYSICS]["sim_s"] / r[PHYSICS]["cpu_s"] for r in rounds]
    for kind in (JOY, BOMI):
        med = {k: statistics.median(r[kind][k] for r in rounds) for k in
               ("sim_s", "ticks", "setup_cpu_s", "loop_cpu_s", "physics_cpu_s")}
        loop_x = statistics.median(r[kind]["sim_s"] / r[kind]["loop_cpu_s"] for r in rounds)
        phys_x = statistics.median(r[kind]["sim_s"] / r[kind]["physics_cpu_s"] for r in rounds)
        ceiling = statistics.median(r[kind]["sim_s"] / r[kind]["physics_cpu_s"] / x for r, x in zip(rounds, limit_x))
        share = statistics.median(r[kind]["physics_cpu_s"] / r[kind]["loop_cpu_s"] for r in rounds)
        left = statistics.median(1e6 * (r[kind]["sim_s"] / (BARS[kind][0] * x) - r[kind]["physics_cpu_s"]) / r[kind]["ticks"]
                                 for r, x in zip(rounds, limit_x))
        lines.append(f"| {kind} | {med['sim_s']:.1f} | {med['ticks']:.0f} | {med['setup_cpu_s']:.2f} | "
                     f"{med['loop_cpu_s']:.2f} | {loop_x:.1f} | {med['physics_cpu_s']:.2f} | {phys_x:.1f} | "
                     f"{ceiling:.2f} | {share:.2f} | {left:.0f} |")
    lines += ["", "Every round (CPU s / wall s):", "", "| round | seed | " + " | ".join(wall) + " |",
              "|---|---|" + "---|" * len(wall)]
    for k, r in enumerate(rounds):
        lines.append(f"| {k} | {args['first_seed'] + k} | " + " | ".join(
            f"{r[kind]['sim_s']:.1f} s sim: {r[kind]['cpu_s']:.2f} / {r[kind]['wall_s']:.2f}"
            + (f" (CPU of its runs: {', '.join(f'{x:.2f}' for x in r[kind]['repeats_cpu_s'])})"
               if "repeats_cpu_s" in r[kind] else "") for kind in wall) + " |")
    prof = record.get("profile")
    if prof:
        bomi_i, joy_i = prof["bomi"]["instrumented"], prof["joystick"]["instrumented"]
        lines += ["", f"## Where a control tick's time goes (seed {args['profile_seed']})", "",
                  "CPU microseconds per control tick of the task loop, unprofiled: each call below timed alone "
                  "(`process_time` around it), the rest is the loop's own work, the channel and the arm's joystick "
                  "and actuators.", "", "| stage | BoMI (us/tick) | joystick (us/tick) |", "|---|---|---|"]
        for stage in bomi_i["us_per_tick"]:
            lines.append(f"| {stage} | {bomi_i['us_per_tick'][stage]:.0f} | {joy_i['us_per_tick'].get(stage, 0.0):.0f} |")
        lines.append(f"| **task loop** ({bomi_i['ticks']} / {joy_i['ticks']} ticks) | "
                     f"{1e6 * bomi_i['loop_cpu_s'] / bomi_i['ticks']:.0f} | {1e6 * joy_i['loop_cpu_s'] / joy_i['ticks']:.0f} |")
        lines += ["", "The BoMI episode's set-up, CPU seconds (unprofiled, the same episode): " + ", ".join(
            f"{stage} {s:.2f}" for stage, s in bomi_i["setup_cpu_s"].items()) + "."]
        lines += ["", f"### The same by cProfile (every function's own time, seed {args['profile_seed']})", "",
                  "Microseconds per control tick of the task loop, by stage (each function's own time; a library "
                  "function's time goes to the stage of our code that called it). cProfile adds a cost to every "
                  "Python call, so Python-heavy stages weigh more here than unprofiled.", "",
                  "| stage | BoMI (us/tick) | joystick (us/tick) |", "|---|---|---|"]
        stages = sorted(set(prof["bomi"]["loop_us_per_tick"]) | set(prof["joystick"]["loop_us_per_tick"]),
                        key=lambda s: -prof["bomi"]["loop_us_per_tick"].get(s, 0.0))
        for stage in stages:
            lines.append(f"| {stage} | {prof['bomi']['loop_us_per_tick'].get(stage, 0.0):.0f} | "
                         f"{prof['joystick']['loop_us_per_tick'].get(stage, 0.0):.0f} |")
        lines.append(f"| **total** ({prof['bomi']['ticks']} / {prof['joystick']['ticks']} ticks) | "
                     f"{sum(prof['bomi']['loop_us_per_tick'].values()):.0f} | "
                     f"{sum(prof['joystick']['loop_us_per_tick'].values()):.0f} |")
        lines += ["", "The BoMI episode's set-up (calibration session, recording, training), profiled seconds by stage:", "",
                  "| stage | s |", "|---|---|"]
        lines += [f"| {stage} | {s:.3f} |" for stage, s in prof["bomi"]["setup"].items() if s >= 0.005]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--first-seed", type=int, default=0, help="task seed of the first round (development: 0-999)")
    parser.add_argument("--profile-seed", type=int, default=0, help="task seed of the profiled episodes")
    parser.add_argument("--physics-s", type=float, default=20.0, help="simulated seconds of physics alone per run")
    parser.add_argument("--physics-repeats", type=int, default=5,
                        help="runs of physics alone per round, the least disturbed one charged")
    parser.add_argument("--no-profile", action="store_true", help="skip the cProfile tables")
    parser.add_argument("--human", action="store_true",
                        help="our episodes with the human operator model on (docs/human_model.md); with --no-profile")
    parser.add_argument("--out", default="side_by_side", help="results file name (benchmarks/results/OUT.md, .json)")
    args = parser.parse_args()
    if args.human and not args.no_profile:
        parser.error("--human: the profile tables are the scripted user's; add --no-profile")
    overrides = HUMAN_ON if args.human else ()
    pin_to_one_core()
    load_before = os.getloadavg()[0]
    arm = ArmSim()
    built = time.perf_counter()
    env = manipulation.load("stack_2_bricks_features", seed=args.first_seed)
    build_s = time.perf_counter() - built
    dm_control_episode(env, 0)   # steady state for every kind: one untimed run each
    our_episode("joystick", args.first_seed, overrides)
    our_episode("bomi", args.first_seed, overrides)
    rounds = []
    for k in range(args.rounds):
        seed = args.first_seed + k
        kinds = {PHYSICS: lambda: physics_alone(arm, args.physics_s, args.physics_repeats), DM: lambda: dm_control_episode(env, seed),
                 JOY: lambda: our_episode("joystick", seed, overrides), BOMI: lambda: our_episode("bomi", seed, overrides)}
        order = list(kinds)[k % 4:] + list(kinds)[:k % 4]   # who goes first rotates
        rounds.append({kind: r for kind, r in sorted(((kind, kinds[kind]()) for kind in order),
                                                      key=lambda kv: list(kinds).index(kv[0]))})
        print(f"round {k}: " + ", ".join(f"{kind.split(':')[0].split(' (')[0]} {r['sim_s'] / r['cpu_s']:.1f}x"
                                         for kind, r in rounds[-1].items()), flush=True)
    profile = None if args.no_profile else {op: profile_episode(op, args.profile_seed) | {
        "instrumented": instrumented_episode(op, args.profile_seed)} for op in ("bomi", "joystick")}
    record = {
        "args": vars(args), "commit": checkout_commit(),
        "machine": {"cpu": platform.processor() or platform.machine(), "cpu_count": os.cpu_count(),
                    "python": platform.python_version(), "load_before": load_before, "load_after": os.getloadavg()[0]},
        "versions": {name: version(name) for name in ("mujoco", "dm-control", "pin", "numpy")},
        "dm_control_build_s": build_s, "rounds": rounds,
        "ratios": {clock: ratios(rounds, clock) for clock in ("wall", "cpu")}, "profile": profile,
    }
    write_results(args.out, record, markdown(record))


if __name__ == "__main__":
    main()
