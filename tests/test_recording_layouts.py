"""Every published recording layout, extra variables of any type, and one line per missing column."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.io

from bomi.errors import BomiError
from bomi.recording import RAW_SIGNALS, NodeData, Recording, Signal, node_columns, read_recording, write_recording

N = 300


@pytest.fixture(scope="module")
def day1(shared_data):
    return read_recording(shared_data / "day1_testp.mat")


def logger_variables(rec: Recording, node: int = 1, rows: slice = slice(0, N)) -> dict:
    """One node in the original host software's logger naming (no index) plus its other variables."""
    n = rows.stop - rows.start
    columns = {name: getattr(rec.nodes[node], signal.value)[rows, k][:, None]
               for signal, names in node_columns(None).items() for k, name in enumerate(names)}
    extras = {"Time": np.arange(n)[:, None] / 62.5, "Commands": np.zeros((n, 3)), "ArmCoordinates": np.ones((n, 6)),
              "Features": np.zeros((n, 16)), "Gain": np.array([[2.5]]), "Operator": "latyr",
              "Notes": np.array([["a"], ["bc"]], dtype=object), "Settings": {"rate": 62.5, "mode": "ctrl"}}
    return {**columns, "Etiquette": rec.labels[rows][:, None], **extras}


def test_logger_mat_single_node_without_index(tmp_path, day1):
    path = tmp_path / "logger.mat"
    scipy.io.savemat(path, logger_variables(day1))
    rec = read_recording(path)
    assert rec.node_indices == (1,) and len(rec) == N
    np.testing.assert_array_equal(rec.time, np.arange(N) / 62.5)   # the logger's clock, floating-point seconds
    for signal in Signal:
        assert np.array_equal(getattr(rec.nodes[1], signal.value), getattr(day1.nodes[1], signal.value)[:N])
    assert np.array_equal(rec.labels, day1.labels[:N])
    assert sorted(rec.ignored) == ["ArmCoordinates", "Commands", "Features", "Gain", "Notes", "Operator",
                                   "Settings"]


def partial(rec: Recording, nodes: dict[int, tuple[Signal, ...]], rows: int = N, labelled: bool = True) -> Recording:
    return Recording(nodes={i: NodeData(**{s.value: getattr(rec.nodes[i], s.value)[:rows] for s in signals})
                            for i, signals in nodes.items()},
                     labels=rec.labels[:rows] if labelled else None, time=np.arange(rows) / 62.5)


@pytest.mark.parametrize("nodes", [
    {1: (Signal.ANGLES, Signal.GYRO)},                       # what FV1-FV3 use
    {2: RAW_SIGNALS},                                        # raw only (fuse computes the angles)
    {1: (Signal.ANGLES,), 3: tuple(Signal)},                 # any subset of nodes and signals
    {2: (Signal.GYRO,), 3: (Signal.MAG, Signal.ANGLES)},
])
def test_csv_round_trip_of_any_subset(tmp_path, day1, nodes):
    rec = partial(day1, nodes)
    path = tmp_path / "rec.csv"
    write_recording(path, rec)
    back = read_recording(path)
    assert back.node_indices == tuple(sorted(nodes)) and back.ignored == ()
    for i, signals in nodes.items():
        assert set(back.nodes[i].signals) == set(signals)
        for s in signals:
            assert np.array_equal(getattr(back.nodes[i], s.value), getattr(rec.nodes[i], s.value))
    assert np.array_equal(back.labels, rec.labels) and np.array_equal(back.time, rec.time)


def test_csv_extra_columns_of_any_type_are_ignored(tmp_path, day1):
    rec = partial(day1, {1: (Signal.ANGLES, Signal.GYRO)}, rows=3)
    path = tmp_path / "rec.csv"
    write_recording(path, rec)
    lines = path.read_text().splitlines()
    lines[0] = lines[0].replace("Time", "Time,Command,Comment") + ",ArmX"
    lines[1:] = [line.replace(",", ",F,hello world,", 1) + ",0.25" for line in lines[1:]]
    path.write_text("\n".join(lines) + "\n")
    back = read_recording(path)
    assert sorted(back.ignored) == ["ArmX", "Command", "Comment"]
    assert np.array_equal(back.nodes[1].gyro, rec.nodes[1].gyro) and np.array_equal(back.time, rec.time)
    # a clock the chain cannot read is ignored, not an error
    path.write_text(path.read_text().replace("\n0.0,", "\n12:00:01,", 1))
    assert read_recording(path).time is None and "Time" in read_recording(path).ignored


def mat_with(tmp_path, variables: dict):
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, variables)
    return path


