"""`bomi sweep GRID.toml --out DIR`: every combination of the settings a grid file lists, over seeds.

A grid (TOML; benchmarks/grids/ has one):

    participants = ["P4"]                    # shipped names or participant files (a twin from `bomi twin`),
                                             # a relative file relative to the grid file
    operators = ["bomi"]                     # joystick and/or bomi
    seeds = {first = 0, count = 20}          # or a list: seeds = [0, 1, 2]

    [vary]                                   # each a list of values; every combination is a cell
    vote_length = [1, 5, 9]                  # the BoMI's majority vote (the commands' --vote)
    time_limit = [600.0]                     # s of simulated time
    profile.post_processing.rejection_threshold = [0.9, 0.99]   # any key of the participant's profile,
    participant.reaction_s = [0.5]           # of the participant file,
    operator.timing.reaction_time = [0.3]    # or of the scripted user's operator.toml

    [figure]                                 # optional
    metric = "completion_time_mean"          # a column of the summary rows
    setting = "vote_length"                  # one of [vary] (default: the first)

Each (participant, operator, combination) is a cell of ``len(seeds)`` episodes.  The joystick
channel reads no profile, participant or vote setting: its episodes drop them, so its cells
differ only in what it reads (and are not run again for every BoMI setting).

Every finished episode is appended at once to DIR/episodes.jsonl as one JSON line: its ``key`` (a
hash of its settings), its ``settings`` and its metrics.  A sweep run again (after an interruption,
or with more seeds or values) skips every episode whose key is already there.  At the end:
DIR/summary.md and .json (one row per cell, the columns and aggregation of ``bomi benchmark``),
DIR/completion_time.png and DIR/<metric>_vs_<setting>.png.
"""
from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from bomi.config_files import check_table
from bomi.errors import BomiError
from tasks.cli import add_command
from tasks.cli.engine import Engine, add_engine_arguments, engine_from_args
from tasks.cli.figures import completion_time_figure, metric_figure
from tasks.cli.task import (DEFAULT_VOTE, EDITABLE_FILES, ROW_COLUMNS, EpisodeJob, aggregate, episode_record,
                            markdown_table, row_cells, write_json)
from tasks.episode import OPERATORS, profile_controls
from tasks.participants.participant import load_participant
from tasks.planner import load_operator
from tasks.stick import arm_profile

RESULTS_FILE = "episodes.jsonl"
# EpisodeJob fields a grid may vary, beside the EDITABLE_FILES' keys
JOB_SETTINGS = {"time_limit": (int, float), "vote_length": int}
# what the joystick channel never reads
NOT_READ_BY_JOYSTICK = ("vote_length", "profile.", "participant.")
# summary-row columns the figure may plot (tests/test_sweep.py checks they are aggregate's)
FIGURE_METRICS = ("completion_time_mean", "successes", "success_rate", "accuracy_all_decisions",
                  "accuracy_excused_transitions", "scored_share", "relevant_share", "irrelevant_per_min",
                  "longest_error_run_ms", "mode_switches", "unintended_displacement_mm", "latency_ms_median",
                  "cube_drops")
_TOP_KEYS = {"participants", "operators", "seeds", "vary", "figure"}


@dataclass(frozen=True)
class Grid:
    participants: tuple[str, ...]
    operators: tuple[str, ...]
    seeds: tuple[int, ...]
    vary: dict[str, tuple]  # setting -> its values, in the file's order
    metric: str
    setting: str | None
    source: str


@dataclass(frozen=True)
class Cell:
    participant: str
    operator: str
    settings: tuple[tuple[str, Any], ...]  # the swept settings this cell's episodes read

    def job(self, seed: int) -> EpisodeJob:
        values = dict(self.settings)
        return EpisodeJob(self.operator, self.participant, seed, float(values.get("time_limit", 600.0)),
                          "operator", int(values.get("vote_length", DEFAULT_VOTE)),
                          tuple((k, v) for k, v in self.settings if k not in JOB_SETTINGS))

    @property
    def label(self) -> str:
        return " ".join([self.participant, self.operator, *(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in self.settings)])


