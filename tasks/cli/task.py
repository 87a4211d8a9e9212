"""`bomi run-task`, `bomi benchmark`, `bomi demo`: stacking episodes from the command line."""
from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bomi import paper
from bomi.errors import BomiError
from tasks.stacking import failures, metrics
from tasks.operators.assist import ASSIST_HELP, NONE, Assist, assist_label, assist_option, profile_assist
from tasks.cli.engine import Engine, add_engine_arguments, engine_from_args
from tasks.cli import add_command
from bomi.files import atomic_output, write_text
from tasks.cli.options import add_force, check_outputs, episode_seconds, positive_int, seed_count
from tasks.cli.options import seed as seed_option
from tasks.stacking.episode import (OPERATORS, JoystickChannel, calibrated_channel, participant_controls, profile_controls,
                           run_episode, summarize)
from tasks.participants.participant import load_participant
from tasks.operators.planner import DEFAULT_OPERATOR_FILE, NO_RECOVERY, RecoveryAction, load_operator, parse_recovery_actions
from tasks.stacking.task import TaskConfig
from tasks.operators.stick import arm_profile
from tasks.stacking.timeline import timeline_figure

# Majority vote over this many decisions on the simulated BoMI (the profiles ship with it off):
# it removes the one- and two-decision blips that would otherwise press B1/B2 by mistake.
DEFAULT_VOTE = 5
# The demo's MP4 plays this many times faster than simulated time: a long BoMI episode stays a
# short film (and quick to render).
DEMO_VIDEO_SPEEDUP = 8.0

RECOVERY_KEY = "operator.recovery.actions"  # the override --recovery sets (a grid may vary it too)
RECOVERY_HELP = (f"what the scripted user does after a while without progress (docs/task.md, Recovery): "
                 f"{NO_RECOVERY}, or a comma list of {', '.join(a.value for a in RecoveryAction)} "
                 f"(default: the operator file's [recovery] actions, shipped: {NO_RECOVERY})")


def recovery_option(text: str) -> str:
    """``--recovery`` for argparse: the actions, checked, as given."""
    try:
        parse_recovery_actions(text, "")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def with_recovery(job: "EpisodeJob", recovery: str | None) -> "EpisodeJob":
    """``job`` with the recovery actions ``recovery`` (None: as the operator file says)."""
    return job if recovery is None else replace(job, overrides=(*job.overrides, (RECOVERY_KEY, recovery)))


# The configuration files an episode reads, each of which a job may edit (``EpisodeJob.overrides``).
EDITABLE_FILES = ("profile", "participant", "operator")
JOYSTICK_ANYONE = "any"  # the participant column of a joystick row: the stick needs no body


@dataclass(frozen=True)
class EpisodeJob:
    """Everything an episode depends on.  ``overrides``: ``(file.dotted.key, value)`` pairs that
    edit the profile, participant or operator file before it is read (``("profile.post_processing.
    rejection_threshold", 0.99)``); the majority vote is ``vote_length``, never a profile override."""

    operator: str
    participant: str
    seed: int
    time_limit: float = 600.0
    operator_file: str = str(DEFAULT_OPERATOR_FILE)
    vote_length: int = DEFAULT_VOTE
    overrides: tuple[tuple[str, Any], ...] = ()
    assist: frozenset[Assist] | None = None  # None: as the profile says (BoMI), none (joystick)

    def __str__(self) -> str:
        edits = "".join(f", {key}={value!r}" for key, value in self.overrides)
        vote = f", vote {self.vote_length}" if self.operator != "joystick" else ""
        assist = f", assist {assist_label(self.assist)}" if self.assist is not None else ""
        return f"episode {self.participant} {self.operator} seed {self.seed}{vote}{assist}{edits}"

    def edits(self, file: str) -> dict[str, Any]:
        """The overrides of one of EDITABLE_FILES, keyed relative to that file."""
        prefix = file + "."
        return {key[len(prefix):]: value for key, value in self.overrides if key.startswith(prefix)}


