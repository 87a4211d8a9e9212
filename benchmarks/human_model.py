"""The human operator model: its one fitted parameter on the joystick, then the BoMI as a prediction.

    python benchmarks/human_model.py calibrate [--seeds 20] [--slopes 0.35,0.5,0.65] [--jobs 1]
    python benchmarks/human_model.py predict [--participants P1,P4,P5] [--seeds 5] [--first-seed 0] [--name N] [--jobs 1]
    python benchmarks/human_model.py check --seeds A-B [--cells P1:joystick,P1:bomi,P4:bomi,P5:bomi] [--recovery R]
    python benchmarks/human_model.py sensitivity [--params K,K] [--seeds 5] [--first-seed 0] [--jobs 1]
    python benchmarks/human_model.py latency --seeds A-B [--participants P1,P4,P5]
    python benchmarks/human_model.py pushes --seeds A-B [--cells P1:bomi]

``calibrate`` runs the joystick operator (tasks/operators/human.toml, only ``timing.fitts_slope`` varied) on
dev seeds 0..N-1 and interpolates the slope at which the mean completion time is the paper's
joystick mean (58 s): benchmarks/results/human_calibration.{md,json}.  Nothing of the BoMI is run.

``predict`` runs the joystick and the BoMI of each participant with tasks/operators/human.toml as shipped
(the operator file's ``[human] model = "human"``): completion times against the paper, the
BoMI/joystick ratio, time per phase, the share of time spent switching modes (Herlant et al. 2016:
17.4 % for able-bodied JACO users), the fastest joystick and P1 BoMI trials in the paper's layout:
benchmarks/results/N.{md,json,png}, N_phases.png, N_best.png.  Development seeds by default; a
held-out range (a fresh one of 10000-19999; 1000-4999 are spent) only once the model is frozen.

``check`` (issue 53) runs each participant:operator cell with the human model on, one episode at a time,
and prints one JSON row per cell: successes, mean time and its budget over the successes (seconds per
``tasks.stacking.budget.Part``), the share of relevant decisions (not ``metrics.irrelevant``), the longest
irrelevant run, the irrelevant decisions by context (``tasks.stacking.budget``).

``latency`` (issue 53.3) times the body against a real person's cue-to-decision latency (issue 53: a median
560 ms, SD 185 ms on a continuous calibration recording): each seed's participant performs the protocol twice
on one day, both kept continuous (the moves in), a model is trained on the first, and the second is decided
window by window as the stream is; per cue (``metrics.decision_latencies``), the time from the cue to the first decision of the cued class.

``pushes`` (issue 53: where a BoMI episode's pushes go) reads each episode's pushes of the hand (runs of ticks
pushed along one direction: a BoMI drives one function at a time; a stick pushing several axes at once changes
direction at every look, so its runs are not pushes) from its record: how many, how long, how far they moved the hand; and each push of a
step's travel (``metrics``' stage "travel") against the true error along the pushed axis when it began (the cube
to reach, or the held cube's place): ``needless`` (the true error already under ``NEEDLESS_M``, the push made on a
misjudgement), ``wrong way``, ``unanswered`` (the hand moved under 2 mm), ``short`` (under 60 % of the error),
``long`` (over 140 %), else ``ok``.

``sensitivity`` varies each human parameter alone (50 %, 150 %) for the joystick and P1's BoMI:
benchmarks/results/human_sensitivity.{md,json}.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections import Counter
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bomi import paper  # noqa: E402
from bomi.chain import prepare, train  # noqa: E402
from bomi.classifier import NEUTRAL_LABEL, classify_windows  # noqa: E402
from bomi.fusion import DT  # noqa: E402
from tasks.stacking import metrics  # noqa: E402
from tasks.experiments.engine import ProcessPool  # noqa: E402
from tasks.experiments.jobs import HUMAN_MODEL_KEY, HUMAN_ON, RECOVERY_KEY, EpisodeJob, run_job  # noqa: E402
from tasks.stacking import budget  # noqa: E402
from tasks.stacking.task import TaskConfig  # noqa: E402
from tasks.stacking.channels import participant_controls
from tasks.stacking.summary import summarize
from tasks.operators.human import DEFAULT_HUMAN_FILE, load_human  # noqa: E402
from tasks.operators.params import DEFAULT_OPERATOR_FILE, load_operator  # noqa: E402
from tasks.operators.stick import arm_profile  # noqa: E402
from tasks.participants.participant import Session, calibration_session, load_participant, session_recording  # noqa: E402
from tasks.stacking.timeline import timeline_figure  # noqa: E402
from tasks.statistics import mean_interval, wilson_interval

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
    """Mean and half-width of its 95 % Student-t interval (``tasks.statistics.mean_interval``; nan below two values)."""
    interval = mean_interval(values)
    m = statistics.fmean(values) if values else float("nan")
    return m, float("nan") if interval is None else (interval[1] - interval[0]) / 2


def human_variant(directory: Path, key: str, value: float) -> str:
    """A copy of tasks/operators/human.toml with ``key`` (a key of any table; they are unique) set to ``value``."""
    text = DEFAULT_HUMAN_FILE.read_text()
    line = next(x for x in text.splitlines() if x.split("=")[0].strip() == key)
    comment = line[line.index("#"):] if "#" in line else ""
    path = directory / f"human_{key}_{value:g}.toml"
    path.write_text(text.replace(line, f"{key} = {value!r}  {comment}"))
    return str(path)


def calibrate(args: argparse.Namespace) -> None:
    slopes = [float(x) for x in args.slopes.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        jobs = [EpisodeJob("joystick", "P1", seed, overrides=((HUMAN_MODEL_KEY, human_variant(Path(tmp), "fitts_slope", b)),))
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
             f"operator with tasks/operators/human.toml, only `timing.fitts_slope` varied, seeds 0-{args.seeds - 1}. "
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


PHASES = ("reach", "grasp", "carry", "place", "release", "other")


def joystick_on(controls: str) -> str:
    """The joystick condition on these controls (a results row's ``layout``, e.g. "2-axis, B1")."""
    return f"joystick ({controls})"


def condition(record: dict) -> str:
    return joystick_on(record["layout"]) if record["operator"] == "joystick" else f"{record['participant']} BoMI"


def group_records(records: list[dict]) -> tuple[dict[str, list[dict]], dict[str, str]]:
    """Episode records by condition (participants with the same controls share one joystick row: an
    episode of a seed already there is not added twice), and each condition's joystick on the same controls."""
    groups: dict[str, list[dict]] = {}
    for r in records:
        group = groups.setdefault(condition(r), [])
        if not any(other["seed"] == r["seed"] for other in group):
            group.append(r)
    return groups, {condition(r): joystick_on(r["layout"]) for r in records}


def predict(args: argparse.Namespace) -> None:
    participants = args.participants.split(",")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    # the joystick on the paper's controls, and on each participant's (like for like: P4/P5 have 2 axes, 1 button)
    by_controls: dict[str, str] = {}  # one joystick run per distinct controls (P4 and P5 share theirs)
    for p in ["P1", *participants]:
        by_controls.setdefault(participant_controls(p).label, p)
    jobs = [EpisodeJob("joystick", p, seed, overrides=HUMAN_ON) for p in by_controls.values() for seed in seeds]
    jobs += [EpisodeJob("bomi", p, seed, overrides=HUMAN_ON) for p in participants for seed in seeds]
    records = run(jobs, args.jobs)
    groups, reference = group_records(records)
    paper_joystick = joystick_on(next(r["layout"] for r, j in zip(records, jobs) if j.participant == "P1"))
    paper_times = {paper_joystick: PAPER_JOYSTICK_S, "P1 BoMI": PAPER_BOMI_S}
    seed_words = f"seeds {seeds[0]}-{seeds[-1]}" + (" (held out)" if seeds[0] >= 1000 else " (development)")
    lines = [f"# Human model: joystick and BoMI completion times, {seed_words}", "",
             f"`python benchmarks/human_model.py predict --participants {args.participants} --seeds {args.seeds} "
             f"--first-seed {args.first_seed} --name {args.name}`: tasks/operators/human.toml as shipped (fitted on the joystick "
             f"only).", "",
             "| condition | successes [95 % CI] | completion time mean (s) [95 % CI] | paper (s) | within 25 % | "
             "/ joystick on the same controls | paper ratio | mode-switch share | " + " | ".join(PHASES) + " |",
             "|---|---|---|---|---|---|---|---|" + "---|" * len(PHASES)]
    means = {name: statistics.fmean([r["completion_time"] for r in rs if r["success"]] or [float("nan")])
             for name, rs in groups.items()}
    for name, rs in groups.items():
        done = [r for r in rs if r["success"]]
        times = [r["completion_time"] for r in done]
        m, h = mean_ci(times) if times else (float("nan"), float("nan"))
        low, high = wilson_interval(len(done), len(rs))
        share = statistics.fmean(r["mode_switch_time"] / r["completion_time"] for r in done) if done else float("nan")
        phases = {k: statistics.fmean(r["phase_times"][k] for r in done) if done else float("nan") for k in PHASES}
        ref = paper_times.get(name)
        near = "" if ref is None else ("yes" if abs(m - ref) <= 0.25 * ref else f"no ({100 * (m / ref - 1):+.0f} %)")
        lines.append(f"| {name} | {len(done)}/{len(rs)} [{100 * low:.0f}, {100 * high:.0f}] % | {m:.1f} "
                     f"[{m - h:.1f}, {m + h:.1f}] | {'' if ref is None else f'{ref:g}'} | {near} | {m / means[reference[name]]:.2f} | "
                     f"{f'{PAPER_BOMI_S / PAPER_JOYSTICK_S:.2f}' if name == 'P1 BoMI' else ''} | {100 * share:.1f} % | "
                     + " | ".join(f"{phases[k]:.1f}" for k in PHASES) + " |")
    best = {name: min((r for r in groups.get(name, []) if r["success"]), key=lambda r: r["completion_time"], default=None)
            for name in (paper_joystick, "P1 BoMI")}
    best_names = [name for name, r in best.items() if r is not None]
    failed = [f"{r['participant']} {r['operator']} seed {r['seed']} ({r['failure']})"
              for rs in groups.values() for r in rs if not r["success"]]
    lines += ["", f"Failed: {', '.join(failed) if failed else 'none'}.", "",
              f"Mode-switch share: time from the last push before a mode change to the first push after it, "
              f"over the completion time (Herlant et al. 2016 measured {100 * HERLANT_MODE_SWITCH_SHARE:.1f} % "
              f"for able-bodied JACO joystick users). Phases: mean seconds over the successful episodes "
              f"(`tasks.stacking.metrics.TaskPhase`: place = the carried cube lowered onto its place). Figures: "
              f"{args.name}.png (times), {args.name}_phases.png (phases), {args.name}_best.png (the fastest "
              f"trial of {' and '.join(best_names) or 'no condition'} in the paper's layout: hand relative to B, "
              f"then the BoMI's decisions and amplitude)."]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    (RESULTS / f"{args.name}.json").write_text(json.dumps({"groups": groups}, indent=1))
    times_figure(groups, RESULTS / f"{args.name}.png")
    phases_figure(groups, RESULTS / f"{args.name}_phases.png")
    logs = [run_job(EpisodeJob(best[name]["operator"], best[name]["participant"], best[name]["seed"], overrides=HUMAN_ON))
            for name in best_names]
    if logs:
        timeline_figure(logs, RESULTS / f"{args.name}_best.png")
    print("\n".join(lines))


def times_figure(groups: dict[str, list[dict]], path: Path) -> None:
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
    fig.savefig(path, dpi=110)
    plt.close(fig)


def phases_figure(groups: dict[str, list[dict]], path: Path) -> None:
    """Mean seconds per task phase, one stacked bar per condition."""
    fig, ax = plt.subplots(figsize=(8, 4))
    names = list(groups)
    bottom = np.zeros(len(names))
    for phase in PHASES:
        means = np.array([statistics.fmean(r["phase_times"][phase] for r in groups[n] if r["success"])
                          if any(r["success"] for r in groups[n]) else 0.0 for n in names])
        ax.bar(names, means, bottom=bottom, label=phase)
        bottom += means
    ax.set_ylabel("mean time per phase (s), successful episodes")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


SENSITIVE = ("fitts_slope", "rt_mu", "hick_slope", "visual_delay", "glance_interval", "lateral_weber", "depth_ratio",
             "check_pause", "wrong_mode_rate")


def sensitivity(args: argparse.Namespace) -> None:
    """Each human parameter alone at 50 % and 150 % of its shipped value: joystick and P1 BoMI times, ratio."""
    params = load_human()
    keys = args.params.split(",")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    with tempfile.TemporaryDirectory() as tmp:
        settings = [(None, None)] + [(k, f * float(getattr(params, k))) for k in keys for f in (0.5, 1.5)]
        jobs, cells = [], []
        for key, value in settings:
            human = "human" if key is None else human_variant(Path(tmp), key, value)
            for operator in ("joystick", "bomi"):
                for seed in seeds:
                    jobs.append(EpisodeJob(operator, "P1", seed, overrides=((HUMAN_MODEL_KEY, human),)))
                    cells.append((key, value, operator))
        records = run(jobs, args.jobs)
    table: dict[tuple, dict[str, list[float]]] = {}
    for (key, value, operator), r in zip(cells, records):
        entry = table.setdefault((key, value), {"joystick": [], "bomi": [], "failed": []})
        (entry[operator] if r["success"] else entry["failed"]).append(r["completion_time"] or 0.0)
    base = table[(None, None)]
    base_j, base_b = statistics.fmean(base["joystick"]), statistics.fmean(base["bomi"])
    lines = [f"# Human model sensitivity (seeds {seeds[0]}-{seeds[-1]})", "",
             f"`python benchmarks/human_model.py sensitivity --seeds {args.seeds} --first-seed {args.first_seed}`: "
             f"each parameter of tasks/operators/human.toml alone at 50 % and 150 %, the same seeds; mean completion time "
             f"of the successful episodes, P1.", "",
             "| parameter | value | joystick (s) | change | P1 BoMI (s) | change | ratio | failures (joystick + BoMI) |",
             "|---|---|---|---|---|---|---|---|",
             f"| as shipped | | {base_j:.1f} | | {base_b:.1f} | | {base_b / base_j:.2f} | {len(base['failed'])} |"]
    for (key, value), e in table.items():
        if key is None:
            continue
        j = statistics.fmean(e["joystick"]) if e["joystick"] else float("nan")
        b = statistics.fmean(e["bomi"]) if e["bomi"] else float("nan")
        lines.append(f"| {key} | {value:g} | {j:.1f} | {100 * (j / base_j - 1):+.0f} % | {b:.1f} | "
                     f"{100 * (b / base_b - 1):+.0f} % | {b / j:.2f} | {len(e['failed'])} |")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "human_sensitivity.md").write_text("\n".join(lines) + "\n")
    (RESULTS / "human_sensitivity.json").write_text(json.dumps(
        [{"parameter": k, "value": v, **e} for (k, v), e in table.items()], indent=1))
    print("\n".join(lines))