# ------------------------------------------------------------------------------------ the grid
def load_grid(path: Path) -> Grid:
    """Read and check a grid file; every fault is a one-line BomiError naming the file."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BomiError(f"{path}: no such grid file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise BomiError(f"{path}: not valid TOML ({exc})") from None
    except OSError as exc:
        raise BomiError(f"{path}: cannot be read ({exc.strerror})") from None
    try:
        grid = _parse_grid(data, str(path))
    except ValueError as exc:
        raise BomiError(f"{path}: {exc}") from None
    files = tuple(str(Path(path).parent / name) if Path(name).suffix.lower() == ".toml" and not Path(name).is_absolute()
                  else name for name in grid.participants)
    return replace(grid, participants=files)


def _names(data: dict, key: str) -> tuple[str, ...]:
    names = data.get(key)
    if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names):
        raise ValueError(f"'{key}' must be a non-empty list of names")
    if len(set(names)) != len(names):
        raise ValueError(f"'{key}' lists a name twice")
    return tuple(names)


def _seeds(value: Any) -> tuple[int, ...]:
    if isinstance(value, dict):
        if set(value) != {"first", "count"} or not all(isinstance(value[k], int) and not isinstance(value[k], bool)
                                                       for k in value):
            raise ValueError("'seeds' as a table needs integers 'first' and 'count' (and nothing else)")
        seeds = tuple(range(value["first"], value["first"] + value["count"]))
    elif isinstance(value, list) and all(isinstance(s, int) and not isinstance(s, bool) for s in value):
        seeds = tuple(value)
    else:
        raise ValueError("'seeds' must be a list of integers or {first = N, count = K}")
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise ValueError("'seeds' must be at least one seed, none negative, none twice")
    return seeds


def _flatten(table: dict, prefix: str = "") -> dict[str, Any]:
    """[vary]'s nested tables as dotted names (TOML's a.b.c = [...] is a table a with a table b ...)."""
    flat: dict[str, Any] = {}
    for key, value in table.items():
        name = prefix + key
        flat.update(_flatten(value, name + ".") if isinstance(value, dict) else {name: value})
    return flat


def _check_setting(name: str, values: Any) -> tuple:
    file = name.split(".", 1)[0]
    if name not in JOB_SETTINGS and not (file in EDITABLE_FILES and "." in name):
        raise ValueError(f"[vary] {name}: not a setting (expected {', '.join(JOB_SETTINGS)}, or a key of a file: "
                         f"{', '.join(f'{f}.KEY' for f in EDITABLE_FILES)})")
    if name == "profile.post_processing.vote_length":
        raise ValueError(f"[vary] {name}: the majority vote is set with vote_length")
    if not isinstance(values, list) or not values:
        raise ValueError(f"[vary] {name}: must be a non-empty list of values")
    if name in JOB_SETTINGS and not all(isinstance(v, JOB_SETTINGS[name]) and not isinstance(v, bool) and v > 0
                                        for v in values):
        raise ValueError(f"[vary] {name}: values must be positive numbers"
                         + (" (whole)" if JOB_SETTINGS[name] is int else ""))
    if len({json.dumps(v) for v in values}) != len(values):
        raise ValueError(f"[vary] {name}: a value is listed twice")
    return tuple(values)


def _parse_grid(data: dict, source: str) -> Grid:
    check_table(data, "grid", _TOP_KEYS)
    operators = _names(data, "operators")
    bad = [o for o in operators if o not in OPERATORS]
    if bad:
        raise ValueError(f"'operators': unknown {', '.join(bad)} (expected {', '.join(OPERATORS)})")
    if "seeds" not in data:
        raise ValueError("missing 'seeds'")
    vary = data.get("vary", {})
    if not isinstance(vary, dict):
        raise ValueError("[vary] must be a table of settings, each a list of values")
    vary = {name: _check_setting(name, values) for name, values in _flatten(vary).items()}
    figure = check_table(data.get("figure", {}), "[figure]", {"metric", "setting"})
    metric = figure.get("metric", FIGURE_METRICS[0])
    if metric not in FIGURE_METRICS:
        raise ValueError(f"[figure] metric: {metric!r} is not one of {', '.join(FIGURE_METRICS)}")
    setting = figure.get("setting", next(iter(vary), None))
    if setting is not None and setting not in vary:
        raise ValueError(f"[figure] setting: {setting!r} is not one of [vary] ({', '.join(vary) or 'none'})")
    return Grid(_names(data, "participants"), operators, _seeds(data["seeds"]), vary, metric, setting, source)


def cells(grid: Grid) -> list[Cell]:
    """Every (participant, operator, combination of [vary]), without the settings the operator does
    not read (joystick cells that would only differ in those are one cell)."""
    combinations = [tuple(zip(grid.vary, values)) for values in itertools.product(*grid.vary.values())]
    out: dict[Cell, None] = {}
    for participant, operator, settings in itertools.product(grid.participants, grid.operators, combinations):
        if operator == "joystick":
            settings = tuple((k, v) for k, v in settings if not k.startswith(NOT_READ_BY_JOYSTICK))
        out[Cell(participant, operator, settings)] = None
    return list(out)


def check_cells(grid: Grid, cell_list: list[Cell]) -> None:
    """Every file a cell edits loads with its edits (a bad participant name or value fails here,
    before any episode): one-line BomiError naming the grid and the setting."""
    for cell in cell_list:
        job = cell.job(grid.seeds[0])
        try:
            load_operator(job.operator_file, job.edits("operator"))
            if cell.operator != "joystick":
                params = load_participant(cell.participant, job.edits("participant"))
                profile_controls(arm_profile(params.profile, job.edits("profile")))
        except BomiError as exc:
            raise BomiError(f"{grid.source}: cell {cell.label}: {exc}") from None


def job_settings(job: EpisodeJob) -> dict[str, Any]:
    """What an episode depends on, by the grid's setting names (the joystick reads no vote)."""
    settings = {"participant": job.participant, "operator": job.operator, "seed": job.seed,
                "time_limit": job.time_limit}
    if job.operator != "joystick":
        settings["vote_length"] = job.vote_length
    if job.operator_file != "operator":
        settings["operator_file"] = job.operator_file
    return settings | dict(job.overrides)