def run_job(job: EpisodeJob, video: Path | None = None, video_speedup: float = 4.0, progress: bool = False):
    """One episode (calibration first for the BoMI); returns its log (and films it if ``video``).
    With ``progress``, a bar on stderr for each stage: the calibration, then the episode."""
    what = f"{job.participant} {job.operator} seed {job.seed}"
    params = load_participant(job.participant, job.edits("participant"))
    profile = arm_profile(params.profile, job.edits("profile"))
    assist = job_assist(job, profile)
    if job.operator == "joystick":  # on the controls the participant's profile gives (like for like)
        channel = JoystickChannel(profile_controls(profile))
    else:
        with _stage(f"{what}: calibration (the participant performs the protocol, the LDA is trained)", progress):
            channel = calibrated_channel(params, job.seed, replace(profile.post, vote_length=job.vote_length),
                                         profile)
    filming = f", filming at {video_speedup:g}x" if video is not None else ""
    with _simulated_time(f"{what}: episode{filming}", progress) as on_tick:
        return run_episode(channel, operator=job.operator, participant=job.participant, seed=job.seed,
                           operator_file=load_operator(job.operator_file, job.edits("operator")),
                           task_config=TaskConfig(time_limit=job.time_limit), video=video,
                           video_speedup=video_speedup, on_tick=on_tick, assist=assist)


def job_assist(job: EpisodeJob, profile) -> frozenset[Assist]:
    """The assistances of a job: as the run says, else as the participant's profile says (the
    joystick operator: none, unless the profile's controls have no mode button to press)."""
    if job.assist is not None:
        return job.assist
    return frozenset() if job.operator == "joystick" and profile_controls(profile).buttons else profile_assist(profile)


@contextmanager
def _stage(what: str, progress: bool) -> Iterator[None]:
    """A one-step bar: shown when the stage starts, complete (with its duration) when it ends."""
    with tqdm(total=1, desc=what, file=sys.stderr, disable=not progress, bar_format="{desc}: {elapsed}") as bar:
        yield
        bar.update(1)


@contextmanager
def _simulated_time(what: str, progress: bool) -> Iterator:
    """A bar counting simulated seconds (an episode's length is not known in advance)."""
    with tqdm(desc=what, file=sys.stderr, disable=not progress, unit="s", mininterval=0.5,
              bar_format="{desc}: {n:.0f} s simulated in {elapsed} ({rate_noinv_fmt})") as bar:
        yield (lambda t: bar.update(t - bar.n)) if progress else None  # no bar: no call a tick


def episode_record(job: EpisodeJob) -> dict:
    """The per-episode metrics of one job (what the engines run)."""
    return summarize(run_job(job))


# ------------------------------------------------------------------------------------ tables
def _mean(values: list) -> float | None:
    values = [v for v in values if v is not None]
    return statistics.fmean(values) if values else None


def _pooled(rs: list[dict], key: str) -> list:
    return [v for r in rs for v in r.get(key) or []]


# what the assistance did, per episode (0 without one)
ASSIST_KEYS = ("automatic_switches", "wrong_goal_switches", "refused_switches", "undone_switches", "grasp_helps")
# the decision metrics of a row (None for an operator without a classifier)
DECISION_KEYS = ("accuracy_all_decisions", "accuracy_excused_transitions", "excused_share", "excused_allowance_ms",
                 "relevant_share", "irrelevant_per_min", "irrelevant_longest_run_ms", "longest_error_run_ms",
                 "latency_ms_median", "latency_ms_p90", "onsets_unrecognised_share", "accuracy_vs_allowance")


def _unrecognised_share(records: list[dict]) -> float | None:
    """Pooled share of motion onsets the chain never output before the intent ended (None for
    records written before this was counted)."""
    if any("onsets" not in r for r in records):
        return None
    onsets = sum(r["onsets"] for r in records)
    return sum(r["onsets_unrecognised"] for r in records) / onsets if onsets else None