def seed_range(text: str) -> range:
    first, _, last = text.partition("-")
    return range(int(first), int(last or first) + 1)


def cell_row(participant: str, operator: str, seeds: range, recovery: str | None = None) -> dict:
    records, contexts, decisions, budgets = [], Counter(), 0, []
    overrides = HUMAN_ON + (((RECOVERY_KEY, recovery),) if recovery else ())
    still = load_operator(DEFAULT_OPERATOR_FILE).still_speed
    for seed in seeds:
        log = run_job(EpisodeJob(operator, participant, seed, overrides=overrides))
        record = summarize(log)
        records.append(record)
        if record["success"]:
            budgets.append(budget.time_budget(log, still))
        if operator == "bomi":
            contexts.update({c.value: n for c, n in budget.irrelevant_by_context(log).items()})
            decisions += len(log.decisions.t)
        print(json.dumps({k: record.get(k) for k in ("participant", "operator", "seed", "success", "completion_time",
                                                       "irrelevant_decisions", "irrelevant_longest_run_ms", "stuck")}, default=str),
              file=sys.stderr, flush=True)
    times = [r["completion_time"] for r in records if r["success"]]
    row = {"cell": f"{participant} {operator}", "recovery": recovery or "none", "seeds": f"{seeds.start}-{seeds.stop - 1}",
           "success": f"{len(times)}/{len(records)}", "mean_time_s": round(float(np.mean(times)), 1) if times else None,
           "time_budget_s": {part.value: round(float(np.mean([b[part] for b in budgets])), 1) for part in budget.Part}
           if budgets else None}
    if operator == "bomi":
        wild = sum(r["irrelevant_decisions"] for r in records)
        row.update({"relevant_pct": round(100.0 * (1.0 - wild / decisions), 2),
                    "longest_irrelevant_ms_max": max(r["irrelevant_longest_run_ms"] for r in records),
                    "longest_irrelevant_ms_mean": round(float(np.mean([r["irrelevant_longest_run_ms"] for r in records])), 1),
                    "irrelevant_by_context": dict(contexts)})
    return row


