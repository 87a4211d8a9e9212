"""Sweeps: every combination of the settings a grid file lists, over seeds, resumable.

The grid file's format is `bomi sweep`'s help (tasks/cli/sweep.py). Each (participant, operator,
combination) is a cell of len(seeds) episodes; an episode's key hashes what it depends on, so a
rerun of the same or an extended grid runs only the episodes whose key is not yet in the directory's
results file (``sweep_records``), whose records are checked against their keys before any work.
The summaries and figures are regenerated from every record of the grid.
"""
from __future__ import annotations

import fcntl
import hashlib
import itertools
import json
import math
import os
import signal
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any

from tqdm import tqdm

from bomi.classifier import MAX_VOTE_LENGTH
from bomi.config_files import beside, coerce, config_path, from_table, parse_toml, within
from bomi.errors import BomiError
from bomi.files import atomic_output, write_text
from tasks.experiments.engine import Engine, is_interruption
from tasks.experiments.figures import completion_time_figure, metric_figure
from tasks.experiments.jobs import DEFAULT_VOTE, EDITABLE_FILES, EpisodeJob, episode_record
from tasks.experiments.limits import MAX_SECONDS, MAX_SEED, MAX_SEEDS, MIN_TIME_LIMIT_S
from tasks.experiments.summary import aggregate
from tasks.experiments.sweep_records import RESULTS_FILE, ResultsFile, check_records, read_results
from tasks.experiments.tables import (MIN_EPISODES_FOR_INTERVAL, ROW_COLUMNS, TERMINAL_COLUMNS, aligned_table,
                                      markdown_table, row_cells, terminal_cells)
from tasks.operators.params import load_operator
from tasks.operators.stick import arm_profile
from tasks.participants.participant import PARTICIPANT_DIR, load_participant
from tasks.stacking.episode import OPERATORS
from tasks.stacking.channels import profile_controls

# EpisodeJob fields a grid may vary, beside the EDITABLE_FILES' keys
JOB_SETTINGS = {"time_limit": (int, float), "vote_length": int}
JOB_RANGES = {"time_limit": (MIN_TIME_LIMIT_S, MAX_SECONDS, " s"), "vote_length": (1, MAX_VOTE_LENGTH, " decisions")}
# what the joystick channel never reads
NOT_READ_BY_JOYSTICK = ("vote_length", "profile.", "participant.")
# summary-row columns the figure may plot (tests/test_sweep.py checks they are aggregate's)
FIGURE_METRICS = ("completion_time_mean", "successes", "success_rate", "accuracy_all_decisions",
                  "accuracy_excused_transitions", "excused_share", "relevant_share", "irrelevant_per_min",
                  "longest_error_run_ms", "mode_switches", "unintended_displacement_mm", "latency_ms_median",
                  "cube_drops")
LOCK_FILE = ".sweep.lock"  # flock'ed while a sweep writes the directory; holds its pid
SUMMARY_FILES = ("summary.md", "summary.json", "completion_time.png")
# Sizes a grid may ask for: far beyond any sweep this machine (or a cluster in a week) runs, far
# below what would exhaust memory listing the episodes.
MAX_VALUES = 100            # per [vary] setting
MAX_EPISODES = 100_000      # per grid: cells x seeds


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
    data = parse_toml(Path(path), "grid")
    try:
        grid = _parse_grid(data, str(path))
    except ValueError as exc:
        raise BomiError(f"{path}: {exc}") from None
    shipped = sorted(p.stem for p in PARTICIPANT_DIR.glob("*.toml"))
    odd = [name for name in grid.participants if name not in shipped and Path(name).suffix.lower() != ".toml"]
    if odd:
        raise BomiError(f"{path}: participants: {odd[0]!r} is neither a shipped participant ({', '.join(shipped)}) "
                        f"nor a participant .toml file (named relative to the grid file)")
    return replace(grid, participants=tuple(beside(name, Path(path)) for name in grid.participants))


@dataclass(frozen=True)
class _SeedRange:
    """``seeds = {first = N, count = K}``: K seeds from N."""

    first: int
    count: int

    def __post_init__(self) -> None:
        within(self, 1, MAX_SEEDS, "count")
        within(self, 0, MAX_SEED - self.count + 1, "first")