def aggregate(records: list[dict]) -> list[dict]:
    """One row per (participant, operator, layout): successes with their Wilson 95 % interval,
    completion time of the successes with a Student-t 95 % interval, and the decision metrics
    (accuracies: mean over episodes; latency and irrelevant outputs: pooled over episodes)."""
    groups: dict[tuple[str, str, str, str], list[dict]] = {}
    for r in records:  # the joystick needs no body: its rows are per layout, for anyone
        who = JOYSTICK_ANYONE if r["operator"] == "joystick" else r["participant"]
        # records written before the assistance existed had none
        # (and before the recovery existed, none)
        groups.setdefault((who, r["operator"], r["layout"], r.get("assist", NONE), r.get("recovery", NO_RECOVERY)),
                          []).append(r)
    rows = []
    for (participant, operator, layout, assist, recovery), rs in sorted(groups.items()):
        done = [r for r in rs if r["success"]]
        times = [r["completion_time"] for r in done]
        ci = metrics.mean_ci95(times)
        row = {
            "participant": participant, "operator": operator, "layout": layout, "assist": assist,
            "recovery": recovery, "episodes": len(rs),
            "seeds": [r["seed"] for r in rs], "successes": len(done),
            "success_rate": len(done) / len(rs), "success_ci95": list(metrics.success_ci95(len(done), len(rs))),
            "completion_time_mean": _mean(times),
            "completion_time_sd": statistics.stdev(times) if len(times) > 1 else None,
            "completion_time_ci95": None if ci is None else list(ci),
            "failures": [{"seed": r["seed"], "failure": r["failure"]} for r in rs if not r["success"]],
            "mode_switches": _mean([r["mode_switches"] for r in rs]),
            **{key: _mean([r.get(key, 0) for r in rs]) for key in ASSIST_KEYS},
            "unintended_displacement_mm": _mean([r["unintended_displacement_mm"] for r in rs]),
            "cube_drops": sum(r["cube_drops"] for r in rs),
            "realtime_factor": _mean([r["realtime_factor"] for r in rs]),
        }
        decided = [r for r in rs if r.get("decisions")]
        row.update(dict.fromkeys(DECISION_KEYS))  # None where no classifier decided (the joystick)
        if decided:
            latency = _pooled(decided, "latency_onsets_ms")
            decisions = sum(r["decisions"] for r in decided)
            period_s = decided[0]["excused_allowance_ms"] / 1000.0 / max(decided[0]["excused_allowance_samples"], 1)
            curves = [r["accuracy_vs_allowance"]["accuracy"] for r in decided]
            row.update({
                "accuracy_all_decisions": _mean([r["accuracy_all_decisions"] for r in decided]),
                "accuracy_excused_transitions": _mean([r["accuracy_excused_transitions"] for r in decided]),
                "excused_share": _mean([r.get("excused_share") for r in decided]),   # None in records before it
                "excused_allowance_ms": _mean([r["excused_allowance_ms"] for r in decided]),
                "relevant_share": 1.0 - sum(r["irrelevant_decisions"] for r in decided) / decisions,
                "irrelevant_per_min": metrics.per_minute(sum(r["irrelevant_runs"] for r in decided), decisions, period_s),
                "irrelevant_longest_run_ms": max(r["irrelevant_longest_run_ms"] for r in decided),
                "longest_error_run_ms": max(r["longest_error_run_ms"] for r in decided),
                "latency_ms_median": float(np.median(latency)) if latency else None,
                "latency_ms_p90": float(np.percentile(latency, 90)) if latency else None,
                "onsets_unrecognised_share": _unrecognised_share(decided),
                "accuracy_vs_allowance": {"allowance_s": decided[0]["accuracy_vs_allowance"]["allowance_s"],
                                          "accuracy": np.nanmean(np.array(curves, dtype=float), axis=0).tolist()},
            })
        rows.append(row)
    return rows