def cue_latencies_s(participant: str, seed: int) -> list[float]:
    """Per motion cue of a second continuous session of ``seed``'s day, the time from the cue to the first
    decision of the cued class by a model trained on the first, every window decided in time order as the
    stream decides them (``metrics.decision_latencies``, the episodes' own; a cue never decided: left out)."""
    params = load_participant(participant)
    profile = arm_profile(params.profile)
    first = calibration_session(params, profile, seed)
    model = train([session_recording(first, profile, holds_only=False)], profile)
    rec = session_recording(calibration_session(params, profile, seed, session=Session.TASK), profile, holds_only=False)
    windows = prepare(rec, model.spec, profile.neutral_samples)   # labels: the cue on screen at each window's end
    decided = classify_windows(model, windows.features, model.post).labels
    return (metrics.decision_latencies(windows.labels, decided, NEUTRAL_LABEL) * model.spec.stride * DT).tolist()


def latency(args: argparse.Namespace) -> None:
    """One JSON row per participant: the cue-to-decision latencies over the seeds (``cue_latencies_s``)."""
    for participant in args.participants.split(","):
        ms = 1000.0 * np.array([x for seed in seed_range(args.seeds) for x in cue_latencies_s(participant, seed)])
        print(json.dumps({"participant": participant, "seeds": args.seeds, "cues": len(ms),
                          "median_ms": round(float(np.median(ms))), "sd_ms": round(float(np.std(ms, ddof=1))),
                          "p10_p90_ms": [round(float(q)) for q in np.percentile(ms, [10, 90])],
                          "min_max_ms": [round(float(ms.min())), round(float(ms.max()))]}), flush=True)