@pytest.mark.parametrize("edit, message", [
    (lambda v: v.pop("ACCZ"), "node 1 ACC is incomplete, column ACCZ is missing"),
    (lambda v: [v.pop("PitchRaw"), v.pop("YawRaw")], "node 1 angles is incomplete, column PitchRaw, YawRaw are missing"),
    (lambda v: v.update(GYRO1X=v["GYROX"]), "both GYROX and GYRO1X are present (node 1 given twice)"),
    (lambda v: v.update(MAGY=np.array(["abc"])), "variable MAGY is not numeric"),
    (lambda v: v.update(ACCX=np.ones((N, 2))), "variable ACCX is not a single column (shape (300, 2))"),
    (lambda v: v.update(RollRaw=np.ones((N - 1, 1))), "column RollRaw has 299 rows"),
    (lambda v: v.update(Etiquette=np.full((N, 1), 0.5)), "Etiquette, row 1: 0.5 is not a class label"),
    (lambda v: [v.pop(k) for k in list(v) if k not in ("Time", "Commands")], "no IMU node columns"),
])
def test_malformed_logger_mat_is_one_line(tmp_path, day1, edit, message):
    variables = logger_variables(day1)
    edit(variables)
    path = mat_with(tmp_path, variables)
    with pytest.raises(BomiError) as info:
        read_recording(path)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value) and "\n" not in str(info.value)


def test_require_names_what_is_missing(day1):
    rec = partial(day1, {1: (Signal.ANGLES, Signal.GYRO), 2: RAW_SIGNALS})
    rec.source = "r.csv"
    rec.require([1], (Signal.ANGLES, Signal.GYRO), "FV3")      # present: no error
    with pytest.raises(BomiError) as info:
        rec.require([1, 2], RAW_SIGNALS, "fuse")
    assert str(info.value) == ("r.csv: fuse needs ACC, GYRO, MAG of node(s) [1, 2]; missing "
                               "ACC1X, ACC1Y, ACC1Z, MAG1X, MAG1Y, MAG1Z")
    with pytest.raises(BomiError) as info:
        rec.require([2, 3], (Signal.ANGLES,), "a FV1 model")
    assert str(info.value) == ("r.csv: a FV1 model needs angles of node(s) [2, 3]; missing "
                               "Pitch2Raw, Roll2Raw, Yaw2Raw, node 3 (none of its columns)")
    with pytest.raises(BomiError, match=r"missing Pitch2Raw, Roll2Raw, Yaw2Raw \(it has raw ACC/GYRO/MAG: `bomi fuse`"):
        rec.require([2], (Signal.ANGLES,), "a FV1 model")


def test_fuse_reads_raw_only_and_names_what_it_lacks(tmp_path, capsys, day1):
    from tasks.cli import main
    raw, angles, out = tmp_path / "raw.csv", tmp_path / "angles.csv", tmp_path / "out.csv"
    write_recording(raw, partial(day1, {2: RAW_SIGNALS}))
    write_recording(angles, partial(day1, {1: (Signal.ANGLES, Signal.GYRO)}))
    assert main(["fuse", str(raw), "--out", str(out), "--verbose"]) == 0
    fused = read_recording(out)                       # round trip: fuse's output is a recording again
    assert fused.nodes[2].signals == tuple(Signal) and np.all(np.isfinite(fused.nodes[2].angles))
    assert f"{raw}: {N} samples; node 2: ACC, GYRO, MAG;" in capsys.readouterr().out
    assert main(["fuse", str(angles), "--out", str(tmp_path / "o2.csv")]) == 2
    assert main(["train", str(raw), "--profile", "P1", "--out", str(tmp_path / "m.json")]) == 2
    errors = capsys.readouterr().err.splitlines()
    assert errors[0] == (f"bomi: error: {angles}: fuse needs ACC, GYRO, MAG of node(s) [1]; missing "
                         "ACC1X, ACC1Y, ACC1Z, MAG1X, MAG1Y, MAG1Z")
    assert errors[1].startswith(f"bomi: error: {raw}: a FV3 model needs angles, GYRO of node(s) [1, 2, 3]; missing ")
    assert not (tmp_path / "o2.csv").exists() and not (tmp_path / "m.json").exists()


def test_verbose_lists_the_ignored_variables(tmp_path, capsys, day1):
    from tasks.cli import main
    path = tmp_path / "logger.mat"
    scipy.io.savemat(path, logger_variables(day1))
    assert main(["fuse", str(path), "--out", str(tmp_path / "f.csv"), "--verbose"]) == 0
    printed = capsys.readouterr().out
    assert (f"{path}: ignored 7 variable(s): Commands, ArmCoordinates, Features, Gain, Operator, Notes, "
            "Settings") in printed