def job_key(job: EpisodeJob) -> str:
    """A stable name of the episode: the same settings give the same key on any machine, any day."""
    canonical = json.dumps(job_settings(job), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()[:20]


# ------------------------------------------------------------------------------------ results file
def read_results(path: Path) -> dict[str, dict]:
    """The records already in the results file, by key.  A last line cut short by an interruption
    is dropped (and truncated away before anything is appended); any other bad line is an error."""
    if not path.exists():
        return {}
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BomiError(f"{path}: cannot be read ({exc})") from None
    records: dict[str, dict] = {}
    lines = text.split("\n")
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            records[record["key"]] = record
        except (json.JSONDecodeError, KeyError, TypeError):
            if number == len(lines):  # the unfinished last line of an interrupted write
                continue
            raise BomiError(f"{path}: line {number} is not an episode record; move the file away to start afresh") from None
    return records


def _drop_unfinished_line(path: Path) -> None:
    if path.exists():
        data = path.read_bytes()
        if data and not data.endswith(b"\n"):
            with path.open("r+b") as handle:
                handle.truncate(data.rfind(b"\n") + 1)


def run_sweep(grid: Grid, out: Path, engine: Engine) -> list[dict]:
    """Run the grid's episodes not yet in ``out``/episodes.jsonl, appending each as it finishes;
    return the records of every episode of the grid."""
    cell_list = cells(grid)
    check_cells(grid, cell_list)
    out.mkdir(exist_ok=True)
    path = out / RESULTS_FILE
    done = read_results(path)
    jobs = [cell.job(seed) for cell in cell_list for seed in grid.seeds]
    keys = [job_key(job) for job in jobs]
    todo = [job for job, key in zip(jobs, keys) if key not in done]
    _drop_unfinished_line(path)
    with path.open("a", encoding="utf-8") as results, \
            tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc="episodes", unit="ep") as bar:
        for i, record in engine.run(episode_record, todo):
            key = job_key(todo[i])
            done[key] = {"key": key, "settings": job_settings(todo[i]), **record}
            results.write(json.dumps(done[key]) + "\n")
            results.flush()
            bar.update(1)
    return [done[key] for key in keys]


# ------------------------------------------------------------------------------------ summary
def by_cell(grid: Grid, records: list[dict]) -> list[tuple[dict, list[dict]]]:
    """The records grouped by cell, in the grid's order: (the cell's swept settings, "-" for one its
    operator does not read; its records)."""
    groups: dict[str, tuple[dict, list[dict]]] = {}
    for record in records:
        swept = {name: record["settings"].get(name, "-") for name in grid.vary}
        key = json.dumps([record["participant"], record["operator"], swept])
        groups.setdefault(key, (swept, []))[1].append(record)
    return list(groups.values())