def _seeds(value: Any) -> tuple[int, ...]:
    """A grid's ``seeds``: a list of integers or {first = N, count = K}; at least one, at most MAX_SEEDS,
    each in [0, MAX_SEED], none twice."""
    if isinstance(value, dict):
        span = from_table(_SeedRange, value)
        seeds = tuple(range(span.first, span.first + span.count))
    elif isinstance(value, list):
        seeds = coerce(value, tuple[int, ...])
    else:
        raise ValueError(f"must be a list of integers or {{first = N, count = K}}, got {value!r}")
    if len(seeds) > MAX_SEEDS:
        raise ValueError(f"at most {MAX_SEEDS} seeds, got {len(seeds)}")
    if not seeds or min(seeds) < 0 or max(seeds) > MAX_SEED or len(set(seeds)) != len(seeds):
        raise ValueError(f"must be at least one seed, each in [0, {MAX_SEED}], none twice")
    return tuple(seeds)


@dataclass(frozen=True)
class _Figure:
    metric: str = FIGURE_METRICS[0]
    setting: str | None = None   # one of [vary] (default: the first)

    def __post_init__(self) -> None:
        if self.metric not in FIGURE_METRICS:
            raise ValueError(f"metric: {self.metric!r} is not one of {', '.join(FIGURE_METRICS)}")


@dataclass(frozen=True)
class _GridFile:
    """A grid file as written (`bomi sweep`'s help)."""

    participants: tuple[str, ...]
    operators: tuple[str, ...]
    seeds: Annotated[tuple[int, ...], _seeds]
    vary: dict[str, Any] = field(default_factory=dict)   # setting -> its values; dotted names are nested tables
    figure: _Figure = _Figure()

    def __post_init__(self) -> None:
        for key in ("participants", "operators"):
            names = getattr(self, key)
            if not names or not all(names):
                raise ValueError(f"{key}: must be a non-empty list of names")
            if len(set(names)) != len(names):
                raise ValueError(f"{key}: lists a name twice")
        bad = [o for o in self.operators if o not in OPERATORS]
        if bad:
            raise ValueError(f"operators: unknown {', '.join(bad)} (expected {', '.join(OPERATORS)})")


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
    if len(values) > MAX_VALUES:
        raise ValueError(f"[vary] {name}: at most {MAX_VALUES} values, got {len(values)}")
    if name in JOB_SETTINGS:
        low, high, unit = JOB_RANGES[name]
        if not all(isinstance(v, JOB_SETTINGS[name]) and not isinstance(v, bool) and low <= v <= high
                   for v in values):
            raise ValueError(f"[vary] {name}: values must be {'whole ' if JOB_SETTINGS[name] is int else ''}"
                             f"numbers in [{low:g}, {high:g}]{unit}")
    if len({json.dumps(v) for v in values}) != len(values):
        raise ValueError(f"[vary] {name}: a value is listed twice")
    return tuple(values)


def _parse_grid(data: dict, source: str) -> Grid:
    file = from_table(_GridFile, data)
    vary = {name: _check_setting(name, values) for name, values in _flatten(file.vary).items()}
    setting = next(iter(vary), None) if file.figure.setting is None else file.figure.setting
    if setting is not None and setting not in vary:
        raise ValueError(f"[figure] setting: {setting!r} is not one of [vary] ({', '.join(vary) or 'none'})")
    grid = Grid(file.participants, file.operators, file.seeds, vary, file.figure.metric, setting, source)
    episodes = len(grid.participants) * len(grid.operators) * math.prod(map(len, vary.values())) * len(grid.seeds)
    if episodes > MAX_EPISODES:
        raise ValueError(f"{episodes} episodes (participants x operators x [vary] combinations x seeds), "
                         f"more than the {MAX_EPISODES} a grid may ask for")
    return grid


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


