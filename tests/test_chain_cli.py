"""Batch chain == streaming chain on real recordings; the train/evaluate/fuse commands; the FV3 bar."""
from __future__ import annotations

import json
import os
from dataclasses import replace

import numpy as np
import pytest

from bomi.chain import (OnlineChain, evaluate, hold_folds, node_states, prepare, recording_neutral, select_settings,
                        window_features)
from bomi import paper
from bomi.classifier import PostProcessing, classify_windows
from tasks.cli import main
from bomi.fusion import NodeCalibration, fused_recording
from bomi.model_io import load_model
from bomi.recording import NodeData, Recording, read_recording, write_recording


def replay(chain: OnlineChain, rec: Recording, nodes) -> list:
    """Row by row; the other nodes first, so node 1's tick sees the same row (as the batch form)."""
    decisions = []
    order = list(nodes[1:]) + [nodes[0]]
    for k in range(len(rec)):
        for node in order:
            d = chain.push_angles(node, rec.nodes[node].angles[k], rec.nodes[node].gyro[k])
        decisions.append(d)
    return decisions


@pytest.mark.parametrize("post", [PostProcessing(), PostProcessing(rejection_threshold=0.9999, vote_length=5)])
def test_streaming_equals_batch_on_a_real_recording(p1_days, p1_profile, day1_fv3_model, post):
    rec = p1_days[3]
    model = day1_fv3_model
    model_with_post = replace(model, post=post)
    chain = OnlineChain(model_with_post, p1_profile)
    neutral = recording_neutral(rec, model.spec.nodes, p1_profile.neutral_samples)
    chain.set_neutral({node: neutral[k] for k, node in enumerate(model.spec.nodes)})
    streamed = replay(chain, rec, model.spec.nodes)
    assert streamed[:7] == [None] * 7 and all(d is not None for d in streamed[7:])
    streamed = streamed[7:]

    prepared = prepare(rec, model.spec, p1_profile.neutral_samples)
    batch = classify_windows(model, prepared.features, post)
    assert [d.sample_index for d in streamed] == prepared.ends.tolist()
    assert [d.label for d in streamed] == batch.labels.tolist()
    assert [d.rejected for d in streamed] == batch.rejected.tolist()
    assert np.allclose([d.confidence for d in streamed], batch.confidence, rtol=0, atol=1e-12)
    # proportional output: P1's amplitude is the class node's angle change along the class's mean
    # direction at the tick (by hand: a dot product), nu within [0, 1]
    d = next(d for d in streamed if d.label == 7)
    direction = model.amplitude[7].direction
    assert p1_profile.amplitude == "along_class" and np.linalg.norm(direction) == pytest.approx(1.0)
    angles = prepared.states[d.sample_index, 6:9]
    assert d.function == "B1" and d.gamma == pytest.approx(sum(a * u for a, u in zip(angles, direction)), abs=1e-12)
    assert 0.0 <= d.nu <= 1.0 and all(0.0 <= x.nu <= 1.0 for x in streamed)
    if post.rejection_threshold is None:
        assert evaluate(model, rec, p1_profile.neutral_samples).accuracy == pytest.approx(
            np.mean(batch.labels[prepared.pure] == prepared.labels[prepared.pure]))


def test_raw_push_path_fuses_like_the_batch_fusion(p1_days, p1_profile, day1_fv1_model):
    """push(raw) == fuse the raw columns in batch, then push_angles / the batch chain."""
    day = p1_days[2]
    part = Recording(nodes={i: NodeData(n.acc[:1500], n.gyro[:1500], n.mag[:1500], n.angles[:1500])
                            for i, n in day.nodes.items()}, labels=day.labels[:1500], source=day.source)
    calibrations = {n.index: n.calibration for n in p1_profile.nodes}
    refused = fused_recording(part, calibrations)
    chain = OnlineChain(day1_fv1_model, p1_profile)
    decisions = []
    for k in range(len(part)):
        for node in (2, 3, 1):
            n = part.nodes[node]
            d = chain.push(node, n.acc[k], n.gyro[k], n.mag[k])
        decisions.append(d)
    states = node_states(refused, (1, 2, 3), np.zeros((3, 3)))     # the chain was given no neutral offsets
    batch = classify_windows(day1_fv1_model, window_features(states, day1_fv1_model.spec))
    assert [d.label for d in decisions[7:]] == batch.labels.tolist()


def test_neutral_calibration_from_samples(p1_days, p1_profile, day1_fv1_model):
    rec = p1_days[1]
    chain = OnlineChain(day1_fv1_model, p1_profile)
    chain.begin_neutral_calibration()
    for k in range(100):
        for node in (1, 2, 3):
            assert chain.push_angles(node, rec.nodes[node].angles[k], rec.nodes[node].gyro[k]) is None
    assert not chain.calibrating
    assert np.allclose([chain.neutral[i] for i in (1, 2, 3)], recording_neutral(rec, (1, 2, 3), 100), rtol=0, atol=1e-12)


def test_cross_validation_folds_on_p1_day1(p1_days):
    # day 1 holds c2 seven times (folds 0,1,2,0,1,2,0, whole holds) and c1 once (cut in 3 chunks)
    labels = p1_days[1].labels
    folds = hold_folds(labels)
    starts = np.flatnonzero(np.diff(labels, prepend=-1))
    c2 = starts[labels[starts] == 2]
    assert folds[c2].tolist() == [0, 1, 2, 0, 1, 2, 0]
    c1 = np.flatnonzero(labels == 1)
    assert sorted(set(folds[c1].tolist())) == [0, 1, 2] and np.all(np.diff(folds[c1]) >= 0)


