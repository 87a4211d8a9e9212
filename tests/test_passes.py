"""Passes of the protocol found in a recording (bomi/passes.py) and every command that reads one."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from bomi.chain import evaluate, leave_one_pass_out, train
from bomi.derived import derive_profile
from bomi.fusion import HEADSET_MOUNTING, IDENTITY, NodeCalibration, angle_disagreement, fuse, fused_recording, mounting_warnings
from bomi.model_io import load_model
from bomi.profiles import save_profile
from bomi.logger_layout import write_logger_passes
from bomi.passes import (PassBounds, cut, in_sample_share, join, pass_bounds, passes_text, split_passes,
                         training_digests)
from bomi.recording import NodeData, Recording, read_recording, write_logger_mat, write_recording
from tasks.cli import main
from tasks.experiments.training import most_confused
from tasks.experiments.twins import self_check
from tasks.stacking.channels import profile_controls
from tasks.participants.participant import load_participant
from tasks.participants.population import PASS_GAP_S, draw_person, pass_recordings
from tasks.operators.stick import arm_profile

PERSON = 5   # six head motions and the neutral posture, one node (bomi.logger_layout writes its two passes in the logger layout)
DT = 0.016


def clocked(time: np.ndarray, labels: np.ndarray | None = None) -> Recording:
    n = len(time)
    labels = np.zeros(n, int) if labels is None else labels
    return Recording({1: NodeData(angles=np.arange(3 * n, dtype=float).reshape(n, 3))}, labels, time=time, source="r")


def test_a_pause_is_a_new_pass_only_well_beyond_the_moves_and_the_lost_samples():
    # continuous: 1000 rows, 6.2 s pause, 1000 rows; two lost samples (a 0.048 s step) inside
    time = np.r_[np.arange(1000) * DT, 999 * DT + 6.2 + np.arange(1000) * DT]
    time[400:] += 2 * DT
    assert pass_bounds(clocked(time)) == [PassBounds(0, 1000), PassBounds(1000, 2000, "a 6.2 s gap in Time at row 1000")]
    # holds only: a 2.0 s pause at every move (rows 300, 600, 900, 1300) is no pass; 6.2 s (row 1000) is
    steps = np.full(1999, DT)
    steps[[299, 599, 899, 1299]] = 2.0
    steps[999] = 6.2
    bounds = pass_bounds(clocked(np.r_[0.0, np.cumsum(steps)]))
    assert [(b.start, b.stop) for b in bounds] == [(0, 1000), (1000, 2000)]
    # 3.9 s is more than PASS_GAP_S but not twice the moves' 2.0 s: one pass
    steps[999] = 3.9
    assert len(pass_bounds(clocked(np.r_[0.0, np.cumsum(steps)]))) == 1
    # a restarted clock; no clock at all
    restarted = pass_bounds(clocked(np.r_[np.arange(1700) * DT, np.arange(1000) * DT]))
    assert [(b.start, b.stop, b.cause) for b in restarted] == [(0, 1700, None), (1700, 2700, "the clock restarts at row 1700")]
    assert pass_bounds(replace(clocked(time), time=None)) == [PassBounds(0, 2000)]


def test_a_pause_with_fewer_rows_than_a_pass_beside_it_is_no_boundary():
    # the logger's start: one row (or 900, 14.4 s), a 3 s pause, then the pass; a pause 900 rows before the end
    for lead in (1, 900):
        time = np.r_[np.arange(lead) * DT, (lead - 1) * DT + 3.0 + np.arange(2000) * DT]
        assert pass_bounds(clocked(time)) == [PassBounds(0, lead + 2000)]
    time = np.r_[np.arange(2000) * DT, 1999 * DT + 6.2 + np.arange(900) * DT]
    assert pass_bounds(clocked(time)) == [PassBounds(0, 2900)]
    # 938 rows (15.0 s at 62.5 Hz) on each side are a pass
    time = np.r_[np.arange(938) * DT, 937 * DT + 6.2 + np.arange(938) * DT]
    assert pass_bounds(clocked(time)) == [PassBounds(0, 938), PassBounds(938, 1876, "a 6.2 s gap in Time at row 938")]


@pytest.fixture(scope="module")
def two_pass_file(tmp_path_factory):
    """A synthetic person's two passes in one .mat, as the original logger writes it (bomi.logger_layout:
    int32 ms Time, a 3 s pause after the first row, 6.2 s between the passes); the first 5000 rows of
    each pass (every motion held at least once)."""
    path = tmp_path_factory.mktemp("person") / "me.mat"
    write_logger_passes(path, [cut(p, PassBounds(0, 5000), p.source) for p in pass_recordings(draw_person(PERSON))])
    return path


def test_a_logger_file_of_two_passes_is_split_where_its_clock_pauses(two_pass_file):
    rec = read_recording(two_pass_file)
    assert rec.node_indices == (1,) and sorted(set(rec.labels.tolist())) == list(range(7))
    boundary = int(np.flatnonzero(np.diff(rec.time) > PASS_GAP_S - 0.01)[0]) + 1
    bounds = pass_bounds(rec)
    assert [(b.start, b.stop) for b in bounds] == [(0, boundary), (boundary, len(rec))]
    assert passes_text(rec, bounds) == (
        f"{two_pass_file}: 2 passes: rows 0-{boundary - 1}, {boundary}-{len(rec) - 1} (a 6.2 s gap in Time at row {boundary}; the "
        "same class sequence in each): each is calibrated and counted as one pass")
    first, second = split_passes(rec, bounds)
    assert first.source == f"{two_pass_file} pass 1 (rows 0-{boundary - 1})" and len(second) == len(rec) - boundary
    back = join([first, second], rec.source)
    assert np.array_equal(back.nodes[1].angles, rec.nodes[1].angles) and np.array_equal(back.labels, rec.labels)


def test_leave_one_pass_out_is_each_pass_decided_by_the_other_and_in_sample_is_said(two_pass_file):
    first, second = split_passes(rec := read_recording(two_pass_file), pass_bounds(rec))
    profile = replace(derive_profile([first, second]), shrinkage=None, select_rejection=False, amplitude_scales=())
    model = train([first, second], profile)
    out = leave_one_pass_out([first, second], profile, model)
    by_hand = [evaluate(train([second], profile), first, 100), evaluate(train([first], profile), second, 100)]
    for ours, theirs in zip(out.evaluations, by_hand):
        assert np.array_equal(ours.predicted, theirs.predicted)
    windows = [len(ev.truth) for ev in by_hand]
    assert out.accuracy == pytest.approx(sum(ev.accuracy * n for ev, n in zip(by_hand, windows)) / sum(windows))
    # the model knows the runs it was trained on: all of both passes, none of a pass it never saw
    assert in_sample_share(first, model.training_runs) == 1.0 == in_sample_share(second, model.training_runs)
    assert in_sample_share(second, training_digests([first])) == 0.0
    # trained on pass 1's first 4000 rows: its runs that end before row 4000, and no row of pass 2
    partly = replace(first, nodes={1: NodeData(angles=first.nodes[1].angles[:4000])}, labels=first.labels[:4000])
    run_ends = np.flatnonzero(np.diff(first.labels)) + 1
    assert in_sample_share(first, training_digests([partly])) == run_ends[run_ends < 4000][-1] / len(first)
    assert in_sample_share(second, training_digests([partly])) == 0.0


@pytest.fixture(scope="module")
def fixed_profile(two_pass_file, tmp_path_factory):
    """The derived profile with the classifier settings fixed (no selection: the CLI tests stay fast)."""
    path = tmp_path_factory.mktemp("profile") / "me.toml"
    rec = read_recording(two_pass_file)
    save_profile(path, replace(derive_profile([rec]), shrinkage=None, select_rejection=False, amplitude_scales=()))
    return path


def test_train_and_evaluate_on_a_two_pass_file(two_pass_file, fixed_profile, tmp_path, capsys):
    model_path = tmp_path / "m.json"
    assert main(["train", str(two_pass_file), "--out", str(model_path), "--profile", str(fixed_profile)]) == 0
    printed = capsys.readouterr().out
    assert f"{two_pass_file}: 2 passes: rows 0-" in printed
    assert "how good is this classifier: leave-one-pass-out accuracy " in printed
    assert "trained FV3 LDA on 2 pass(es) of 1 recording(s)" in printed
    assert len(load_model(model_path).training_runs) > 20
    assert main(["evaluate", "--train", str(model_path), "--test", str(two_pass_file),
                 "--png", str(tmp_path / "c.png")]) == 0
    assert capsys.readouterr().out.count("IN-SAMPLE: the model was trained on these rows") == 2


def test_split_writes_the_passes_and_a_model_of_one_is_out_of_sample_on_the_other(two_pass_file, fixed_profile,
                                                                                  tmp_path, capsys):
    out_dir = tmp_path / "passes"
    assert main(["split", str(two_pass_file), "--out-dir", str(out_dir)]) == 0
    pass1, pass2 = out_dir / "me_pass1.csv", out_dir / "me_pass2.csv"
    rec = read_recording(two_pass_file)
    assert read_recording(pass2).labels.tolist() == split_passes(rec, pass_bounds(rec))[1].labels.tolist()
    assert main(["split", str(two_pass_file), "--out-dir", str(out_dir)]) == 2   # nothing replaced unasked
    assert capsys.readouterr().err == f"bomi: error: {pass1}: file exists, not overwriting it (use --force to replace it)\n"
    model, record = tmp_path / "one.json", tmp_path / "e.json"
    assert main(["train", str(pass1), "--out", str(model), "--profile", str(fixed_profile)]) == 0
    assert main(["evaluate", "--train", str(model), "--test", str(pass2), "--test", str(pass1),
                 "--json", str(record), "--png", str(tmp_path / "c.png")]) == 0
    shares = [r["in_sample_share"] for r in json.loads(record.read_text())["results"]]
    assert shares == [0.0, 1.0] and capsys.readouterr().out.count("IN-SAMPLE") == 1


def test_passes_of_different_class_sets_are_one_error_line(two_pass_file, tmp_path, capsys):
    rec = read_recording(two_pass_file)
    boundary = pass_bounds(rec)[1].start
    labels = rec.labels.copy()
    labels[boundary:][labels[boundary:] == 6] = 0   # pass 2 never holds c6
    bad = tmp_path / "bad.mat"
    write_logger_mat(bad, replace(rec, labels=labels))
    assert main(["train", str(bad), "--out", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("bomi: error: passes of different class sets in one file (")
    assert f"{bad} pass 2 (rows {boundary}-{len(rec) - 1}): c0, c1, c2, c3, c4, c5)" in err[0]
    assert not (tmp_path / "m.json").exists()


def test_fuse_starts_each_pass_afresh_and_says_when_the_mounting_disagrees(p1_days, tmp_path, capsys):
    day = p1_days[1]
    node = NodeData(**{s: getattr(day.nodes[1], s)[:2000] for s in ("acc", "gyro", "mag", "angles")})
    time = np.r_[np.arange(1000) * DT, 999 * DT + 10.0 + np.arange(1000) * DT]
    rec = Recording({1: node}, day.labels[:2000], time=time, source="two")
    headset = NodeCalibration.default_for(1)
    fused = join([fused_recording(p, {1: headset}) for p in split_passes(rec, pass_bounds(rec))], "two")
    alone = np.column_stack(fuse(node.acc[1000:], node.gyro[1000:], node.mag[1000:], headset))
    np.testing.assert_allclose(fused.nodes[1].angles[1000:], alone, atol=1e-9)   # same kernel, same rows
    # P1's own angle columns are not in the headset's mounting (~90 deg apart): said, and the one that agrees offered
    warning, = mounting_warnings(rec, fused, {1: headset})
    assert "node 1: the fused angles differ from the file's own angle columns by a median" in warning
    offered = eval(warning.split("; mounting = ")[1].split(" agrees")[0])
    again = fused_recording(rec, {1: replace(headset, mounting=tuple(map(tuple, offered)))})
    assert angle_disagreement(node.angles, again.nodes[1].angles).max() < 10.0
    assert mounting_warnings(rec, again, {1: replace(headset, mounting=tuple(map(tuple, offered)))}) == []
    path = tmp_path / "two.mat"
    write_logger_mat(path, rec)
    assert main(["fuse", str(path), "--out", str(tmp_path / "f.csv")]) == 0
    printed = capsys.readouterr().out
    assert f"{path}: 2 passes: rows 0-999, 1000-1999 (a 10.0 s gap in Time at row 1000" in printed
    assert "fused from its own start" in printed and "warning: " in printed


def test_most_confused_names_the_largest_confusions_by_hand():
    truth = np.array([1] * 10 + [2] * 10 + [3] * 10)
    decided = np.array([1] * 6 + [2] * 4 + [2] * 9 + [1] + [3] * 10)
    # c1 read as c2 in 4 of 10, c2 as c1 in 1 of 10 (10 %), c3 never wrong
    assert most_confused(truth, decided) == [(1, 2, 0.4), (2, 1, 0.1)]


def test_train_warns_below_the_threshold_and_names_the_confused_classes(tmp_path, capsys):
    # c2 is held in c1's posture: the two cannot be told apart
    labels = np.concatenate([np.zeros(150, int)] + [np.repeat([k, 0], [100, 40]) for _ in range(3) for k in (1, 2, 3)])
    rng = np.random.default_rng(1)
    angles = rng.normal(0.0, 1.0, (len(labels), 3))
    angles[labels == 1] += [20.0, 0.0, 0.0]
    angles[labels == 2] += [20.0, 0.0, 0.0]
    angles[labels == 3] += [0.0, 20.0, 0.0]
    path = tmp_path / "alike.csv"
    write_recording(path, Recording({1: NodeData(angles=angles)}, labels, source="alike"))
    assert main(["train", str(path), "--out", str(tmp_path / "m.json")]) == 0
    printed = capsys.readouterr().out
    headline = next(line for line in printed.splitlines() if line.startswith("how good is this classifier"))
    accuracy = float(headline.split("cross-validated accuracy ")[1].split(" %")[0])
    assert accuracy < 85.0
    warning = next(line for line in printed.splitlines() if line.startswith("warning: accuracy"))
    assert "is below 85 %" in warning and ("c1 read as c2" in warning or "c2 read as c1" in warning)


def test_a_derived_profile_takes_the_mounting_its_recording_agrees_with(p1_days):
    # P1's published angle columns are in the sensor's own axes, 90 deg from the headset mounting
    day = p1_days[1]
    signals = ("acc", "gyro", "mag", "angles")
    head = Recording({1: NodeData(**{s: getattr(day.nodes[1], s)[:6000] for s in signals})}, day.labels[:6000],
                     source="head")
    assert derive_profile([head]).nodes[0].calibration.mounting == IDENTITY
    angles_only = Recording({1: NodeData(angles=head.nodes[1].angles)}, head.labels, source="angles")
    assert derive_profile([angles_only]).nodes[0].calibration.mounting == HEADSET_MOUNTING


def test_the_twin_of_a_two_pass_file_counts_two_passes_and_its_profile_drives_the_task(two_pass_file, tmp_path,
                                                                                        capsys):
    out = tmp_path / "me_twin.toml"
    assert main(["twin", str(two_pass_file), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"{two_pass_file}: 2 passes: rows 0-" in printed and "2 pass(es)" in printed
    assert "layout 2-axis (6 motions" in printed
    params = load_participant(out)
    controls = profile_controls(arm_profile(params.profile))   # what `bomi benchmark` checks before any episode
    assert controls.layout.name == "2-axis" and controls.buttons == ("B1", "B2")
    assert params.provenance["day_std_deg"].startswith("measured")   # drift measured between the two passes
    # the self-check: the twin's calibration reads as the person's (100 % here), said in one line
    check = next(line for line in printed.splitlines() if "self-check:" in line)
    assert check.startswith("self-check: the twin's calibration reads ")
    # against a person whose postures cannot be told apart (every label's rows moved to the neutral
    # posture's levels: a CV near the neutral share), the two are far apart: a warning
    rec = read_recording(two_pass_file)
    noise = np.random.default_rng(0).normal(0.0, 1.0, (len(rec), 3))
    flat = replace(rec, nodes={1: replace(rec.nodes[1], angles=noise)})
    warning = self_check(out, split_passes(flat, pass_bounds(flat)), arm_profile(params.profile))
    assert warning.startswith("warning: self-check: ") and "more than 10 points apart" in warning


@pytest.mark.long
def test_the_new_person_path_end_to_end_twin_design_benchmark_train(two_pass_file, tmp_path, capsys):
    """docs/start_here.md's commands, in order, on the six-motion two-pass file, no edit: each exits 0
    and hands the next what it needs (short episodes: the path, not the success, is under test)."""
    twin, best, design = tmp_path / "me_twin.toml", tmp_path / "best.toml", tmp_path / "design.json"
    assert main(["twin", str(two_pass_file), "--out", str(twin), "--no-check"]) == 0
    assert main(["design", str(twin), "--seeds", "1", "--time-limit", "5", "--jobs", "1", "--out", str(best),
                 "--json", str(design)]) == 0
    chosen = json.loads(design.read_text())
    assert len(chosen["candidates"]) >= 2 and all(c["episodes"] == 1 for c in chosen["candidates"])
    # one seed can show no candidate better than the default beyond chance: the default is written
    assert chosen["recommended"] == chosen["candidates"][0]["name"] and "no candidate beat" in chosen["reason"]
    assert main(["twin", str(two_pass_file), "--profile", str(best), "--out", str(twin), "--force", "--no-check"]) == 0
    out = tmp_path / "benchmark.json"
    assert main(["benchmark", "--participants", str(twin), "--operators", "bomi", "--seeds", "1", "--time-limit", "5",
                 "--jobs", "1", "--json", str(out)]) == 0
    (episode,) = json.loads(out.read_text())["episodes"]
    assert episode["participant"] == str(twin) and episode["layout"] == "2-axis, B1+B2"
    assert episode["failure"] == "time limit 5 s" and episode["sim_time"] == pytest.approx(5.0, abs=0.02)
    assert episode["decisions"] > 200   # the chain decided all along (5 s at 62.5 Hz: about 300 windows)
    assert main(["train", str(two_pass_file), "--profile", str(best), "--out", str(tmp_path / "me.json")]) == 0
    assert "2 passes" in capsys.readouterr().out
