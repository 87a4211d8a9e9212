"""The original logger's files (bomi/logger_layout.py): its int32 millisecond clock is read as a clock and
its passes are found; the published files' uint8 Time counter is not a clock."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.io

from bomi.logger_layout import LOGGER_STEP_MS, logger_clock, write_logger_passes
from bomi.passes import PassBounds, cut, pass_bounds
from bomi.recording import NodeData, Recording, read_recording
from tasks.cli import main
from tasks.participants.population import draw_person, pass_recordings

PERSON = 5   # six head motions and the neutral posture, one node


def unclocked(rows: int, source: str) -> Recording:
    return Recording({1: NodeData(angles=np.zeros((rows, 3)))}, np.zeros(rows, int), source=source)


def test_the_logger_clock_by_hand():
    # 3 + 2 rows, 1 lead row: 0, then +16 + 3000 (start pause), +16, then +6200 (between passes), +16
    clock = logger_clock([unclocked(3, "a"), unclocked(2, "b")], start_pause_s=3.0, pass_pause_s=6.2, lead_rows=1)
    assert clock.dtype == np.int32 and clock.tolist() == [0, 3016, 3032, 9232, 9248]


@pytest.fixture(scope="module")
def logger_file(tmp_path_factory):
    """A person's two passes (4000 rows each) written as the logger writes them: two rows, a 3 s pause, ..."""
    path = tmp_path_factory.mktemp("logger") / "calib.mat"
    passes = [cut(p, PassBounds(0, 4000), p.source) for p in pass_recordings(draw_person(PERSON))]
    write_logger_passes(path, passes, start_pause_s=3.0, pass_pause_s=6.2, lead_rows=2)
    return path, passes


def test_a_logger_file_holds_an_int32_ms_clock_and_is_read_as_two_passes(logger_file):
    path, passes = logger_file
    time = scipy.io.loadmat(path)["Time"]
    steps = np.diff(time.ravel().astype(np.int64))
    assert time.dtype == np.int32 and np.median(steps) == LOGGER_STEP_MS
    # each pass's own steps (its lost samples kept), 3 s more after the second row, 6.2 s between the passes
    own = [np.round(np.diff(p.time) * 1000).astype(np.int64) for p in passes]
    expected = np.r_[own[0], 6200, own[1]]
    expected[1] += 3000
    np.testing.assert_array_equal(steps, expected)
    rec = read_recording(path)
    np.testing.assert_array_equal(rec.time, time.ravel() / 1000.0)      # read as seconds
    assert pass_bounds(rec) == [PassBounds(0, 4000), PassBounds(4000, 8000, "a 6.2 s gap in Time at row 4000")]


def test_bomi_split_writes_the_logger_files_two_passes(logger_file, tmp_path, capsys):
    logger_file, _ = logger_file
    assert main(["split", str(logger_file), "--out-dir", str(tmp_path), "--verbose"]) == 0
    printed = capsys.readouterr().out
    assert f"{logger_file}: 2 passes: rows 0-3999, 4000-7999 (a 6.2 s gap in Time at row 4000" in printed
    assert len(read_recording(tmp_path / "calib_pass1.csv")) == 4000 == len(read_recording(tmp_path / "calib_pass2.csv"))


def test_the_published_files_uint8_counter_is_not_a_clock(p1_days, shared_data, tmp_path, capsys):
    day1 = shared_data / "day1_testp.mat"
    assert scipy.io.loadmat(day1)["Time"].dtype == np.uint8
    for rec in p1_days.values():
        assert rec.time is None and "Time" in rec.ignored and pass_bounds(rec) == [PassBounds(0, len(rec))]
    assert main(["split", str(day1), "--out-dir", str(tmp_path), "--verbose"]) == 0
    assert f"{day1}: one pass (no Time clock)" in capsys.readouterr().out
    # a uint8 counter that counts (wrapping every 256 rows) is no clock either
    variables = {k: v for k, v in scipy.io.loadmat(day1).items() if not k.startswith("__")}
    variables["Time"] = (np.arange(len(variables["Etiquette"])) % 256).astype(np.uint8)[:, None]
    counted = tmp_path / "counted.mat"
    scipy.io.savemat(counted, variables)
    assert read_recording(counted).time is None