NEEDLESS_M = 0.012  # the tightest tolerance the task's person keeps on xy (operator.toml's placed)
AT_B_M = TaskConfig().at_b


def hand_pushes(log) -> list[tuple[int, int]]:
    """(first, last) tick of each push of the hand until the completion: a run of ticks pushed along one direction."""
    end = len(log.t) if log.completion_time is None else int(np.searchsorted(log.t, log.completion_time))
    direction = log.intended_dir[:end]
    pushed = log.pushing[:end] & (np.linalg.norm(direction, axis=1) > 0)
    turned = np.r_[True, np.any(direction[1:] != direction[:-1], axis=1)]   # the direction differs from the tick before
    pushes = []
    for start, length in metrics.runs(pushed):   # each run of pushed ticks, cut where the direction turns
        bounds = [start, *(start + 1 + np.flatnonzero(turned[start + 1:start + length])).tolist(), start + length]
        pushes += [(a, b - 1) for a, b in zip(bounds[:-1], bounds[1:])]
    return pushes


def travel_outcome(log, first: int, until: int) -> str | None:
    """What a travel push begun at tick ``first`` did by tick ``until`` (the next push's start), against the true
    error along its axis (``pushes``' categories); None for a push that is not a step's travel."""
    step, axis = log.goals[first], log.intended_dir[first]
    if log.stages[first] != "travel" or not step.startswith(("reach cube", "carry cube")):
        return None
    k = int(step.split()[-1]) - 1
    if step.startswith("reach"):
        error = log.cube_pos[first, k] - log.hand_pos[first]
    else:   # the held cube onto the other one if that one is at B (the task's at_b), else to B
        other = log.cube_pos[first, 1 - k]
        place = other if np.linalg.norm(other[:2] - log.target_pos[:2]) <= AT_B_M else log.target_pos
        error = place - log.cube_pos[first, k]
    true, moved = float(np.dot(error[:2], axis[:2])), float(np.dot(log.hand_pos[until] - log.hand_pos[first], axis))
    if abs(true) < NEEDLESS_M:
        return "needless"
    if true < 0:
        return "wrong way"
    if abs(moved) < 0.002:
        return "unanswered"
    return "short" if moved < 0.6 * true else "long" if moved > 1.4 * true else "ok"


