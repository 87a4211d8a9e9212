"""An episode's record (``EpisodeLog``) as the per-episode metrics a benchmark stores."""
from __future__ import annotations

import numpy as np

from tasks.stacking import failures, metrics
from tasks.stacking.record import EpisodeLog

# allowances (s) at which the excused accuracy is also given: its curve shows what excusing buys
ALLOWANCE_CURVE_S = tuple(round(0.1 * k, 1) for k in range(16))
WRONG_GOAL_WINDOW_S = 1.0  # an automatic switch the user's own press undoes this soon chose the wrong mode


def summarize(log: EpisodeLog) -> dict:
    """The per-episode metrics as a JSON-ready dict."""
    sim_time = float(log.t[-1]) if len(log.t) else 0.0
    out = {
        "operator": log.operator,
        "participant": log.participant,
        "seed": log.seed,
        "layout": log.controls,
        "success": bool(log.success),
        "completion_time": log.completion_time,
        "failure": log.failure,
        "sim_time": sim_time,
        "wall_time": log.wall_time,
        "cpu_time": log.cpu_time,
        "realtime_factor": sim_time / log.wall_time if log.wall_time > 0 else None,
        "realtime_factor_cpu": sim_time / log.cpu_time if log.cpu_time > 0 else None,
        "assist": log.assist,
        "mode_switches": metrics.user_mode_switches(log.mode, [s.tick for s in log.automatic]),
        "automatic_switches": len(log.automatic),
        "wrong_goal_switches": metrics.wrong_goal_switches(log.t, log.mode, [s.tick for s in log.automatic],
                                                           WRONG_GOAL_WINDOW_S),
        "refused_switches": sum(s.refused for s in log.automatic),
        "undone_switches": sum(s.undone for s in log.automatic),
        "grasp_helps": log.grasp_helps,
        "button_presses": log.presses,
        "unintended_displacement_mm": metrics.unintended_displacement_mm(log.hand_pos, log.intended_dir),
        "cube_drops": metrics.cube_drops(log.cube_pos[:, :, 2], log.touching),
        "stuck": failures.summary(log),  # the longest span without progress and its mechanism
        "recovery": log.recovery,
        "recoveries": [{"action": e.action.value, "start_s": e.start_s, "end_s": e.end_s, "obeyed": e.obeyed}
                       for e in log.recoveries],
    }
    d = log.decisions
    if d is None:
        return out
    errors = metrics.misclassified(d.intended, d.decided, log.allowance, log.neutral)
    wild = metrics.irrelevant(d.intended, d.decided, log.neutral)
    onsets = metrics.onset_latencies(d.intended, d.decided, log.neutral)
    latency_ms = metrics.recognised(onsets) * 1000.0 * log.sample_period
    curve = np.round(np.array(ALLOWANCE_CURVE_S) / log.sample_period).astype(int)
    out.update({
        "decisions": int(len(d.t)),
        "decisions_intended_active": int(np.sum(d.intended != log.neutral)),
        "decisions_emitted_active": int(np.sum(d.decided != log.neutral)),
        "accuracy_all_decisions": metrics.accuracy_all_decisions(d.intended, d.decided),
        "accuracy_excused_transitions": metrics.accuracy_excused_transitions(d.intended, d.decided, log.allowance,
                                                                             log.neutral),
        "excused_share": metrics.excused_share(d.intended, d.decided, log.allowance, log.neutral),
        "excused_allowance_samples": log.allowance,
        "excused_allowance_ms": 1000.0 * log.allowance * log.sample_period,
        "accuracy_vs_allowance": {"allowance_s": list(ALLOWANCE_CURVE_S),
                                  "accuracy": metrics.accuracy_vs_allowance(d.intended, d.decided, curve).tolist()},
        "misclassified": int(errors.sum()),
        "longest_error_run_ms": metrics.longest_error_run_ms(errors, log.sample_period),
        **{f"errors_{k}": v for k, v in metrics.error_destinations(d.decided, errors, log.neutral).items()},
        "irrelevant_decisions": int(wild.sum()),
        "irrelevant_runs": len(metrics.runs(wild)),
        "irrelevant_per_min": metrics.per_minute(len(metrics.runs(wild)), len(d.t), log.sample_period),
        "irrelevant_longest_run_ms": metrics.longest_error_run_ms(wild, log.sample_period),
        "latency_onsets_ms": latency_ms.tolist(),
        "onsets": len(onsets),
        "onsets_unrecognised": sum(n is None for n in onsets),  # the intent ended before the chain output it
        "latency_ms_median": float(np.median(latency_ms)) if latency_ms.size else None,
        "latency_ms_p90": float(np.percentile(latency_ms, 90)) if latency_ms.size else None,
        "latency_ms_max": float(latency_ms.max()) if latency_ms.size else None,
    })
    return out
