"""The rows of ``summary.aggregate`` as text: the full markdown tables (files) and the
narrower aligned tables of the terminal."""
from __future__ import annotations

import json

from tasks.experiments.summary import comparison, shown_name
from tasks.operators.assist import NONE
from tasks.stacking.vocabulary import NO_RECOVERY
from tasks.stacking import failures


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
                         [[shown_name(r["participant"]), r["operator"], *(r[key] for key in extra), *terminal_cells(r)]
                          for r in rows])


def terminal_comparison(rows: list[dict]) -> str:
    """The comparison with the paper within 100 columns, like beside like: each paper figure right of
    ours in the same sense (the paper's real-time accuracy is the share of relevant outputs,
    ``metrics.irrelevant``, its longest error run the longest run of irrelevant outputs: 18 outputs);
    our accuracies, which the paper does not report, after them."""
    return aligned_table(
        ["participant", "assist", "BoMI/joy time", "paper", "relevant", "paper", "irr. run ms", "paper",
         "acc. all", "acc. exc."],
        [[shown_name(c["participant"]), c["assist"], _fmt(c["time_ratio"], ".2f"), f"{c['paper_time_ratio']:.2f}",
          _pct(c["relevant_share"]), _pct(c["paper_realtime_accuracy"]), _fmt(c["irrelevant_longest_run_ms"], ".0f"),
          f"{c['paper_longest_irrelevant_run_ms']:.0f}", _pct(c["accuracy_all_decisions"]),
          _pct(c["accuracy_excused_transitions"])] for c in comparison(rows)])


# The mechanism table's short column names (within 100 columns), in ``failures.Mechanism``'s order
MECHANISM_COLUMNS = {failures.Mechanism.CUBE_LOST: "cube lost", failures.Mechanism.ARM_AT_LIMIT: "at limit",
                     failures.Mechanism.CLASSIFIER_STUCK: "clf stuck", failures.Mechanism.MODE_SWITCH_STORM: "storm",
                     failures.Mechanism.PLANNER_STUCK: "planner", failures.Mechanism.MISREAD_MOTION: "misread"}


# Settings a record keeps that the failure table shows elsewhere (its own columns) or pools over (the seed)
POOLED_SETTINGS = ("participant", "operator", "seed")


def differing_settings(records: list[dict]) -> list[dict]:
    """The records with only the settings in which they differ (a sweep's swept ones), by their short
    names (``profile.vote_length`` -> ``vote_length``): the seed pooled, participant and operator left
    to their columns."""
    keys = {k for r in records for k in r.get("settings", {})} - set(POOLED_SETTINGS)
    differ = sorted(k for k in keys if len({json.dumps(r.get("settings", {}).get(k)) for r in records}) > 1)
    return [r | {"settings": {k.rsplit(".", 1)[-1]: r["settings"].get(k) for k in differ}} if "settings" in r else r
            for r in records]


def settings_cell(settings: dict) -> str:
    """A row's differing settings as ``name=value`` pairs."""
    return " ".join(f"{k}={json.dumps(v)}" for k, v in settings.items()) or "-"


def terminal_mechanisms(records: list[dict]) -> str:
    """Why episodes failed or were slow (more than ``failures.SLOW_FACTOR`` x their median time): per
    participant and operator (and a sweep's settings that differ: ``differing_settings``), how many each
    mechanism explains."""
    rows = failures.mechanism_rows(differing_settings(records))
    settings = any(r["settings"] for r in rows)
    recovery = any(r["recovery"] != NO_RECOVERY for r in rows)
    unrecorded = any(r["mechanisms"].get(failures.NOT_RECORDED) for r in rows)
    header = ["participant", "operator", *(["settings"] if settings else []), *(["recovery"] if recovery else []),
              "failed", "slow", *MECHANISM_COLUMNS.values(), *([failures.NOT_RECORDED] if unrecorded else [])]
    cells = [[shown_name(r["participant"]), r["operator"], *([settings_cell(r["settings"])] if settings else []),
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
    return "\n".join([markdown_table(["participant", "operator", *ROW_COLUMNS],
                                     [[shown_name(r["participant"]), r["operator"], *row_cells(r)] for r in rows]), "",
                      markdown_comparison(rows)])


def markdown_comparison(rows: list[dict]) -> str:
    """The comparison with the paper, every column, like beside like (``terminal_comparison``)."""
    lines = ["| participant | layout | assist | BoMI / joystick time (same layout and assist) | paper "
              "| relevant outputs | paper real-time accuracy (relevant outputs) | longest irrelevant run (ms) "
              "| paper longest run of irrelevant outputs (ms) | accuracy, all decisions | accuracy, transitions excused "
              "| longest misclassified run (ms) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in comparison(rows):
        lines.append(f"| {shown_name(c['participant'])} | {c['layout']} | {c['assist']} | {_fmt(c['time_ratio'], '.2f')} "
                     f"| {c['paper_time_ratio']:.2f} | {_pct(c['relevant_share'])} "
                     f"| {_pct(c['paper_realtime_accuracy'])} | {_fmt(c['irrelevant_longest_run_ms'], '.0f')} "
                     f"| {c['paper_longest_irrelevant_run_ms']:.0f} | {_pct(c['accuracy_all_decisions'])} "
                     f"| {_pct(c['accuracy_excused_transitions'])} | {_fmt(c['longest_error_run_ms'], '.0f')} |")
    return "\n".join(lines)