def pushes(args: argparse.Namespace) -> None:
    """One JSON row per cell: pushes of the hand per episode, their median length and move, and the travel
    pushes per episode by outcome (``travel_outcome``), printed as it comes."""
    for cell in args.cells.split(","):
        participant, operator = cell.split(":")
        seeds, counts, lengths, moves, outcomes = seed_range(args.seeds), [], [], [], Counter()
        for seed in seeds:
            log = run_job(EpisodeJob(operator, participant, seed, overrides=HUMAN_ON))
            runs = hand_pushes(log)
            counts.append(len(runs))
            for n, (first, last) in enumerate(runs):
                until = runs[n + 1][0] if n + 1 < len(runs) else min(last + 1, len(log.t) - 1)
                lengths.append(float(log.t[last] - log.t[first]) + float(log.t[1] - log.t[0]))
                moves.append(float(np.dot(log.hand_pos[until] - log.hand_pos[first], log.intended_dir[first])))
                outcomes[travel_outcome(log, first, until)] += 1
            print(json.dumps({"seed": seed, "time": log.completion_time, "pushes": len(runs)}), file=sys.stderr, flush=True)
        outcomes.pop(None, None)
        print(json.dumps({"cell": cell, "seeds": args.seeds, "pushes_per_episode": round(float(np.mean(counts)), 1),
                          "median_push_s": round(float(np.median(lengths)), 2),
                          "median_move_mm": round(1000 * float(np.median(moves)), 1),
                          "travel_pushes_per_episode": {k: round(v / len(seeds), 1) for k, v in sorted(outcomes.items())}}),
              flush=True)


