"""Where MuJoCo's Newton solver spends its iterations while the arm moves, and whether the scene's
solver options (tolerance, line search, iteration cap, dense or sparse Jacobian) make an episode's
physics cheaper without making the limit (the scene at rest) cheaper as much.

    python benchmarks/solver_options.py [--seed 0] [--rounds 5] [--rest-ticks 600]

Method: ``benchmarks/physics_cost.py``'s replay.  A joystick episode of virtual P1 (task seed
``--seed``, development) is recorded once (the integration state before every control tick), and
so are ``--rest-ticks`` ticks of the scene at rest (the limit's ticks).  Per option: (1) solver
statistics per 1/480 s substep, deterministic: solver iterations summed over the constraint
islands (``data.solver_niter``: Newton's, and noslip's where it has work), line-search cost
evaluations and Cholesky rank updates (``data.solver[...].neval``, ``.nupdate``); (2) the replay's CPU time relative to the shipped
scene, the two replayed alternately ``--rounds`` times (the median of the per-round ratios: the same
load for both).  A ratio below 1 at rest speeds the limit; only one below 1 in the episode and not
at rest would bring an episode nearer the limit.  The options change trajectories (none is
adopted without an outcome check): the replay measures their cost on the same states.  Writes
benchmarks/results/solver_options.md and .json.
"""
from __future__ import annotations

import statistics

import mujoco
import numpy as np

from physics_cost import (STATE, Variant, _option, build, record_episode, record_rest, replay, replay_arguments,
                          write_results)

OPTIONS = (
    Variant("line search tolerance 0.1 (from 0.01)", False, True, _option(ls_tolerance=0.1)),
    Variant("line search at most 5 evaluations (from 50)", False, True, _option(ls_iterations=5)),
    Variant("Newton at most 3 iterations (from 100)", False, True, _option(iterations=3)),
    Variant("sparse Jacobian (auto picks dense: 21 dofs)", False, True,
            _option(jacobian=mujoco.mjtJacobian.mjJAC_SPARSE)),
    Variant("solver tolerance 1e-5 (from 1e-8)", False, True, _option(tolerance=1e-5)),
    Variant("noslip 2 iterations (from 5; grasps may slip)", False, True, _option(noslip_iterations=2)),
)
STATS = ("solver_iterations", "line_search_evaluations", "cholesky_updates")


def solver_statistics(arm, states: np.ndarray) -> dict[str, float]:
    """Per substep, means over the replayed ticks: solver iterations (all islands), line-search
    evaluations and Cholesky rank updates."""
    model, data, substeps = arm.model, arm.data, arm.config.physics.substeps
    totals = np.zeros(3)
    for state in states:
        mujoco.mj_setState(model, data, state, STATE)
        for _ in range(substeps):
            mujoco.mj_step(model, data)
            for island in range(max(1, data.nisland)):
                iterations = int(data.solver_niter[island])
                totals[0] += iterations
                for k in range(min(iterations, mujoco.mjNSOLVER)):
                    stat = data.solver[island * mujoco.mjNSOLVER + k]
                    totals[1:] += (stat.neval, stat.nupdate)
    return dict(zip(STATS, (totals / (len(states) * substeps)).tolist()))


def relative_cost(shipped, arm, states: np.ndarray, rounds: int) -> float:
    """Median over rounds of (the option's replay CPU time / the shipped scene's), replayed alternately."""
    ratios = []
    for _ in range(rounds):
        base = replay(shipped, states, timed=False)["cpu_us"]
        ratios.append(replay(arm, states, timed=False)["cpu_us"] / base)
    return statistics.median(ratios)


def markdown(record: dict) -> str:
    shipped = record["shipped"]
    lines = ["# Solver options: where Newton's iterations go while the arm moves, and what the options cost", "",
             f"`python benchmarks/solver_options.py --seed {record['seed']} --rounds {record['rounds']} --rest-ticks "
             f"{record['rest_ticks']}` at commit {record['commit']}. {record['machine']}", "",
             f"Replayed: {record['episode_ticks']} control ticks of the joystick episode of P1 (task seed "
             f"{record['seed']}) and {record['rest_ticks']} ticks at rest (the limit's). Statistics per 1/480 s "
             "substep (deterministic; solver iterations: Newton's and noslip's, summed over the islands, as "
             "`data.solver_niter` counts them); cost = the option's replay CPU time over the shipped scene's, replayed "
             "alternately, median of the rounds' ratios. See the script's docstring.", "",
             "| scene | at rest: solver iterations | line-search evaluations | Cholesky updates | episode: solver "
             "iterations | line-search evaluations | Cholesky updates | cost at rest | cost in the episode |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in [{"name": "shipped (Newton, tolerance 1e-8, noslip 5)", **shipped, "cost": {"rest": 1.0, "episode": 1.0}},
                *record["options"]]:
        lines.append(f"| {row['name']} | " + " | ".join(f"{row[kind][s]:.2f}" for kind in ("rest", "episode")
                                                         for s in STATS)
                     + f" | {row['cost']['rest']:.3f} | {row['cost']['episode']:.3f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    args = replay_arguments(__doc__.split("\n\n")[0], 5, "alternate replays per option and kind")
    episode, _ = record_episode(args.seed)
    kinds = {"rest": record_rest(args.rest_ticks), "episode": episode}
    shipped = build(Variant("shipped", True))
    record = {"seed": args.seed, "rounds": args.rounds, "rest_ticks": args.rest_ticks, "episode_ticks": len(episode),
              "shipped": {kind: solver_statistics(shipped, states) for kind, states in kinds.items()}, "options": []}
    for option in OPTIONS:
        arm = build(option)
        record["options"].append({"name": option.name,
                                  **{kind: solver_statistics(arm, states) for kind, states in kinds.items()},
                                  "cost": {kind: relative_cost(shipped, arm, states, args.rounds)
                                           for kind, states in kinds.items()}})
        arm.close()
        print(f"{option.name}: cost at rest {record['options'][-1]['cost']['rest']:.3f}, in the episode "
              f"{record['options'][-1]['cost']['episode']:.3f}", flush=True)
    shipped.close()
    write_results("solver_options", record, markdown)

if __name__ == "__main__":
    main()
