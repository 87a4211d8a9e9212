"""Sizes and units of recordings (issue 55 item 6): a size beyond the limit refused before anything is
allocated, a clock that runs backwards, a recording too short to judge and angles in radians each named
in one line (bomi/recording.py, bomi/passes.py)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.io

import bomi.recording
from bomi.errors import BomiError
from bomi.passes import pass_bounds
from bomi.recording import (MAX_RECORDING_ROWS, NodeData, Recording, check_recording_seconds, read_recording,
                            write_recording)
from tasks.cli import main

HEADER = "Time,Pitch1Raw,Roll1Raw,Yaw1Raw,Etiquette\n"
LIMIT = f"more than the {MAX_RECORDING_ROWS} (1.1 h) a recording may have: cut it into shorter recordings"


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("bomi: error: "), err
    return err[0].removeprefix("bomi: error: ")


def never(*_args, **_kwargs):
    raise AssertionError("the file was parsed before its size was checked")


def test_a_csv_over_the_row_limit_is_refused_before_it_is_parsed(tmp_path, capsys, monkeypatch):
    path = tmp_path / "long.csv"
    path.write_text(HEADER + "0.0,1.0,2.0,3.0,0\n" * (MAX_RECORDING_ROWS + 1))
    monkeypatch.setattr(bomi.recording, "_read_csv_variables", never)
    assert main(["twin", str(path), "--out", str(tmp_path / "t.toml")]) == 2
    assert one_error_line(capsys) == f"{path}: {MAX_RECORDING_ROWS + 1} rows (1.1 h at 62.5 Hz), {LIMIT}"
    assert not (tmp_path / "t.toml").exists()
    # at the limit, without a final newline: read (the count is of rows, not of line ends)
    path.write_text(HEADER + "0.0,1.0,2.0,3.0,0\n" * (MAX_RECORDING_ROWS - 1) + "0.0,1.0,2.0,3.0,0")
    monkeypatch.undo()
    assert len(read_recording(path)) == MAX_RECORDING_ROWS


def test_a_mat_over_the_row_limit_is_refused_from_its_headers(tmp_path, monkeypatch):
    path = tmp_path / "long.mat"
    column = np.zeros((MAX_RECORDING_ROWS + 1, 1))
    scipy.io.savemat(path, {"Pitch1Raw": column, "Roll1Raw": column, "Yaw1Raw": column})
    monkeypatch.setattr(bomi.recording, "_read_mat_variables", never)
    with pytest.raises(BomiError, match=f"^{path}: {MAX_RECORDING_ROWS + 1} rows \\(1.1 h at 62.5 Hz\\), more than"):
        read_recording(path)


def test_a_protocol_longer_than_a_recording_may_be_is_refused_before_it_is_performed():
    # 55 runs of an hour (what `bomi synth` ran out of memory on): 198,000 s, 12,375,001 rows
    with pytest.raises(BomiError) as error:
        check_recording_seconds(55 * 3600.0, "me.toml: [protocol]")
    assert str(error.value) == f"me.toml: [protocol]: 12375001 rows (55.0 h at 62.5 Hz), {LIMIT}"
    check_recording_seconds((MAX_RECORDING_ROWS - 1) / 62.5, "fits")       # exactly the limit: accepted


def test_bomi_synth_refuses_a_protocol_of_55_hours_in_one_line(tmp_path, capsys):
    import re
    from tasks.participants.participant import PARTICIPANT_DIR
    text = (PARTICIPANT_DIR / "P1.toml").read_text()
    long = tmp_path / "long.toml"
    long.write_text(re.sub(r"durations_s = \[[^\]]*\]", "durations_s = [" + ", ".join(["3600.0"] * 55) + "]", text))
    assert main(["synth", "--participant", str(long), "--seed", "1", "--out", str(tmp_path / "out.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"bomi: error: {long}: the [protocol] of day1_testp.mat: 12375001 rows (55.0 h at 62.5 Hz), {LIMIT}"
    assert not (tmp_path / "out.csv").exists()


def labelled(rows: int, time: np.ndarray | None = None) -> Recording:
    """Neutral, then class 1 held 20 deg of pitch away, in degrees."""
    labels = (np.arange(rows) >= rows // 2).astype(int)
    angles = np.random.default_rng(0).normal(0.0, 0.5, (rows, 3)) + [40.0, -10.0, 120.0]
    angles[labels == 1, 0] += 20.0
    return Recording({1: NodeData(angles=angles)}, labels, time=time, source="r")


def test_a_clock_running_backwards_is_named_not_read_as_thousands_of_passes(tmp_path, capsys):
    rows = 15381
    path = tmp_path / "back.csv"
    write_recording(path, labelled(rows, time=np.arange(rows)[::-1] * 0.016))
    for command in (["split", str(path), "--out-dir", str(tmp_path / "out")],
                    ["train", str(path), "--out", str(tmp_path / "m.json")]):
        assert main(command) == 2
        assert one_error_line(capsys) == (
            f"{path}: Time runs backwards at 15380 row(s) (at row 1: 246.064 s after 246.080 s): a clock restarts "
            "only between passes of at least 15 s; fix or drop the Time column")
    assert not (tmp_path / "out").exists() and not (tmp_path / "m.json").exists()
    # one restart between two passes of 20 s each is a new pass, not an error
    restarted = labelled(2500, time=np.r_[np.arange(1250), np.arange(1250)] * 0.016)
    assert [(b.start, b.stop) for b in pass_bounds(restarted)] == [(0, 1250), (1250, 2500)]


def test_a_recording_too_short_to_judge_is_said_so_not_called_saturated(tmp_path, capsys):
    path = tmp_path / "ten.csv"
    write_recording(path, labelled(10))
    assert main(["twin", str(path), "--out", str(tmp_path / "t.toml")]) == 2
    line = one_error_line(capsys)
    assert line == (f"{path}: 10 rows, too short to judge: shorter than one second (62 rows at 62.5 Hz), the least that "
                    "holds a posture and its neutral")
    assert "saturated" not in line
    assert len(pass_bounds(labelled(62))) == 1


def test_angles_in_radians_are_named_and_degrees_are_read(tmp_path, capsys, p1_days):
    degrees = labelled(2000)
    radians = replace(degrees, nodes={1: NodeData(angles=np.radians(degrees.nodes[1].angles))})
    path = tmp_path / "radians.csv"
    write_recording(path, radians)
    assert main(["train", str(path), "--out", str(tmp_path / "m.json")]) == 2
    assert one_error_line(capsys) == (
        f"{path}: every angle is within +-3.14 and the classes' postures differ by at most 0.35: the angles look "
        "like radians; a recording's angles are degrees (multiply by 57.30)")
    write_recording(tmp_path / "degrees.csv", degrees)
    assert len(read_recording(tmp_path / "degrees.csv")) == 2000
    # P1's real days in radians too (every yaw within +-pi), and as published (degrees) read
    day = p1_days[2]
    in_radians = tmp_path / "day2_radians.csv"
    write_recording(in_radians, replace(day, nodes={i: NodeData(angles=np.radians(d.angles)) for i, d in day.nodes.items()}))
    with pytest.raises(BomiError, match="the angles look like radians"):
        read_recording(in_radians)
    assert math.pi < max(float(np.max(np.abs(d.angles))) for d in day.nodes.values())