def summary_rows(grid: Grid, records: list[dict]) -> list[dict]:
    """One row per cell: its settings and ``bomi benchmark``'s aggregation of its episodes."""
    rows = []
    for swept, episodes in by_cell(grid, records):
        row, = aggregate(episodes)  # one participant and operator: one row
        rows.append({"settings": swept, **row})
    return rows


def summary_table(grid: Grid, rows: list[dict]) -> str:
    short = [name.rsplit(".", 1)[-1] for name in grid.vary]
    return markdown_table(["participant", "operator", *short, *ROW_COLUMNS],
                          [[r["participant"], r["operator"], *(json.dumps(v) if v != "-" else v
                                                               for v in r["settings"].values()), *row_cells(r)]
                           for r in rows])


def write_summary(grid: Grid, records: list[dict], out: Path) -> str:
    rows = summary_rows(grid, records)
    table = summary_table(grid, rows)
    settings = "; ".join(f"{name} = {json.dumps(list(values))}" for name, values in grid.vary.items()) or "none varied"
    seeds = f"{len(grid.seeds)} seeds ({grid.seeds[0]}..{grid.seeds[-1]})" if list(grid.seeds) == list(
        range(grid.seeds[0], grid.seeds[0] + len(grid.seeds))) else f"seeds {list(grid.seeds)}"
    text = "\n".join([f"# Sweep {grid.source}", "", f"{len(records)} episodes: {', '.join(grid.participants)} x "
                      f"{', '.join(grid.operators)} x {seeds}; {settings}.", "", table, ""])
    (out / "summary.md").write_text(text, encoding="utf-8")
    write_json(out / "summary.json", {"grid": grid.source, "seeds": list(grid.seeds),
                                      "vary": {k: list(v) for k, v in grid.vary.items()}, "rows": rows})
    completion_time_figure([("\n".join([episodes[0]["participant"], episodes[0]["operator"],
                                         *(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in swept.items() if v != "-")]),
                             episodes) for swept, episodes in by_cell(grid, records)],
                           out / "completion_time.png",
                           f"{grid.source}: every episode per cell (line: mean of successes; x: failed)")
    if grid.setting is not None:
        metric_figure(_series(grid, rows), out / f"{grid.metric}_vs_{grid.setting.rsplit('.', 1)[-1]}.png",
                      grid.metric, grid.setting)
    return table


def _series(grid: Grid, rows: list[dict]) -> dict[str, list]:
    """The figure's lines: one per combination of everything but the plotted setting."""
    series: dict[str, list] = {}
    for r in rows:
        value = r["settings"][grid.setting]
        if value == "-":
            continue
        others = [f"{k.rsplit('.', 1)[-1]}={v}" for k, v in r["settings"].items() if k != grid.setting]
        interval = r.get(f"{grid.metric.removesuffix('_mean').removesuffix('_rate')}_ci95")
        series.setdefault(" ".join([r["participant"], r["operator"], *others]), []).append(
            (value, r[grid.metric], tuple(interval) if interval else None))
    return series


# ------------------------------------------------------------------------------------ command
def cmd_sweep(args: argparse.Namespace) -> int:
    grid = load_grid(args.grid)
    engine = engine_from_args(args)
    if not args.out.parent.is_dir():
        raise BomiError(f"--out {args.out}: directory {args.out.parent} does not exist")
    if args.out.exists() and not args.out.is_dir():
        raise BomiError(f"--out {args.out}: not a directory")
    records = run_sweep(grid, args.out, engine)
    print(write_summary(grid, records, args.out))
    print(f"wrote {args.out / 'summary.md'}, {args.out / 'summary.json'} and figures in {args.out}")
    return 0


def register(subparsers) -> None:
    sweep = add_command(subparsers, "sweep")
    sweep.add_argument("grid", type=Path, help="the grid file (TOML)")
    sweep.add_argument("--out", type=Path, required=True, help="directory for episodes.jsonl, the summary and figures")
    add_engine_arguments(sweep)
    sweep.set_defaults(func=cmd_sweep)