def check(args: argparse.Namespace) -> None:
    """One JSON row per cell: the body's check (``cell_row``), printed as it comes."""
    for cell in args.cells.split(","):
        participant, operator = cell.split(":")
        print(json.dumps(cell_row(participant, operator, seed_range(args.seeds), args.recovery)), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    cal = sub.add_parser("calibrate", help="fit the Fitts slope on the joystick (dev seeds)")
    cal.add_argument("--seeds", type=int, default=20, help="dev seeds 0..N-1 (default 20)")
    cal.add_argument("--slopes", default="0.35,0.5,0.65", help="Fitts slopes tried, s/bit (default 0.35,0.5,0.65)")
    pred = sub.add_parser("predict", help="joystick and BoMI with the shipped human model")
    pred.add_argument("--participants", default="P1,P4,P5", help="BoMI participants (default P1,P4,P5)")
    pred.add_argument("--name", default="human_model", help="results file name (default human_model)")
    sens = sub.add_parser("sensitivity", help="each human parameter at 50 %% and 150 %%, joystick and P1 BoMI")
    sens.add_argument("--params", default=",".join(SENSITIVE), help="parameters varied (default: the timing, "
                      "perception and slip parameters)")
    chk = sub.add_parser("check", help="the BoMI user's body: success, time, relevant outputs, longest irrelevant run, "
                         "irrelevant decisions by context, per cell (issue 53)")
    chk.add_argument("--seeds", required=True, help="first-last, e.g. 0-9")
    chk.add_argument("--cells", default="P1:joystick,P1:bomi,P4:bomi,P5:bomi", help="participant:operator, comma list")
    chk.add_argument("--recovery", help='recovery actions, e.g. "rezero,backoff,pause" (default: none)')
    lat = sub.add_parser("latency", help="the body's cue-to-decision latency on a continuous session (issue 53.3)")
    lat.add_argument("--seeds", required=True, help="first-last, e.g. 0-9")
    lat.add_argument("--participants", default="P1,P4,P5", help="comma list (default P1,P4,P5)")
    push = sub.add_parser("pushes", help="where a BoMI episode's pushes go: per episode, and each travel push's outcome "
                          "(BoMI cells: one function at a time)")
    push.add_argument("--seeds", required=True, help="first-last, e.g. 0-9")
    push.add_argument("--cells", default="P1:bomi", help="participant:operator, comma list (default P1:bomi)")
    for p in (pred, sens):
        p.add_argument("--seeds", type=int, default=5, help="episodes per condition (default 5)")
        p.add_argument("--first-seed", type=int, default=0, help="first seed (default 0: development seeds)")
    for p in (cal, pred, sens):
        p.add_argument("--jobs", type=int, default=1, help="parallel episodes (default 1)")
    args = parser.parse_args()
    {"calibrate": calibrate, "predict": predict, "sensitivity": sensitivity, "check": check,
     "latency": latency, "pushes": pushes}[args.command](args)


if __name__ == "__main__":
    main()
