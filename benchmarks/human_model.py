"""The human operator model: its one fitted parameter on the joystick, then the BoMI as a prediction.

    python benchmarks/human_model.py calibrate [--seeds 20] [--slopes 0.35,0.5,0.65] [--jobs 1]
    python benchmarks/human_model.py predict [--participants P1,P4,P5] [--seeds 5] [--jobs 1]

``calibrate`` runs the joystick operator (tasks/human.toml, only ``timing.fitts_slope`` varied) on
dev seeds 0..N-1 and interpolates the slope at which the mean completion time is the paper's
joystick mean (58 s): benchmarks/results/human_calibration.{md,json}.  Nothing of the BoMI is run.

``predict`` runs the joystick and the BoMI of each participant with tasks/human.toml as shipped
(the operator file's ``[human] model = "human"``) on dev seeds 0..N-1: completion times against the
paper, the BoMI/joystick ratio, time per phase and the share of time spent switching modes
(Herlant et al. 2016: 17.4 % for able-bodied JACO users): benchmarks/results/human_model.{md,json,png}.
"""
from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bomi import paper  # noqa: E402
from tasks import metrics  # noqa: E402
from tasks.cli.engine import ProcessPool  # noqa: E402
from tasks.cli.task import EpisodeJob, run_job  # noqa: E402
from tasks.episode import summarize  # noqa: E402
from tasks.human import DEFAULT_HUMAN_FILE  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
PAPER_JOYSTICK_S = paper.TASK["joystick_time_s"]
PAPER_BOMI_S = paper.TASK["bomi_time_s"]
HERLANT_MODE_SWITCH_SHARE = 0.174


def episode(job: EpisodeJob) -> dict:
    """One episode's summary with its time per phase and its mode-switching time (until success)."""
    log = run_job(job)
    record = summarize(log)
    dt = float(log.t[1] - log.t[0])
    until = int(round(log.completion_time / dt)) if log.success else None
    record["phase_times"] = metrics.phase_times(log.goals, dt, until, log.stages)
    record["mode_switch_time"] = metrics.mode_switch_time(log.mode, log.pushing, dt, until)
    return record


def run(jobs: list[EpisodeJob], workers: int) -> list[dict]:
    results = dict(ProcessPool(workers).run(episode, jobs))
    return [results[i] for i in range(len(jobs))]


def mean_ci(values: list[float]) -> tuple[float, float]:
    """Mean and half-width of its 95 % Student-t interval."""
    import scipy.stats
    m = statistics.fmean(values)
    if len(values) < 2:
        return m, float("nan")
    return m, float(scipy.stats.t.ppf(0.975, len(values) - 1) * statistics.stdev(values) / len(values) ** 0.5)


def human_variant(directory: Path, fitts_slope: float) -> str:
    """A copy of tasks/human.toml with another Fitts slope (the one parameter fitted)."""
    text = DEFAULT_HUMAN_FILE.read_text()
    line = next(x for x in text.splitlines() if x.startswith("fitts_slope"))
    path = directory / f"human_fitts_{fitts_slope:g}.toml"
    path.write_text(text.replace(line, f"fitts_slope = {fitts_slope!r}"))
    return str(path)


def calibrate(args: argparse.Namespace) -> None:
    slopes = [float(x) for x in args.slopes.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        jobs = [EpisodeJob("joystick", "P1", seed, overrides=(("operator.human.model", human_variant(Path(tmp), b)),))
                for b in slopes for seed in range(args.seeds)]
        records = run(jobs, args.jobs)
    rows = []
    for b in slopes:
        rs = [r for r, j in zip(records, jobs) if j.overrides[0][1].endswith(f"_{b:g}.toml")]
        times = [r["completion_time"] for r in rs if r["success"]]
        m, h = mean_ci(times)
        rows.append({"fitts_slope": b, "successes": len(times), "episodes": len(rs), "mean": m, "ci95": h})
    means = np.array([r["mean"] for r in rows])
    order = np.argsort(means)
    fitted = float(np.interp(PAPER_JOYSTICK_S, means[order], np.array(slopes)[order]))
    lines = ["# Human model: the Fitts slope fitted on the joystick (dev seeds)", "",
             f"`python benchmarks/human_model.py calibrate --seeds {args.seeds} --slopes {args.slopes}`: joystick "
             f"operator with tasks/human.toml, only `timing.fitts_slope` varied, seeds 0-{args.seeds - 1}. "
             f"Target: the paper's joystick mean {PAPER_JOYSTICK_S:.1f} s.", "",
             "| fitts_slope (s/bit) | successes | completion time mean (s) | 95 % CI half-width |", "|---|---|---|---|"]
    lines += [f"| {r['fitts_slope']:g} | {r['successes']}/{r['episodes']} | {r['mean']:.1f} | {r['ci95']:.1f} |"
              for r in rows]
    lines += ["", f"Linear interpolation to {PAPER_JOYSTICK_S:.1f} s: fitts_slope = {fitted:.3f} s/bit."]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "human_calibration.md").write_text("\n".join(lines) + "\n")
    (RESULTS / "human_calibration.json").write_text(json.dumps({"rows": rows, "fitted": fitted,
                                                                "records": records}, indent=1))
    print("\n".join(lines))


