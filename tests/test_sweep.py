"""`bomi sweep`: the grid file, its cells and keys, resuming an interrupted sweep, the summary."""
import fcntl
import hashlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bomi.files import TEMP_MARK
from tasks.cli import main
from tasks.experiments.engine import ProcessPool
from tasks.experiments.summary import aggregate
from tasks.experiments.sweep import FIGURE_METRICS, LOCK_FILE, cells, job_key, load_grid, run_sweep
from tasks.experiments.sweep_records import RESULTS_FILE, read_results
from tasks.participants.participant import PARTICIPANT_DIR

SHORT = 2.0  # s of simulated time: a joystick episode that short costs well under a second


def grid_file(tmp_path, text, name="grid.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


JOYSTICK_GRID = f"""
participants = ["P1"]
operators = ["joystick"]
seeds = {{first = 3, count = 2}}
[vary]
time_limit = [{SHORT}, 2.5]
"""


@pytest.mark.parametrize("text, fault", [
    ('participants = ["P1"]\noperators = ["joystick"\n', "not valid TOML"),
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = [0]\ncolour = "red"\n', "unknown key(s) ['colour']"),
    ('participants = ["P1"]\noperators = ["telepathy"]\nseeds = [0]\n', "unknown telepathy"),
    ('participants = []\noperators = ["bomi"]\nseeds = [0]\n', "participants: must be a non-empty list of names"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = {first = 0}\n', "seeds: count: missing"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [1, 1]\n', "none twice"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote = [1, 3]\n', "vote: not a setting"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote_length = 3\n', "non-empty list"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote_length = [0]\n', "whole numbers in [1, 625]"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nprofile.post_processing.vote_length = [3]\n',
     "set with vote_length"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote_length = [3]\n[figure]\nsetting = "x"\n',
     "not one of [vary]"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[figure]\nmetric = "colour"\n', "'colour' is not one of"),
    # faults only the files the cells edit can tell: checked before any episode runs too
    ('participants = ["P9"]\noperators = ["bomi"]\nseeds = [0]\n', "neither a shipped participant"),
    ('participants = ["../../../tmp/x"]\noperators = ["bomi"]\nseeds = [0]\n', "neither a shipped participant"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nprofile.post_processing.rejection_threshold '
     '= [0.9, 1.5]\n', "rejection threshold must be in (0, 1)"),
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = [0]\n[vary]\noperator.timing.reaction_tim = [0.3]\n',
     "[timing] unknown key(s) ['reaction_tim']"),
])
def test_a_bad_grid_is_one_line_naming_the_file_before_any_episode(tmp_path, capsys, text, fault):
    grid, out = grid_file(tmp_path, text), tmp_path / "out"
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("bomi: error:") and str(grid) in err and fault in err and "\n" not in err
    assert not (out / RESULTS_FILE).exists()


def test_cells_are_every_combination_and_joystick_cells_drop_what_it_does_not_read(tmp_path):
    grid = load_grid(grid_file(tmp_path, """
participants = ["P1", "P4"]
operators = ["joystick", "bomi"]
seeds = [0, 7]
[vary]
vote_length = [1, 5, 9]
profile.post_processing.rejection_threshold = [0.9, 0.99]
operator.timing.reaction_time = [0.2, 0.3]
"""))
    all_cells = cells(grid)
    bomi = [c for c in all_cells if c.operator == "bomi"]
    joystick = [c for c in all_cells if c.operator == "joystick"]
    assert len(bomi) == 2 * 3 * 2 * 2 and len(joystick) == 2 * 2  # per participant: reaction times only
    assert {dict(c.settings)["operator.timing.reaction_time"] for c in joystick} == {0.2, 0.3}
    job = bomi[0].job(7)
    assert (job.seed, job.vote_length, job.edits("profile")) == (7, 1, {"post_processing.rejection_threshold": 0.9})
    assert job.edits("operator") == {"timing.reaction_time": 0.2} and job.edits("participant") == {}


def test_an_episode_key_is_a_hash_of_its_settings_whatever_the_grid_order(tmp_path):
    a = load_grid(grid_file(tmp_path, 'participants = ["P1"]\noperators = ["bomi"]\nseeds = [4]\n[vary]\n'
                                      'vote_length = [3]\noperator.timing.reaction_time = [0.2]\n', "a.toml"))
    b = load_grid(grid_file(tmp_path, 'participants = ["P1"]\noperators = ["bomi"]\nseeds = [4]\n[vary]\n'
                                      'operator.timing.reaction_time = [0.2]\nvote_length = [3]\n', "b.toml"))
    job_a, job_b = cells(a)[0].job(4), cells(b)[0].job(4)
    p1 = hashlib.sha256((PARTICIPANT_DIR / "P1.toml").read_bytes()).hexdigest()
    settings = {"participant": f"sha256:{p1}", "operator": "bomi", "seed": 4, "time_limit": 600.0,
                "vote_length": 3, "operator.timing.reaction_time": 0.2}
    expected = hashlib.sha256(json.dumps(settings, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:20]
    assert job_key(job_a) == job_key(job_b) == expected
    assert job_key(cells(a)[0].job(5)) != expected


class Interrupting:
    """A process pool that is interrupted (as by Ctrl-C) after ``after`` episodes, and remembers
    which episodes it was asked to run."""

    def __init__(self, after=None):
        self.after, self.asked = after, []

    def run(self, work, items):
        self.asked += list(items)
        for n, result in enumerate(ProcessPool(1).run(work, items), 1):
            yield result
            if n == self.after:
                raise KeyboardInterrupt


def test_an_interrupted_sweep_resumes_without_rerunning_finished_episodes(tmp_path, capsys):
    grid = load_grid(grid_file(tmp_path, JOYSTICK_GRID))
    out = tmp_path / "out"
    first = Interrupting(after=2)
    result = run_sweep(grid, out, first)
    assert result.interrupted and (result.total, result.ran, len(result.records)) == (4, 2, 2)
    path = out / RESULTS_FILE
    kept = path.read_text().splitlines()
    assert len(first.asked) == 4 and len(kept) == 2
    with path.open("a") as handle:  # killed in the middle of writing a third record
        handle.write('{"key": "abc", "settings": {"seed"')
    assert set(read_results(path).records) == {json.loads(line)["key"] for line in kept}

    second = Interrupting()
    records = run_sweep(grid, out, second).records
    assert "set aside an unfinished last line (34 bytes" in capsys.readouterr().err
    finished = {json.loads(line)["key"] for line in kept}
    assert len(second.asked) == 2 and not finished & {job_key(job) for job in second.asked}
    lines = path.read_text().splitlines()
    assert lines[:2] == kept and len(lines) == 4  # the cut line is gone, nothing kept was rewritten
    assert [(r["settings"]["time_limit"], r["seed"]) for r in records] == [(SHORT, 3), (SHORT, 4), (2.5, 3), (2.5, 4)]
    assert [r["sim_time"] for r in records] == pytest.approx([SHORT, SHORT, 2.5, 2.5], abs=0.02)

    third = Interrupting()
    assert run_sweep(grid, out, third).records == records and third.asked == []


def test_a_complete_last_record_without_its_line_end_is_kept_and_said(tmp_path, capsys):
    grid = load_grid(grid_file(tmp_path, JOYSTICK_GRID))
    out = tmp_path / "out"
    run_sweep(grid, out, Interrupting(after=2))
    path = out / RESULTS_FILE
    whole = path.read_bytes()
    path.write_bytes(whole[:-1])  # the last record's newline lost (an editor, a copy)
    again = Interrupting()
    records = run_sweep(grid, out, again).records
    assert "its last record had no line end; kept it (2 records)" in capsys.readouterr().err
    assert len(again.asked) == 2 and len(records) == 4
    assert path.read_bytes().startswith(whole) and len(path.read_text().splitlines()) == 4


# ------------------------------------------------------------------------------- as a user runs it
def sweep(grid, out, *extra, check=None, **kwargs):
    """`bomi sweep` in its own process (what a user runs)."""
    done = subprocess.run([sys.executable, "-m", "tasks.cli", "sweep", str(grid), "--out", str(out), "--jobs", "1",
                           *extra], capture_output=True, text=True, timeout=300, **kwargs)
    if check is not None:
        assert done.returncode == check, done.stderr
    return done


def keys_in(out):
    return [json.loads(line)["key"] for line in (out / RESULTS_FILE).read_text().splitlines()]


ONE_SECOND = """
participants = ["P1"]
operators = ["joystick"]
seeds = {first = 0, count = %d}
[vary]
time_limit = [1.0]
"""


@pytest.fixture(scope="module")
def finished_sweep(tmp_path_factory):
    """(grid, directory) of a finished sweep of ONE_SECOND % 2, made once for the module: the first step of
    the tests below, each of which copies the directory and goes on with `bomi sweep` in its own process
    (they share an xdist group, so that one worker makes it once). The first step is the same command
    through ``main`` in this process: the directory it leaves is what the tests start from, not the
    process that made it."""
    where = tmp_path_factory.mktemp("finished_sweep")
    grid, out = grid_file(where, ONE_SECOND % 2), where / "out"
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 0
    assert len(keys_in(out)) == 2
    return grid, out


def finished_copy(finished_sweep, tmp_path) -> tuple[Path, Path]:
    """A grid of ONE_SECOND % 2 in ``tmp_path`` and a copy of the finished sweep's directory beside it:
    as after `bomi sweep grid.toml --out out` (the same command, the same files)."""
    return grid_file(tmp_path, ONE_SECOND % 2), Path(shutil.copytree(finished_sweep[1], tmp_path / "out"))


@pytest.mark.xdist_group("finished-sweep")
def test_the_same_command_again_reruns_nothing_and_regenerates_every_summary(tmp_path, finished_sweep):
    grid, out = finished_copy(finished_sweep, tmp_path)
    first = keys_in(out)
    (out / "summary.md").write_text("stale")
    done = sweep(grid, out, check=0)
    assert keys_in(out) == first and "file exists" not in done.stderr
    assert "2 episodes" in (out / "summary.md").read_text()
    assert not [p for p in out.iterdir() if TEMP_MARK in p.name]


@pytest.mark.xdist_group("finished-sweep")
def test_more_seeds_run_only_the_new_episodes_and_the_summaries_agree(tmp_path, finished_sweep):
    grid, out = finished_copy(finished_sweep, tmp_path)
    first = keys_in(out)
    grid.write_text(ONE_SECOND % 3)  # the grid file's own advice: add seeds and rerun the same command
    sweep(grid, out, check=0)
    keys = keys_in(out)
    assert keys[:2] == first and len(keys) == len(set(keys)) == 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["seeds"] == [0, 1, 2] and summary["rows"][0]["episodes"] == 3
    assert "| 0/3 " in (out / "summary.md").read_text()


def test_a_second_sweep_on_the_same_directory_says_one_line_and_runs_nothing(tmp_path):
    grid, out = grid_file(tmp_path, ONE_SECOND % 2), tmp_path / "out"
    out.mkdir()
    with open(out / LOCK_FILE, "w") as held:  # as a running sweep holds it
        fcntl.flock(held, fcntl.LOCK_EX)
        held.write("12345\n")
        held.flush()
        done = sweep(grid, out, check=2)
    assert done.stderr.strip().splitlines() == [done.stderr.strip()]
    assert "another bomi sweep (pid 12345) is writing this directory" in done.stderr
    assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]


def test_two_sweeps_started_together_run_each_episode_once(tmp_path):
    grid, out = grid_file(tmp_path, ONE_SECOND % 3), tmp_path / "out"
    command = [sys.executable, "-m", "tasks.cli", "sweep", str(grid), "--out", str(out), "--jobs", "1"]
    both = [subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    codes = sorted(p.wait(timeout=300) for p in both)
    errors = [p.stderr.read() for p in both]
    assert codes in ([0, 0], [0, 2]), errors
    keys = keys_in(out)
    assert len(keys) == len(set(keys)) == 3


@pytest.mark.xdist_group("finished-sweep")
@pytest.mark.parametrize("planted, own_process", [("summary.md", True), (RESULTS_FILE, False),
                                                  ("completion_time.png", False), (LOCK_FILE, False)])
def test_a_symlink_planted_in_the_directory_is_refused_and_its_target_untouched(tmp_path, capsys, finished_sweep,
                                                                                planted, own_process):
    """`bomi sweep` refuses a directory with a link among its files before writing anything. One case
    in its own process (its whole stderr is the one line); the others, which differ only in the file
    planted, through the same ``main`` in this one (no interpreter and stack to start again)."""
    grid, out = finished_copy(finished_sweep, tmp_path)
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me")
    (out / planted).unlink()
    (out / planted).symlink_to(victim)
    before = {p.name: p.read_bytes() for p in out.iterdir() if not p.is_symlink()}
    if own_process:
        err = sweep(grid, out, check=2).stderr
    else:
        assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 2
        err = capsys.readouterr().err
    assert err.strip().startswith("bomi: error:") and "\n" not in err.strip()
    assert planted in err and "symbolic link" in err
    assert victim.read_text() == "keep me" and (out / planted).is_symlink()
    assert {p.name: p.read_bytes() for p in out.iterdir() if not p.is_symlink()} == before


def children(pid):
    """The pids of ``pid``'s child processes (Linux /proc)."""
    kids = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        kids += [int(k) for k in (task / "children").read_text().split()]
    return kids


def alive(pid):
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] not in "ZX"
    except FileNotFoundError:
        return False


def wait_for(condition, seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


LONG = """
participants = ["P1"]
operators = ["joystick"]
seeds = {first = 0, count = 8}
[vary]
time_limit = [30.0]
"""


def start_long_sweep(tmp_path):
    grid, out = grid_file(tmp_path, LONG), tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-m", "tasks.cli", "sweep", str(grid), "--out", str(out),
                                "--jobs", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True,  # its own process group, as a shell job
                               # a person's Ctrl-C: the default SIGINT even when the tests run as a background
                               # job, whose children inherit SIGINT ignored (the sweep then ran all 8 to the end)
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert wait_for(lambda: (out / RESULTS_FILE).exists() and (out / RESULTS_FILE).read_text().count("\n") >= 1, 120)
    workers = children(process.pid)
    assert len(workers) >= 2
    return process, out, workers


def test_ctrl_c_keeps_every_finished_episode_and_stops_the_workers(tmp_path):
    process, out, workers = start_long_sweep(tmp_path)
    os.killpg(process.pid, signal.SIGINT)  # what Ctrl-C at a terminal does: the whole job gets it
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert "Traceback" not in err
    saved = keys_in(out)
    assert 1 <= len(saved) < 8 and f"{len(saved)} of the grid's 8 episodes are saved" in err
    assert (out / RESULTS_FILE).read_text().endswith("\n")
    assert json.loads((out / "summary.json").read_text())["rows"][0]["episodes"] == len(saved)
    assert wait_for(lambda: not any(alive(w) for w in workers), 10)


@pytest.mark.parametrize("how", [signal.SIGTERM, signal.SIGKILL])
def test_no_worker_outlives_the_driver_whatever_ends_it(tmp_path, how):
    process, out, workers = start_long_sweep(tmp_path)
    process.send_signal(how)
    process.communicate(timeout=60)
    assert wait_for(lambda: not any(alive(w) for w in workers), 10), "a pool worker outlived its driver"
    lines = (out / RESULTS_FILE).read_text()
    assert lines.endswith("\n") and all(json.loads(line)["key"] for line in lines.splitlines())


@pytest.mark.xdist_group("finished-sweep")
def test_a_full_disk_is_one_line_and_leaves_only_whole_records(tmp_path, finished_sweep):
    grid, out = grid_file(tmp_path, ONE_SECOND % 4), tmp_path / "out"

    def small_files():  # in the child: files may not grow beyond 1.5 records (as a disk that fills up)
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    # one record's line (seed 0 of this grid's time limit: the finished sweep's first, as this grid's first)
    line = len((finished_sweep[1] / RESULTS_FILE).read_bytes().splitlines(keepends=True)[0])
    limit = int(1.5 * line)
    done = sweep(grid, out, preexec_fn=small_files)
    assert done.returncode == 2, done.stderr
    errors = [x for x in done.stderr.splitlines() if x.startswith("bomi: ")]
    assert len(errors) == 1 and "episodes.jsonl: cannot append an episode (" in errors[0] \
        and "the 1 episodes before it are saved, rerun to go on" \
        in errors[0], done.stderr
    assert "Traceback" not in done.stderr
    assert len(keys_in(out)) == 1 and (out / RESULTS_FILE).read_text().endswith("\n")
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 0  # room again: the rest runs
    assert len(keys_in(out)) == 4


@pytest.mark.parametrize("text, fault", [
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = {first = 0, count = 1000000000000000}\n',
     "seeds: count: must be in [1, 10000], got 1000000000000000"),
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = [1000000000000000]\n', "each in [0, 4294967295]"),
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = [0]\n[vary]\ntime_limit = ['
     + ", ".join(str(1.0 + k) for k in range(101)) + "]\n", "at most 100 values"),
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = [0]\n[vary]\ntime_limit = ['
     + ", ".join(str(1.0 + k) for k in range(1_000_000)) + "]\n", "bytes, more than the 1048576 a grid file may have"),
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = [0]\n[vary]\ntime_limit = [1e-300]\n',
     "numbers in [1, 86400] s"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote_length = [1000000000000]\n',
     "whole numbers in [1, 625] decisions"),
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = {first = 0, count = 10000}\n[vary]\n'
     'time_limit = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0]\n', "more than the 100000"),
    ("a = " + "[" * 3000 + "]" * 3000 + "\n", "nested deeper than 16 levels"),
], ids=["seed-count-1e15", "seed-1e15", "101-values", "1e6-values", "time-limit-1e-300", "vote-1e12",
        "1.1e5-episodes", "nested-3000-deep"])
