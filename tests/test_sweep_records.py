"""Resuming a sweep whose results file was edited: every record is checked against the schema and
its key before any episode runs; a fault is one line naming the file and the record, exit 2,
and nothing is run, written or lost."""
import json
import re
import shutil

import pytest

from tasks.cli import main
from tasks.experiments.sweep_records import RESULTS_FILE

GRID = """
participants = ["P1"]
operators = ["joystick"]
seeds = [3, 4]
[vary]
time_limit = [2.0, 2.5]
"""


FINISHED = pytest.mark.xdist_group("finished-records")   # finished's tests: one worker makes it once


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A sweep that ran all four of its episodes: its grid and directory."""
    base = tmp_path_factory.mktemp("sweep")
    grid, out = base / "grid.toml", base / "out"
    grid.write_text(GRID)
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 0
    return grid, out


def lines_of(out) -> list[dict]:
    return [json.loads(line) for line in (out / RESULTS_FILE).read_text().splitlines()]


def edited(finished, tmp_path, edit):
    """A copy of the finished sweep whose second record ``edit`` changed: the grid, the directory,
    the results file's bytes and the summary's, the key of that record."""
    grid, out = finished
    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    records = lines_of(copy)
    edit(records[1])
    (copy / RESULTS_FILE).write_text("".join(json.dumps(r) + "\n" for r in records))
    return grid, copy


def _set(field, value):
    return lambda r: r.__setitem__(field, value)


def _del(field):
    return lambda r: r.pop(field)


def _setting(field, value):
    return lambda r: r["settings"].__setitem__(field, value)


@pytest.mark.parametrize("edit, fault", [
    (_set("completion_time", "fast"), re.escape("completion_time: 'fast' is not of type 'number', 'null'")),
    (_del("completion_time"), re.escape("'completion_time' is a required property")),
    (_set("participant", 5), re.escape("participant: 5 is not of type 'string'")),
    (_set("success", "yes"), re.escape("success: 'yes' is not of type 'boolean'")),
    (_set("success", "no"), re.escape("success: 'no' is not of type 'boolean'")),
    (_set("success", 0.5), re.escape("success: 0.5 is not of type 'boolean'")),
    (_set("success", 1), re.escape("success: 1 is not of type 'boolean'")),
    (lambda r: r.update(seed=r["seed"] + 100), r"seed \d+ is not its settings' \d+"),
    (_set("operator", "bomi"), r'operator "bomi" is not its settings\' "joystick"'),
    (_setting("time_limit", 2.5), "its settings are not the ones its key"),
    (_setting("vote_length", 9), "its settings are not the ones its key"),
    (_set("cube_drops", -1), re.escape("cube_drops: -1 is less than the minimum of 0")),
    (_set("settings", "P1"), None),  # not a record at all: the reader's own line
])
@FINISHED
def test_an_edited_record_stops_the_resume_with_one_line_naming_it(finished, tmp_path, capsys, edit, fault):
    grid, out = edited(finished, tmp_path, edit)
    before = {name: (out / name).read_bytes() for name in (RESULTS_FILE, "summary.md", "summary.json")}
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith(f"bomi: error: {out / RESULTS_FILE}: ")
    if fault is None:
        assert "line 2 is not an episode record" in err
    else:
        assert re.search(": record 2: " + fault, err) and "nothing was run or changed" in err, err
    assert {name: (out / name).read_bytes() for name in before} == before  # nothing lost or rewritten


@FINISHED
def test_a_success_beyond_its_time_limit_is_named(finished, tmp_path, capsys):
    grid, out = edited(finished, tmp_path, lambda r: r.update(success=True, failure=None,
                                                              completion_time=r["settings"]["time_limit"] + 1.0))
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 2
    err = capsys.readouterr().err
    assert "record 2: completion_time 3 s is beyond its time limit (2 s)" in err, err


@FINISHED
def test_a_failure_with_a_completion_time_is_named(finished, tmp_path, capsys):
    grid, out = edited(finished, tmp_path, lambda r: r.update(success=False, completion_time=1.0,
                                                              failure="time limit 2 s"))
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 2
    assert "record 2: completion_time: 1.0 is not of type 'null'" in capsys.readouterr().err


@FINISHED
def test_records_as_written_resume_and_extra_fields_are_free(finished, tmp_path, capsys):
    """The check refuses nothing a sweep writes, nor a field it does not read (a later version's)."""
    grid, out = edited(finished, tmp_path, lambda r: r.update(note="checked by hand"))
    assert main(["sweep", str(grid), "--out", str(out), "--jobs", "1"]) == 0
    assert "record" not in capsys.readouterr().err
    assert len(lines_of(out)) == 4  # nothing ran again, nothing was dropped