def predict(args: argparse.Namespace) -> None:
    participants = args.participants.split(",")
    human = (("operator.human.model", "human"),)
    jobs = [EpisodeJob("joystick", "P1", seed, overrides=human) for seed in range(args.seeds)]
    jobs += [EpisodeJob("bomi", p, seed, overrides=human) for p in participants for seed in range(args.seeds)]
    records = run(jobs, args.jobs)
    groups: dict[str, list[dict]] = {}
    for job, r in zip(jobs, records):
        groups.setdefault("joystick" if job.operator == "joystick" else f"{job.participant} BoMI", []).append(r)
    joystick = statistics.fmean(r["completion_time"] for r in groups["joystick"] if r["success"])
    paper_times = {"joystick": PAPER_JOYSTICK_S, "P1 BoMI": PAPER_BOMI_S}
    lines = ["# Human model: joystick and BoMI completion times (dev seeds)", "",
             f"`python benchmarks/human_model.py predict --participants {args.participants} --seeds {args.seeds}`: "
             f"tasks/human.toml as shipped (fitted on the joystick only), seeds 0-{args.seeds - 1}.", "",
             "| condition | successes | completion time mean (s) | 95 % CI | paper (s) | / joystick | paper ratio | "
             "mode-switch share | reach | grasp | carry | release | other |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, rs in groups.items():
        done = [r for r in rs if r["success"]]
        times = [r["completion_time"] for r in done]
        m, h = mean_ci(times) if times else (float("nan"), float("nan"))
        share = statistics.fmean(r["mode_switch_time"] / r["completion_time"] for r in done) if done else float("nan")
        phases = {k: statistics.fmean(r["phase_times"][k] for r in done) if done else float("nan")
                  for k in ("reach", "grasp", "carry", "release", "other")}
        ref = paper_times.get(name)
        lines.append(f"| {name} | {len(done)}/{len(rs)} | {m:.1f} | ±{h:.1f} | {'' if ref is None else ref:} | "
                     f"{m / joystick:.2f} | {f'{PAPER_BOMI_S / PAPER_JOYSTICK_S:.2f}' if name == 'P1 BoMI' else ''} | {100 * share:.1f} % | "
                     + " | ".join(f"{phases[k]:.1f}" for k in phases) + " |")
    lines += ["", f"Mode-switch share: time from the last push before a mode change to the first push after it, "
                  f"over the completion time (Herlant et al. 2016 measured {100 * HERLANT_MODE_SWITCH_SHARE:.1f} % "
                  f"for able-bodied JACO joystick users). Phases in seconds (mean over successful episodes)."]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "human_model.md").write_text("\n".join(lines) + "\n")
    (RESULTS / "human_model.json").write_text(json.dumps({"groups": groups}, indent=1))
    fig, ax = plt.subplots(figsize=(8, 4))
    for k, (name, rs) in enumerate(groups.items()):
        times = [r["completion_time"] for r in rs if r["success"]]
        ax.plot([k] * len(times), times, "o", alpha=0.6)
    ax.axhline(PAPER_JOYSTICK_S, color="grey", ls="--", label=f"paper joystick {PAPER_JOYSTICK_S:g} s")
    ax.axhline(PAPER_BOMI_S, color="black", ls="--", label=f"paper P1 BoMI {PAPER_BOMI_S:g} s")
    ax.set_xticks(range(len(groups)), list(groups))
    ax.set_ylabel("completion time (s)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(RESULTS / "human_model.png", dpi=110)
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    cal = sub.add_parser("calibrate", help="fit the Fitts slope on the joystick (dev seeds)")
    cal.add_argument("--seeds", type=int, default=20, help="dev seeds 0..N-1 (default 20)")
    cal.add_argument("--slopes", default="0.35,0.5,0.65", help="Fitts slopes tried, s/bit (default 0.35,0.5,0.65)")
    pred = sub.add_parser("predict", help="joystick and BoMI with the shipped human model (dev seeds)")
    pred.add_argument("--participants", default="P1,P4,P5", help="BoMI participants (default P1,P4,P5)")
    pred.add_argument("--seeds", type=int, default=5, help="dev seeds 0..N-1 (default 5)")
    for p in (cal, pred):
        p.add_argument("--jobs", type=int, default=1, help="parallel episodes (default 1)")
    args = parser.parse_args()
    calibrate(args) if args.command == "calibrate" else predict(args)


if __name__ == "__main__":
    main()