def test_a_grid_beyond_any_sweep_is_refused_at_once(tmp_path, capsys, text, fault):
    grid, out = grid_file(tmp_path, text), tmp_path / "out"
    start = time.monotonic()
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("bomi: error:") and fault in err and "\n" not in err, err
    assert time.monotonic() - start < 5 and not out.exists()


@pytest.mark.parametrize("kind", ["fifo", "device", "directory"])
def test_a_grid_that_is_not_a_file_is_refused_without_reading_it(tmp_path, capsys, kind):
    grid = tmp_path / "grid.toml"
    if kind == "fifo":
        os.mkfifo(grid)
    elif kind == "directory":
        grid.mkdir()
    else:
        grid = Path("/dev/zero")
    assert main(["sweep", str(grid), "--out", str(tmp_path / "out"), "--jobs", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"bomi: error: {grid}: is ") and "\n" not in err


def test_summary_is_the_benchmark_aggregation_per_cell_with_figures(tmp_path):
    grid = load_grid(grid_file(tmp_path, JOYSTICK_GRID + '[figure]\nmetric = "unintended_displacement_mm"\n'))
    out = tmp_path / "out"
    result = run_sweep(grid, out, ProcessPool(2))
    records, table = result.records, result.table
    summary = json.loads((out / "summary.json").read_text())
    rows = summary["rows"]
    assert [r["settings"] for r in rows] == [{"time_limit": SHORT}, {"time_limit": 2.5}]
    for row in rows:
        cell = [r for r in records if r["settings"]["time_limit"] == row["settings"]["time_limit"]]
        expected, = aggregate(cell)
        assert {k: row[k] for k in expected} == expected and row["episodes"] == 2
    # a joystick row is for anyone with the controls: its participant is "any", its layout P1's
    full = (out / "summary.md").read_text()
    assert "| any | joystick | 2.5 | 3-axis, B1+B2 | 0/2 |" in full and full.count("| any |") == 2
    # the terminal's table: within 100 columns, no interval for 2 episodes
    assert table.splitlines()[3].split() == ["any", "joystick", "2.5", "0/2", "-", "-", "-", "-"]
    assert max(map(len, table.splitlines())) <= 100
    for figure in ("completion_time.png", "unintended_displacement_mm_vs_time_limit.png"):
        assert (out / figure).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert set(FIGURE_METRICS) <= set(rows[0])  # every metric the figure may plot is a summary column


def test_the_sweep_figure_has_units_and_a_log_axis_for_thresholds(tmp_path):
    """A threshold's 0.9, 0.99, 0.999 are evenly spaced (log of 1 - threshold), the axes say what
    and in which unit; no error bar for fewer than 5 episodes."""
    from tasks.experiments.figures import metric_figure
    import matplotlib.pyplot as plt
    captured = {}
    real_savefig = plt.Figure.savefig

    def keep(fig, path, **kwargs):
        captured["axes"] = fig.axes[0]
        return real_savefig(fig, path, **kwargs)

    plt.Figure.savefig = keep
    try:
        metric_figure({"P4 bomi": [(0.9, 30.0, None), (0.99, 20.0, None), (0.999, 25.0, None)]},
                      tmp_path / "f.png", "completion_time_mean", "profile.post_processing.rejection_threshold")
    finally:
        plt.Figure.savefig = real_savefig
    ax = captured["axes"]
    assert ax.get_xscale() == "log" and ax.get_ylabel() == "completion time, mean of successes (s)"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["0.9", "0.99", "0.999"]
    line = ax.get_lines()[0].get_xdata()
    assert list(line) == pytest.approx([0.1, 0.01, 0.001])
    assert "rejection threshold" in ax.get_xlabel() and "log" in ax.get_xlabel()


def descendants(pid):
    found, todo = [], [pid]
    while todo:
        for kid in children(todo.pop()):
            found.append(kid)
            todo.append(kid)
    return found


@pytest.mark.xdist_group("ray")  # one Ray at a time (see tests/test_engine.py)
@pytest.mark.long
def test_sigterm_on_a_ray_sweep_keeps_what_finished_and_shuts_the_local_ray_down(tmp_path):
    pytest.importorskip("ray", reason="Ray is the optional extra: pip install -e \".[ray]\"")
    grid, out = grid_file(tmp_path, LONG), tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-m", "tasks.cli", "sweep", str(grid), "--out", str(out),
                                "--engine", "ray", "--jobs", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, start_new_session=True)
    assert wait_for(lambda: (out / RESULTS_FILE).exists() and (out / RESULTS_FILE).read_text().count("\n") >= 1, 240)
    ray_processes = descendants(process.pid)
    assert ray_processes  # the local Ray's processes are the driver's descendants
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "episodes are saved in" in err and "Traceback" not in err
    assert wait_for(lambda: not any(alive(p) for p in ray_processes), 30), "a Ray process outlived the sweep"
    assert 1 <= len(keys_in(out)) < 8
