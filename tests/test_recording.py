"""Recordings: the published .mat files, the project's CSV, incremental writing, and clear errors."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.io

from tasks.cli import main
from bomi.errors import BomiError
from bomi.recording import NodeData, NodeSample, Recording, RecordingWriter, read_recording, write_recording


def small_recording(n=20, nodes=(1, 3), labelled=True, seed=0) -> Recording:
    rng = np.random.default_rng(seed)
    data = {i: NodeData(acc=rng.integers(-16000, 16000, (n, 3)).astype(float),
                        gyro=rng.integers(-300, 300, (n, 3)).astype(float),
                        mag=rng.normal(size=(n, 3)), angles=rng.normal(scale=20, size=(n, 3))) for i in nodes}
    labels = np.repeat(np.arange(4), n // 4 + 1)[:n] if labelled else None
    return Recording(nodes=data, labels=labels, time=np.arange(n) / 62.5)


def test_published_mat_matches_scipy_columns(shared_data):
    path = shared_data / "day1_testp.mat"
    raw = scipy.io.loadmat(path)
    rec = read_recording(path)
    assert rec.node_indices == (1, 2, 3) and len(rec) == 16555 and rec.time is None
    assert np.array_equal(rec.nodes[2].angles[:, 1], raw["Roll2Raw"][:, 0])
    assert np.array_equal(rec.nodes[3].gyro[:, 2], raw["GYRO3Z"][:, 0])
    assert np.array_equal(rec.nodes[1].mag[:, 0], raw["MAG1X"][:, 0])
    assert np.array_equal(rec.labels, raw["Etiquette"][:, 0]) and set(rec.labels.tolist()) == set(range(9))


def test_csv_round_trip_is_exact(tmp_path):
    rec = small_recording()
    path = tmp_path / "rec.csv"
    write_recording(path, rec)
    back = read_recording(path)
    assert back.node_indices == (1, 3)
    for i in rec.nodes:
        for signal in ("acc", "gyro", "mag", "angles"):
            assert np.array_equal(getattr(back.nodes[i], signal), getattr(rec.nodes[i], signal))
    assert np.array_equal(back.labels, rec.labels) and np.array_equal(back.time, rec.time)
    header = path.read_text().splitlines()[0].split(",")
    assert header[:4] == ["Time", "Pitch1Raw", "Roll1Raw", "Yaw1Raw"] and header[-1] == "Etiquette"
    assert "ACC3Z" in header and "GYRO2X" not in header
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_csv_with_byte_order_mark_and_spaces(tmp_path):
    path = tmp_path / "excel.csv"
    path.write_text("\ufeff" + GOOD_HEADER + "\n" + row().replace(",2,", ", 2 ,"), encoding="utf-8")
    rec = read_recording(path)
    assert rec.time.tolist() == [0.0] and rec.nodes[2].angles.tolist() == [[1.0, 2.0, 3.0]]


def test_csv_without_labels_or_time(tmp_path):
    rec = small_recording(labelled=False)
    rec.time = None
    path = tmp_path / "rec.csv"
    write_recording(path, rec)
    back = read_recording(path)
    assert back.labels is None and np.allclose(back.time, np.arange(len(rec)) / 62.5)
    with pytest.raises(BomiError, match="rec.csv: no Etiquette column"):
        back.require_labels()


def write_csv(tmp_path, text: str):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    return path


GOOD_HEADER = "Time," + ",".join(f"{a}2Raw" for a in ("Pitch", "Roll", "Yaw")) + "," + ",".join(
    f"{s}2{x}" for s in ("ACC", "GYRO", "MAG") for x in "XYZ") + ",Etiquette"


def row(acc_x: str = "1", label: str = "0", cells: int = 14) -> str:
    values = ["0.0", "1", "2", "3", acc_x] + ["1"] * 8 + [label]
    return ",".join(values[:cells]) + "\n"


@pytest.mark.parametrize("text, message", [
    ("", "empty file"),
    (GOOD_HEADER + "\n", "no samples"),
    (GOOD_HEADER.replace(",MAG2Z", "") + "\n" + row(cells=13), "column MAG2Z is missing"),
    (GOOD_HEADER + "\n" + row(acc_x="abc"), "column ACC2X, line 2: not a number ('abc')"),
    (GOOD_HEADER + "\n" + row(acc_x="nan"), "column ACC2X has a missing/NaN/inf value at row 1"),
    (GOOD_HEADER + "\n" + row(acc_x=""), "column ACC2X, line 2: not a number"),
    (GOOD_HEADER + "\n" + row() + row(cells=13), "line 3 has 13 cells, the header has 14"),
    (GOOD_HEADER + "\n" + row(label="1.5"), "Etiquette, row 1: 1.5 is not a class label"),
    ("Time,Foo\n1,2\n", "no IMU node columns"),
])
def test_malformed_csv_names_file_and_column(tmp_path, text, message):
    path = write_csv(tmp_path, text)
    with pytest.raises(BomiError) as info:
        read_recording(path)
    assert str(path) in str(info.value) and message in str(info.value)


def test_malformed_mat(tmp_path):
    columns = {name: np.ones((5, 1)) for name in GOOD_HEADER.split(",")}
    columns["GYRO2Y"] = np.ones((4, 1))
    scipy.io.savemat(tmp_path / "short.mat", columns)
    with pytest.raises(BomiError, match=r"short\.mat: column GYRO2Y has 4 rows"):
        read_recording(tmp_path / "short.mat")
    columns["GYRO2Y"] = np.array(["abcde"])
    scipy.io.savemat(tmp_path / "text.mat", columns)
    with pytest.raises(BomiError, match=r"text\.mat: variable GYRO2Y is not numeric"):
        read_recording(tmp_path / "text.mat")
    (tmp_path / "garbage.mat").write_bytes(b"\x00garbage" * 10)
    with pytest.raises(BomiError, match=r"garbage\.mat: not a readable MATLAB v5 file"):
        read_recording(tmp_path / "garbage.mat")
    with pytest.raises(BomiError, match="unknown recording format"):
        read_recording(write_csv(tmp_path, "x").rename(tmp_path / "x.txt"))


def sample(k: float) -> NodeSample:
    return NodeSample(acc=(k, 2 * k, 3 * k), gyro=(-k, 0, k), mag=(0.5, 0.25, k), angles=(k / 10, 1.0, -2.0))


def test_recording_writer_flushes_whole_segments(tmp_path):
    path = tmp_path / "live.csv"
    with RecordingWriter(path, [2, 1], segment_rows=3) as writer:
        for k in range(7):
            writer.append(k / 62.5, {1: sample(k), 2: sample(-k)}, label=k % 2)
        on_disk = read_recording(path)       # mid-capture: only whole segments are there
        assert len(on_disk) == 6 and writer.rows_written == 6
    rec = read_recording(path)
    assert len(rec) == 7 and rec.node_indices == (1, 2)
    assert np.array_equal(rec.nodes[1].acc[:, 1], 2.0 * np.arange(7))
    assert np.array_equal(rec.nodes[2].angles[:, 0], -np.arange(7) / 10)
    assert rec.labels.tolist() == [0, 1, 0, 1, 0, 1, 0]


def test_recording_writer_interrupted_leaves_valid_file(tmp_path):
    path = tmp_path / "live.csv"
    with pytest.raises(KeyboardInterrupt):
        with RecordingWriter(path, [1], labelled=False, segment_rows=100) as writer:
            for k in range(5):
                writer.append(k / 62.5, {1: sample(k)})
            raise KeyboardInterrupt
    rec = read_recording(path)
    assert len(rec) == 5 and rec.labels is None
    with pytest.raises(BomiError, match="file exists, not overwriting"):
        RecordingWriter(path, [1])
    assert len(read_recording(path)) == 5


def test_cli_error_is_one_line_and_nothing_is_written(tmp_path, capsys):
    bad = write_csv(tmp_path, GOOD_HEADER + "\n" + row() + row(acc_x="x"))
    out = tmp_path / "out.csv"
    out.write_text("keep me")
    assert main(["fuse", str(bad), "--out", str(out), "--force"]) == 2  # even when allowed to replace it
    err = capsys.readouterr().err
    assert err.startswith("bomi: error: ") and err.count("\n") == 1 and "bad.csv" in err and "ACC2X" in err
    assert out.read_text() == "keep me"
