"""`bomi sweep`: the grid file, its cells and keys, resuming an interrupted sweep, the summary."""
import hashlib
import json

import pytest

from tasks.cli import main
from tasks.cli.engine import ProcessPool
from tasks.cli.sweep import FIGURE_METRICS, RESULTS_FILE, cells, job_key, load_grid, read_results, run_sweep, write_summary
from tasks.cli.task import aggregate

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
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = [0]\ncolour = "red"\n', "unknown key(s) colour"),
    ('participants = ["P1"]\noperators = ["telepathy"]\nseeds = [0]\n', "unknown telepathy"),
    ('participants = []\noperators = ["bomi"]\nseeds = [0]\n', "'participants' must be a non-empty list"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = {first = 0}\n', "integers 'first' and 'count'"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [1, 1]\n', "none twice"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote = [1, 3]\n', "vote: not a setting"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote_length = 3\n', "non-empty list"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote_length = [0]\n', "positive numbers"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nprofile.post_processing.vote_length = [3]\n',
     "set with vote_length"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nvote_length = [3]\n[figure]\nsetting = "x"\n',
     "not one of [vary]"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[figure]\nmetric = "colour"\n', "'colour' is not one of"),
    # faults only the files the cells edit can tell: checked before any episode runs too
    ('participants = ["P9"]\noperators = ["bomi"]\nseeds = [0]\n', "no such participant file"),
    ('participants = ["P1"]\noperators = ["bomi"]\nseeds = [0]\n[vary]\nprofile.post_processing.rejection_threshold '
     '= [0.9, 1.5]\n', "rejection threshold must be in (0, 1)"),
    ('participants = ["P1"]\noperators = ["joystick"]\nseeds = [0]\n[vary]\noperator.timing.reaction_tim = [0.3]\n',
     "[timing]: unknown key(s) reaction_tim"),
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
    settings = {"participant": "P1", "operator": "bomi", "seed": 4, "time_limit": 600.0, "vote_length": 3,
                "operator.timing.reaction_time": 0.2}
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


def test_an_interrupted_sweep_resumes_without_rerunning_finished_episodes(tmp_path):
    grid = load_grid(grid_file(tmp_path, JOYSTICK_GRID))
    out = tmp_path / "out"
    first = Interrupting(after=2)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(grid, out, first)
    path = out / RESULTS_FILE
    kept = path.read_text().splitlines()
    assert len(first.asked) == 4 and len(kept) == 2
    with path.open("a") as handle:  # killed in the middle of writing a third record
        handle.write('{"key": "abc", "settings": {"seed"')
    assert set(read_results(path)) == {json.loads(line)["key"] for line in kept}

    second = Interrupting()
    records = run_sweep(grid, out, second)
    finished = {json.loads(line)["key"] for line in kept}
    assert len(second.asked) == 2 and not finished & {job_key(job) for job in second.asked}
    lines = path.read_text().splitlines()
    assert lines[:2] == kept and len(lines) == 4  # the cut line is gone, nothing kept was rewritten
    assert [(r["settings"]["time_limit"], r["seed"]) for r in records] == [(SHORT, 3), (SHORT, 4), (2.5, 3), (2.5, 4)]
    assert [r["sim_time"] for r in records] == pytest.approx([SHORT, SHORT, 2.5, 2.5], abs=0.02)

    third = Interrupting()
    assert run_sweep(grid, out, third) == records and third.asked == []


def test_summary_is_the_benchmark_aggregation_per_cell_with_figures(tmp_path):
    grid = load_grid(grid_file(tmp_path, JOYSTICK_GRID + '[figure]\nmetric = "unintended_displacement_mm"\n'))
    out = tmp_path / "out"
    records = run_sweep(grid, out, ProcessPool(2))
    table = write_summary(grid, records, out)
    summary = json.loads((out / "summary.json").read_text())
    rows = summary["rows"]
    assert [r["settings"] for r in rows] == [{"time_limit": SHORT}, {"time_limit": 2.5}]
    for row in rows:
        cell = [r for r in records if r["settings"]["time_limit"] == row["settings"]["time_limit"]]
        expected, = aggregate(cell)
        assert {k: row[k] for k in expected} == expected and row["episodes"] == 2
    # a joystick row is for anyone with the controls: its participant is "any", its layout P1's
    assert "| any | joystick | 2.5 | 3-axis, B1+B2 | 0/2 " in table and (out / "summary.md").read_text().count("| any |") == 2
    for figure in ("completion_time.png", "unintended_displacement_mm_vs_time_limit.png"):
        assert (out / figure).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert set(FIGURE_METRICS) <= set(rows[0])  # every metric the figure may plot is a summary column