def test_fv3_day1_model_meets_the_paper_on_days_2_to_5(p1_days, p1_profile, day1_fv3_model):
    """The P1 profile (settings chosen on day 1 only) against the paper's day-1-model table."""
    accuracy = {d: evaluate(day1_fv3_model, p1_days[d], p1_profile.neutral_samples).accuracy for d in range(2, 6)}
    for day, value in accuracy.items():
        assert 100 * value >= paper.DAY1_MODEL_PCT[day], (day, value)
    assert np.mean(list(accuracy.values())) >= 0.99


def test_train_and_evaluate_commands(tmp_path, capsys, p1_profile, day1_fv1_model, p1_days, shared_data):
    day1, day2, day4 = (str(shared_data / f"day{d}_testp.mat") for d in (1, 2, 4))
    model_path = tmp_path / "fv1.json"
    assert main(["train", day1, "--profile", "P1", "--features", "FV1", "--out", str(model_path)]) == 0
    assert np.array_equal(load_model(model_path).coef, day1_fv1_model.coef)
    trained = capsys.readouterr().out
    # classes by label, function and the profile's name, as everything else shows them
    assert "9 classes:" in trained and "c0 neutral" in trained and "c1 F: head pitch up (+29 deg)" in trained
    umask = os.umask(0o022)
    os.umask(umask)
    assert model_path.stat().st_mode & 0o777 == 0o666 & ~umask  # an ordinary file, not a private temporary
    out, png = tmp_path / "eval.json", tmp_path / "confusion.png"
    assert main(["evaluate", "--train", str(model_path), "--test", day2, "--test", day4, "--reject", "0.99",
                 "--json", str(out), "--png", str(png)]) == 0
    printed = capsys.readouterr().out
    record = json.loads(out.read_text())
    assert [r["test"] for r in record["results"]] == [day2, day4]
    expected = evaluate(day1_fv1_model, p1_days[2], 100, PostProcessing(rejection_threshold=0.99))
    assert record["results"][0]["accuracy"] == expected.accuracy
    assert record["results"][0]["rejected_share"] == expected.rejected_share
    assert f"accuracy {100 * expected.accuracy:.2f} %" in printed and "true\\pred" in printed
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # training straight from a recording gives the same numbers
    assert main(["evaluate", "--train", day1, "--test", day2, "--profile", "P1", "--features", "FV1", "--png", str(png), "--force",
                 "--json", str(out)]) == 0
    assert json.loads(out.read_text())["results"][0]["accuracy"] == evaluate(day1_fv1_model, p1_days[2], 100).accuracy


def test_fuse_command_recomputes_angles(tmp_path, p1_days):
    day = p1_days[5]
    part = Recording(nodes={i: NodeData(n.acc[:400], n.gyro[:400], n.mag[:400], np.zeros((400, 3)))
                            for i, n in day.nodes.items() if i in (1, 3)}, labels=day.labels[:400])
    source, out = tmp_path / "in.csv", tmp_path / "out.csv"
    write_recording(source, part)
    assert main(["fuse", str(source), "--out", str(out)]) == 0
    fused = read_recording(out)
    expected = fused_recording(part, {1: NodeCalibration(), 3: NodeCalibration.uncalibrated()})
    for i in (1, 3):
        assert np.array_equal(fused.nodes[i].angles, expected.nodes[i].angles)
        assert np.array_equal(fused.nodes[i].acc, part.nodes[i].acc)
    assert not np.allclose(fused.nodes[1].angles, 0)
    assert np.array_equal(fused.labels, part.labels)


def test_command_errors_are_one_line(tmp_path, capsys, shared_data):
    missing = tmp_path / "nope.mat"
    assert main(["train", str(missing), "--out", str(tmp_path / "m.json")]) == 2
    assert main(["train", str(missing), "--out", str(tmp_path / "m.pkl")]) == 2
    day1 = str(shared_data / "day1_testp.mat")
    assert main(["evaluate", "--train", day1, "--test", str(missing), "--profile", "P9",
                 "--png", str(tmp_path / "c.png")]) == 2
    assert main(["train", day1, "--profile", "P4", "--out", str(tmp_path / "m.json")]) == 2
    errors = capsys.readouterr().err.splitlines()
    assert errors[0] == f"bomi: error: {missing}: no such recording file"
    assert "m.pkl: --out must end in .json or .npz" in errors[1]
    assert "no such profile file" in errors[2]
    assert errors[3] == f"bomi: error: {day1}: label(s) [6, 7, 8] are not classes of profile P4"
    assert not list(tmp_path.iterdir())


def test_no_extra_earns_its_place_on_p1_day1(p1_days, p1_profile):
    """On P1's day 1 the whole-hold CV scores every candidate within 0.4 point of plain: plain is chosen
    (P1.toml keeps its shrinkage 0.001 and direction spread 30, chosen before issue 26)."""
    chosen = select_settings([p1_days[1]], p1_profile, p1_profile.spec)
    assert chosen.describe() == "plain" and chosen.accuracy == chosen.plain_accuracy > 0.995
    assert max(chosen.candidates.values()) - chosen.plain_accuracy < 0.004