def comparison(rows: list[dict]) -> list[dict]:
    """Per participant (without recovery): our BoMI/joystick time ratio and decision figures beside the paper's.  The
    paper's real-time accuracy counts the outputs that were not irrelevant: ``relevant_share``
    is ours in that sense; the two accuracies say how often the output was the intended class."""
    paper_like = [r for r in rows if r["recovery"] == NO_RECOVERY]  # the paper's sessions: no recovery modelled
    bomis = {(r["participant"], r["assist"]): r for r in paper_like if r["operator"] == "bomi"}
    sticks = {(r["layout"], r["assist"]): r for r in paper_like if r["operator"] == "joystick"}
    out = []
    for (participant, assist), bomi in sorted(bomis.items()):
        joy = sticks.get((bomi["layout"], assist))  # with the same assistance
        ratio = None
        if bomi and joy and bomi["completion_time_mean"] and joy["completion_time_mean"]:
            ratio = bomi["completion_time_mean"] / joy["completion_time_mean"]
        out.append({"participant": participant, "layout": bomi["layout"], "assist": assist, "time_ratio": ratio,
                    "paper_time_ratio": paper.TASK["bomi_time_s"] / paper.TASK["joystick_time_s"],
                    **{key: bomi.get(key) for key in
                       ("relevant_share", "accuracy_all_decisions", "accuracy_excused_transitions",
                        "irrelevant_longest_run_ms", "longest_error_run_ms")},
                    "paper_realtime_accuracy": paper.TASK["realtime_accuracy"],
                    "paper_longest_error_run_ms": paper.TASK["longest_error_run_ms"]})
    return out


def _fmt(value, spec: str = ".1f") -> str:
    return "-" if value is None else format(value, spec)


def _pct(value) -> str:
    return "-" if value is None else f"{100 * value:.1f} %"


def _interval(ci, spec: str = ".1f", scale: float = 1.0) -> str:
    return "" if ci is None else f" [{scale * ci[0]:{spec}}, {scale * ci[1]:{spec}}]"


# The columns of a row of ``aggregate`` in the tables (``bomi benchmark``, ``bomi sweep``); 95 % intervals
# in brackets: Wilson for successes, Student-t for the mean completion time
ROW_COLUMNS = ("layout", "successes [95 % CI]", "completion time (s) [95 % CI]", "accuracy, all decisions",
               "accuracy, transitions excused (excused share)", "relevant outputs", "irrelevant / min (longest, ms)",
               "latency from onset median / p90 (ms) (onsets never recognised)", "assist", "user mode switches",
               "automatic (wrong-goal) switches", "drops", "x real time")


# An interval over fewer episodes says little: none is printed (the JSON keeps it).
MIN_EPISODES_FOR_INTERVAL = 5


def successes_text(r: dict) -> str:
    interval = _interval(r["success_ci95"], ".0f", 100) if r["episodes"] >= MIN_EPISODES_FOR_INTERVAL else ""
    return f"{r['successes']}/{r['episodes']}{interval and interval + ' %'}"


def completion_text(r: dict) -> str:
    ci = r["completion_time_ci95"]
    # a time is never negative: a Student-t bound below 0 (few, spread successes) is shown as 0
    interval = _interval([max(0.0, ci[0]), ci[1]]) if ci and r["successes"] >= MIN_EPISODES_FOR_INTERVAL else ""
    return f"{_fmt(r['completion_time_mean'])}{interval}"


# The terminal's table: what fits in 100 columns (the full table, ROW_COLUMNS, goes to the files)
TERMINAL_COLUMNS = ("successes", "time (s)", "acc. all", "acc. exc.", "err. run ms")


def terminal_cells(r: dict) -> list[str]:
    return [successes_text(r), completion_text(r), _pct(r.get("accuracy_all_decisions")),
            _pct(r.get("accuracy_excused_transitions")), _fmt(r.get("longest_error_run_ms"), ".0f")]


def aligned_table(header: list[str], rows: list[list[str]]) -> str:
    """A plain table for the terminal: columns as wide as their widest cell, two spaces apart."""
    widths = [max(len(str(cell)) for cell in column) for column in zip(header, *rows)]
    return "\n".join("  ".join(str(cell).ljust(width) for cell, width in zip(row, widths)).rstrip()
                     for row in [header, ["-" * w for w in widths], *rows])


