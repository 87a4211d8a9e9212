"""Episode records pooled into rows: successes, times and decision metrics with their intervals,
and our figures beside the paper's."""
from __future__ import annotations

import json
import statistics
from pathlib import Path

import numpy as np

from bomi import paper
from bomi.files import write_text
from tasks.experiments.jobs import JOYSTICK_ANYONE
from tasks.operators.assist import NONE
from tasks.stacking.vocabulary import NO_RECOVERY
from tasks.stacking import failures, metrics
from tasks.statistics import mean_interval, wilson_interval


def shown_name(reference: str) -> str:
    """A participant (or any configuration file) as tables and figures show it: a TOML file by its file
    name (a sweep resolves the grid's files to absolute paths), a shipped name as it is."""
    return Path(reference).name if Path(reference).suffix.lower() == ".toml" else reference


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
        ci = mean_interval(times)
        row = {
            "participant": participant, "operator": operator, "layout": layout, "assist": assist,
            "recovery": recovery, "episodes": len(rs),
            "seeds": [r["seed"] for r in rs], "successes": len(done),
            "success_rate": len(done) / len(rs), "success_ci95": list(wilson_interval(len(done), len(rs))),
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
                    "paper_longest_irrelevant_run_ms": paper.TASK["longest_irrelevant_run_ms"]})
    return out




def benchmark_payload(records: list[dict]) -> dict:
    """What `bomi benchmark --json` writes: the paper's figures, the rows, the comparison, the
    failure mechanisms and every episode's record."""
    rows = aggregate(records)
    return {"paper": paper.TASK, "rows": rows, "comparison": comparison(rows),
            "mechanisms": failures.mechanism_rows(records), "episodes": records}


def write_json(path: Path, payload, overwrite: bool = False) -> None:
    write_text(path, json.dumps(payload, indent=2) + "\n", overwrite=overwrite)