def job_key(job: EpisodeJob, content: str | None = None) -> str:
    """A stable name of the episode: the same settings give the same key on any machine, any day,
    from any directory; a participant by its content (``participant_content``), never its path, so
    an edited participant file runs again and a moved one does not (``content``: its
    ``participant_content``, computed when not given)."""
    settings = job_settings(job) | {"participant": content or participant_content(job.participant)}
    canonical = json.dumps(settings, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()[:20]


def participant_content(participant: str) -> str:
    """What a participant file holds, as text that names it: the SHA-256 of its bytes, and of its
    profile's file when it names one (a twin's derived profile) rather than a shipped profile."""
    path = config_path(participant, PARTICIPANT_DIR)
    try:
        digest = hashlib.sha256(path.read_bytes())
        profile = load_participant(participant).profile
        if Path(profile).suffix.lower() == ".toml":
            digest.update(Path(profile).read_bytes())
    except OSError as exc:
        raise BomiError(f"{path}: cannot be read ({exc.strerror})") from None
    return f"sha256:{digest.hexdigest()}"


# ------------------------------------------------------------------------------------ the directory
def output_names(grid: Grid) -> tuple[str, ...]:
    """Every file a sweep of ``grid`` writes in its directory."""
    return (LOCK_FILE, RESULTS_FILE, *SUMMARY_FILES, *([metric_figure_name(grid)] if grid.setting else []))


def metric_figure_name(grid: Grid) -> str:
    return f"{grid.metric}_vs_{grid.setting.rsplit('.', 1)[-1]}.png"


def check_directory(out: Path, names: tuple[str, ...]) -> None:
    """``out`` is (or can be made) a directory whose files ``names`` are absent or regular files:
    a symbolic link, FIFO or device planted there is refused, never followed."""
    if out.exists() and not out.is_dir():
        raise BomiError(f"--out {out}: not a directory")
    if not out.exists():
        if not out.parent.is_dir():
            raise BomiError(f"--out {out}: directory {out.parent} does not exist")
        return
    for name in names:
        path = out / name
        try:
            status = os.lstat(path)
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise BomiError(f"{path}: cannot be checked ({exc.strerror})") from None
        if not stat.S_ISREG(status.st_mode):
            kind = "a symbolic link" if stat.S_ISLNK(status.st_mode) else "not a regular file"
            raise BomiError(f"{path}: is {kind}; a sweep writes only its own regular files in --out, never through "
                            f"a link (move it away)")


@contextmanager
def locked(out: Path) -> Iterator[None]:
    """Hold ``out``'s lock file while the body runs; BomiError at once if another sweep holds it."""
    path = out / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise BomiError(f"{path}: cannot open the sweep's lock file ({exc.strerror})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise BomiError(f"--out {out}: another bomi sweep (pid {holder}) is writing this directory; rerun "
                            f"when it has finished (only what it did not run will run)") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)


@contextmanager
def signals_interrupt() -> Iterator[None]:
    """SIGTERM and SIGHUP end the sweep as Ctrl-C does (finished episodes kept, workers stopped)
    rather than killing the driver outright."""
    def interrupt(signum, frame):
        raise KeyboardInterrupt(signal.Signals(signum).name)

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)




@dataclass
class SweepResult:
    records: list[dict]  # of the grid's episodes that have run, in the grid's order
    total: int           # episodes in the grid
    ran: int             # of them run now
    interrupted: bool
    table: str | None    # the terminal's summary table (None: no episode yet, or not asked for)


def run_sweep(grid: Grid, out: Path, engine: Engine, summarize: bool = True) -> SweepResult:
    """Run the grid's episodes not yet in ``out``/episodes.jsonl, appending each as it finishes,
    then (``summarize``) write the summaries and figures of every record of the grid, all with
    ``out`` locked; an interruption (Ctrl-C, SIGTERM) keeps what finished and summarises it."""
    cell_list = cells(grid)
    check_cells(grid, cell_list)
    check_directory(out, output_names(grid))
    try:
        out.mkdir(exist_ok=True)
    except OSError as exc:
        raise BomiError(f"--out {out}: cannot be made ({exc.strerror})") from None
    jobs = [cell.job(seed) for cell in cell_list for seed in grid.seeds]
    contents = {name: participant_content(name) for name in grid.participants}  # read once, before any episode
    keys = [job_key(job, contents[job.participant]) for job in jobs]
    with locked(out), signals_interrupt():
        check_directory(out, output_names(grid))  # again, now that no other sweep can change it
        path = out / RESULTS_FILE
        results = read_results(path)
        check_records(path, results, {key: job_settings(job) for job, key in zip(jobs, keys)})
        done = results.records
        todo = [(job, key) for job, key in zip(jobs, keys) if key not in done]
        interrupted = False
        file = ResultsFile(path, results)
        try:
            with tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc="episodes", unit="ep") as bar:
                for i, record in engine.run(episode_record, [job for job, _ in todo]):
                    job, key = todo[i]
                    done[key] = {"key": key, "settings": job_settings(job), **record}
                    file.append(done[key])
                    bar.update(1)
        except (KeyboardInterrupt, SystemError) as exc:
            if not is_interruption(exc):
                raise
            interrupted = True
        finally:
            file.close()
        records = [done[key] for key in keys if key in done]
        table = write_summary(grid, records, out) if summarize and records else None
    ran = len(records) - (len(jobs) - len(todo))
    return SweepResult(records, len(jobs), ran, interrupted, table)


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