def terminal_table(rows: list[dict]) -> str:
    """The benchmark rows within 100 columns (acc. all: accuracy over every decision; acc. exc.: with
    the transitions excused; err. run ms: the longest run of misclassified outputs)."""
    extra = [key for key, off in (("assist", NONE), ("recovery", NO_RECOVERY)) if any(r[key] != off for r in rows)]
    return aligned_table(["participant", "operator", *extra, *TERMINAL_COLUMNS],
                         [[r["participant"], r["operator"], *(r[key] for key in extra), *terminal_cells(r)]
                          for r in rows])


def terminal_comparison(rows: list[dict]) -> str:
    """The comparison with the paper, like for like, within 100 columns."""
    return aligned_table(
        ["participant", "assist", "BoMI/joy time", "paper", "acc. all", "acc. exc.", "paper",
         "err. run ms", "paper"],
        [[c["participant"], c["assist"], _fmt(c["time_ratio"], ".2f"), f"{c['paper_time_ratio']:.2f}",
          _pct(c["accuracy_all_decisions"]), _pct(c["accuracy_excused_transitions"]),
          _pct(c["paper_realtime_accuracy"]), _fmt(c["longest_error_run_ms"], ".0f"),
          f"{c['paper_longest_error_run_ms']:.0f}"] for c in comparison(rows)])


# The mechanism table's short column names (within 100 columns), in ``failures.Mechanism``'s order
MECHANISM_COLUMNS = {failures.Mechanism.CUBE_LOST: "cube lost", failures.Mechanism.ARM_AT_LIMIT: "at limit",
                     failures.Mechanism.CLASSIFIER_STUCK: "clf stuck", failures.Mechanism.MODE_SWITCH_STORM: "storm",
                     failures.Mechanism.PLANNER_STUCK: "planner", failures.Mechanism.MISREAD_MOTION: "misread"}


def terminal_mechanisms(records: list[dict]) -> str:
    """Why episodes failed or were slow (more than ``failures.SLOW_FACTOR`` x their median time): per
    participant and operator (and a sweep's settings), how many each mechanism explains."""
    rows = failures.mechanism_rows(records)
    settings = any(r["settings"] for r in rows)
    recovery = any(r["recovery"] != NO_RECOVERY for r in rows)
    unrecorded = any(r["mechanisms"].get(failures.NOT_RECORDED) for r in rows)
    header = ["participant", "operator", *(["settings"] if settings else []), *(["recovery"] if recovery else []),
              "failed", "slow", *MECHANISM_COLUMNS.values(), *([failures.NOT_RECORDED] if unrecorded else [])]
    cells = [[r["participant"], r["operator"], *([json.dumps(r["settings"])] if settings else []),
              *([r["recovery"]] if recovery else []),
              f"{r['failed']}/{r['episodes']}", f"{r['slow']}/{r['episodes']}",
              *(str(len(r["mechanisms"][m.value])) for m in MECHANISM_COLUMNS),
              *([str(len(r["mechanisms"].get(failures.NOT_RECORDED, [])))] if unrecorded else [])] for r in rows]
    return (f"why episodes failed or took over {failures.SLOW_FACTOR:g}x their median (docs/task.md):\n"
            + aligned_table(header, cells))


def row_cells(r: dict) -> list[str]:
    """A row of ``aggregate`` as the texts of ROW_COLUMNS."""
    excused = "-" if r.get("accuracy_excused_transitions") is None else (
        f"{_pct(r['accuracy_excused_transitions'])} ({_pct(r.get('excused_share'))} excused, "
        f"{r['excused_allowance_ms']:.0f} ms excused)")
    wild = "-" if r.get("irrelevant_per_min") is None else (
        f"{r['irrelevant_per_min']:.2f} ({r['irrelevant_longest_run_ms']:.0f})")
    latency = "-" if r.get("latency_ms_median") is None else f"{r['latency_ms_median']:.0f} / {r['latency_ms_p90']:.0f}"
    if r.get("onsets_unrecognised_share") is not None:
        latency += f" ({_pct(r['onsets_unrecognised_share'])} never)"
    return [r["layout"], successes_text(r), completion_text(r),
            _pct(r.get("accuracy_all_decisions")), excused, _pct(r.get("relevant_share")), wild, latency,
            r["assist"], _fmt(r["mode_switches"]), f"{_fmt(r['automatic_switches'])} ({_fmt(r['wrong_goal_switches'])})",
            str(r["cube_drops"]), _fmt(r["realtime_factor"])]


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    return "\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
                     + ["| " + " | ".join(row) + " |" for row in rows])


def markdown_tables(rows: list[dict]) -> str:
    """The benchmark table and the comparison with the paper."""
    lines = [markdown_table(["participant", "operator", *ROW_COLUMNS],
                            [[r["participant"], r["operator"], *row_cells(r)] for r in rows])]
    lines += ["", "| participant | layout | assist | BoMI / joystick time (same layout and assist) | paper "
              "| relevant outputs | accuracy, all decisions | accuracy, transitions excused | paper real-time accuracy "
              "| longest misclassified run (ms) | paper longest error run (ms) | longest irrelevant run (ms) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in comparison(rows):
        lines.append(f"| {c['participant']} | {c['layout']} | {c['assist']} | {_fmt(c['time_ratio'], '.2f')} "
                     f"| {c['paper_time_ratio']:.2f} "
                     f"| {_pct(c['relevant_share'])} | {_pct(c['accuracy_all_decisions'])} "
                     f"| {_pct(c['accuracy_excused_transitions'])} | {_pct(c['paper_realtime_accuracy'])} "
                     f"| {_fmt(c['longest_error_run_ms'], '.0f')} | {c['paper_longest_error_run_ms']:.0f} "
                     f"| {_fmt(c['irrelevant_longest_run_ms'], '.0f')} |")
    return "\n".join(lines)


def run_many(jobs: list[EpisodeJob], engine: Engine) -> list[dict]:
    """Episodes on ``engine``, with a progress bar; results in job order."""
    results = dict(tqdm(engine.run(episode_record, jobs), total=len(jobs), desc="episodes", unit="ep"))
    return [results[i] for i in range(len(jobs))]


def benchmark_jobs(participants: list[str], operators: list[str], seeds: int, time_limit: float,
                   operator_file: str, vote_length: int = DEFAULT_VOTE, first_seed: int = 0,
                   assist: frozenset[Assist] | None = None) -> list[EpisodeJob]:
    """Every (participant, operator, seed) for ``seeds`` seeds from ``first_seed``.  The joystick
    needs no body: it is run once per distinct set of controls (layout and buttons) among the
    participants' profiles, so each BoMI row has a joystick row with the same controls and no
    joystick row is repeated under several names."""
    seen: set[str] = set()
    jobs = []
    for p in participants:
        for op in operators:
            if op == "joystick":
                label = participant_controls(p).label
                if label in seen:
                    continue
                seen.add(label)
            jobs += [EpisodeJob(op, p, s, time_limit, operator_file, vote_length, assist=assist)
                     for s in range(first_seed, first_seed + seeds)]
    return jobs


def write_json(path: Path, payload, overwrite: bool = False) -> None:
    write_text(path, json.dumps(payload, indent=2) + "\n", overwrite=overwrite)


# ------------------------------------------------------------------------------------ commands
def _names(text: str, allowed: tuple[str, ...] | None, what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise BomiError(f"--{what}: empty list")
    if allowed is not None:
        bad = [n for n in names if n not in allowed]
        if bad:
            raise BomiError(f"--{what}: unknown {', '.join(bad)} (expected {', '.join(allowed)})")
    return names


def cmd_run_task(args: argparse.Namespace) -> int:
    outputs = check_outputs({"--video": (args.video, (".mp4",)), "--plot": (args.plot, (".png",)),
                             "--json": (args.json, (".json",))}, force=args.force)
    load_operator(args.operator_file)  # a bad file fails before any simulation
    load_participant(args.participant)  # for the joystick too: a typo is not silently ignored
    job = with_recovery(EpisodeJob(args.operator, args.participant, args.seed, args.time_limit,
                                   str(args.operator_file), args.vote, assist=args.assist), args.recovery)
    job_assist(job, arm_profile(load_participant(job.participant).profile))  # a bad profile fails before simulating
    participant_controls(job.participant)  # so does one without the task's controls (a twin's derived profile)
    if outputs["--video"]:
        with atomic_output(outputs["--video"], overwrite=args.force) as video:
            log = run_job(job, video=video, progress=True)
    else:
        log = run_job(job, progress=True)
    summary = summarize(log)
    print(terminal_table(aggregate([summary])))
    if outputs["--plot"]:
        with atomic_output(outputs["--plot"], overwrite=args.force) as plot:
            timeline_figure([log], plot)
    if outputs["--json"]:
        write_json(outputs["--json"], summary, overwrite=args.force)
    _print_written({outputs["--video"]: "the episode filmed (4x speed)", outputs["--plot"]: "timeline figure",
                    outputs["--json"]: "metrics of the episode"})
    return 0 if log.success else 1


def _print_written(files: dict[Path | None, str]) -> None:
    """The files a command wrote, each with what it holds (None: not asked for)."""
    written = {path: what for path, what in files.items() if path is not None}
    if written:
        width = max(len(str(path)) for path in written)
        print("wrote:\n" + "\n".join(f"  {str(path):<{width}}  {what}" for path, what in written.items()))


def cmd_benchmark(args: argparse.Namespace) -> int:
    outputs = check_outputs({"--json": (args.json, (".json",))}, force=args.force)
    load_operator(args.operator_file)
    participants = _names(args.participants, None, "participants")
    for name in participants:  # every name checked here, not inside a worker after others finished
        load_participant(name)
    jobs = benchmark_jobs(participants, _names(args.operators, OPERATORS, "operators"),
                          args.seeds, args.time_limit, str(args.operator_file), args.vote, args.first_seed,
                          args.assist)
    jobs = [with_recovery(job, recovery) for recovery in args.recovery or [None] for job in jobs]
    for job in {(j.participant, j.operator): j for j in jobs}.values():  # a bad profile fails before simulating
        job_assist(job, arm_profile(load_participant(job.participant).profile))
        participant_controls(job.participant)
    records = run_many(jobs, engine_from_args(args))
    rows = aggregate(records)
    print(terminal_table(rows))
    if comparison(rows):
        print("\n" + terminal_comparison(rows))
    print("\n" + terminal_mechanisms(records))
    if not outputs["--json"]:
        print("(every column, the episodes and the comparison in full: --json FILE)")
    if outputs["--json"]:
        write_json(outputs["--json"], {"paper": paper.TASK, "rows": rows, "comparison": comparison(rows),
                                       "mechanisms": failures.mechanism_rows(records), "episodes": records},
                   overwrite=args.force)
    return 0


DEMO_FILES = ("timeline.png", "bomi_episode.mp4", "demo.json")


DEMO_OUT = Path("demo_out")  # demo's own directory when --out names none: its files are replaced on each run


def cmd_demo(args: argparse.Namespace) -> int:
    out = Path(args.out or DEMO_OUT)
    replace = args.force or args.out is None
    if out.exists() and not out.is_dir():
        raise BomiError(f"{out}: --out must be a directory, this is a file")
    if not out.parent.is_dir():
        raise BomiError(f"{out}: directory {out.parent} does not exist")
    out.mkdir(exist_ok=True)
    figure, video, record = check_outputs({name: (out / name, ()) for name in DEMO_FILES}, force=args.force,
                                          defaults=DEMO_FILES if args.out is None else ()).values()
    participant_controls(args.participant)  # a bad participant or profile fails before simulating
    joystick = run_job(EpisodeJob("joystick", args.participant, args.seed, args.time_limit, assist=args.assist),
                       progress=True)
    with atomic_output(video, overwrite=replace) as temp:
        bomi = run_job(EpisodeJob("bomi", args.participant, args.seed, args.time_limit, assist=args.assist), video=temp,
                       video_speedup=DEMO_VIDEO_SPEEDUP, progress=True)
    summaries = [summarize(joystick), summarize(bomi)]
    with _stage("timeline figure", progress=True), atomic_output(figure, overwrite=replace) as temp:
        timeline_figure([joystick, bomi], temp)
    write_json(record, {"paper": paper.TASK, "episodes": summaries}, overwrite=replace)
    print(terminal_table(aggregate(summaries)))
    print(f"\nOne seed ({args.seed}), one episode per operator: a single draw of the cube placement and of the "
          f"virtual participant's body and noise. The README's figures are means over 20 seeds "
          f"(`bomi benchmark`).")
    _print_written({figure: "timeline: the hand relative to the target, the BoMI's decisions, amplitude and nu",
                    video: f"the BoMI episode filmed at {DEMO_VIDEO_SPEEDUP:g}x speed",
                    record: "metrics of both episodes (JSON)"})
    return 0


def register(subparsers) -> None:
    run = add_command(subparsers, "run-task")
    run.add_argument("--operator", choices=OPERATORS, required=True,
                     help="who drives the arm: the scripted user on a joystick, or a virtual participant "
                          "through the BoMI (calibrated first)")
    run.add_argument("--participant", default="P1",
                     help="virtual participant: P1, P4, P5 or a TOML file (default %(default)s)")
    run.add_argument("--seed", type=seed_option, default=0,
                     help="task seed: cube placement, the participant's body and noise (default %(default)s)")
    _episode_options(run)
    run.add_argument("--recovery", type=recovery_option, help=RECOVERY_HELP)
    run.add_argument("--video", type=Path, help="also film the episode to this MP4 (4x speed)")
    run.add_argument("--plot", type=Path, help="also write the timeline figure (PNG) here")
    run.add_argument("--json", type=Path, help="also write the episode's metrics (JSON) here")
    add_force(run)
    run.set_defaults(func=cmd_run_task)

    bench = add_command(subparsers, "benchmark")
    bench.add_argument("--participants", default="P1",
                       help="comma-separated virtual participants: P1, P4, P5 or TOML files (a twin from "
                            "`bomi twin`), e.g. P1,P4,P5 (default %(default)s)")
    bench.add_argument("--operators", default="joystick,bomi",
                       help=f"comma-separated operators out of {','.join(OPERATORS)} (default %(default)s)")
    bench.add_argument("--seeds", type=seed_count, default=20, help="how many seeds per participant and operator "
                                                             "(default %(default)s)")
    bench.add_argument("--first-seed", type=seed_option, default=0, help="the first seed (default %(default)s)")
    add_engine_arguments(bench)
    _episode_options(bench)
    bench.add_argument("--recovery", type=recovery_option, action="append",
                       help=RECOVERY_HELP + "; given more than once, the episodes are run under each, "
                            "e.g. --recovery none --recovery rezero,backoff,pause")
    bench.add_argument("--json", type=Path, help="also write the table and every episode's metrics (JSON) here")
    add_force(bench)
    bench.set_defaults(func=cmd_benchmark)

    demo = add_command(subparsers, "demo")
    demo.add_argument("--seed", type=seed_option, default=0, help="task seed of both episodes (default %(default)s)")
    demo.add_argument("--participant", default="P1",
                      help="virtual participant: P1, P4, P5 or a TOML file (a twin from `bomi twin`; "
                           "default %(default)s)")
    demo.add_argument("--time-limit", type=episode_seconds, default=600.0,
                      help="seconds of simulated time per episode (default %(default)s)")
    demo.add_argument("--out", type=Path,
                      help=f"directory for timeline.png, bomi_episode.mp4 and demo.json (default {DEMO_OUT}/, whose "
                           f"files are replaced on each run; in a directory you name, only with --force)")
    demo.add_argument("--assist", type=assist_option, help=ASSIST_HELP)
    add_force(demo)
    demo.set_defaults(func=cmd_demo)


def _episode_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--time-limit", type=episode_seconds, default=600.0,
                        help="seconds of simulated time before an episode fails (default %(default)s)")
    parser.add_argument("--operator-file", type=Path, default=DEFAULT_OPERATOR_FILE,
                        help="the scripted user's settings (TOML; default: the shipped tasks/operators/operator.toml)")
    parser.add_argument("--assist", type=assist_option, help=ASSIST_HELP)
    parser.add_argument("--vote", type=positive_int, default=DEFAULT_VOTE,
                        help="BoMI: majority vote over this many decisions (default %(default)s)")