def summary_table(grid: Grid, rows: list[dict], terminal: bool = False) -> str:
    """The summary table: every column (summary.md), or what fits a terminal's 100 columns."""
    short = [name.rsplit(".", 1)[-1] for name in grid.vary]
    columns, cells_of, table = ((TERMINAL_COLUMNS, terminal_cells, aligned_table) if terminal
                                else (ROW_COLUMNS, row_cells, markdown_table))
    return table(["participant", "operator", *short, *columns],
                          [[r["participant"], r["operator"], *(json.dumps(v) if v != "-" else v
                                                               for v in r["settings"].values()), *cells_of(r)]
                           for r in rows])


def write_summary(grid: Grid, records: list[dict], out: Path) -> str:
    """Write the summaries and figures of ``records``; return the terminal's table."""
    rows = summary_rows(grid, records)
    table = summary_table(grid, rows)
    settings = "; ".join(f"{name} = {json.dumps(list(values))}" for name, values in grid.vary.items()) or "none varied"
    seeds = f"{len(grid.seeds)} seeds ({grid.seeds[0]}..{grid.seeds[-1]})" if list(grid.seeds) == list(
        range(grid.seeds[0], grid.seeds[0] + len(grid.seeds))) else f"seeds {list(grid.seeds)}"
    text = "\n".join([f"# Sweep {grid.source}", "", f"{len(records)} episodes: {', '.join(grid.participants)} x "
                      f"{', '.join(grid.operators)} x {seeds}; {settings}.", "", table, ""])
    # the sweep's own files, regenerated from its records: replaced (atomically) on every run
    write_text(out / "summary.md", text, overwrite=True)
    write_text(out / "summary.json", json.dumps({"grid": grid.source, "seeds": list(grid.seeds),
                                                 "vary": {k: list(v) for k, v in grid.vary.items()},
                                                 "rows": rows}, indent=2) + "\n", overwrite=True)
    with atomic_output(out / "completion_time.png", overwrite=True) as temp:
        completion_time_figure([("\n".join([episodes[0]["participant"], episodes[0]["operator"],
                                             *(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in swept.items()
                                               if v != "-")]), episodes)
                                 for swept, episodes in by_cell(grid, records)],
                               temp, f"sweep {Path(grid.source).name}: every episode per cell\n"
                                     f"(dot: a success, line: their mean; x: a failed episode)")
    if grid.setting is not None:
        with atomic_output(out / metric_figure_name(grid), overwrite=True) as temp:
            metric_figure(_series(grid, rows), temp, grid.metric, grid.setting)
    return summary_table(grid, rows, terminal=True)


def _series(grid: Grid, rows: list[dict]) -> dict[str, list]:
    """The figure's lines: one per combination of everything but the plotted setting."""
    series: dict[str, list] = {}
    for r in rows:
        value = r["settings"][grid.setting]
        if value == "-":
            continue
        others = [f"{k.rsplit('.', 1)[-1]}={v}" for k, v in r["settings"].items() if k != grid.setting]
        interval = r.get(f"{grid.metric.removesuffix('_mean').removesuffix('_rate')}_ci95")
        counted = r["successes"] if grid.metric.startswith("completion_time") else r["episodes"]
        interval = interval if counted >= MIN_EPISODES_FOR_INTERVAL else None
        series.setdefault(" ".join([r["participant"], r["operator"], *others]), []).append(
            (value, r[grid.metric], tuple(interval) if interval else None))
    return series
