"""The readers of session, twin, grid and operator files check them before use (issue 40, items 3-4).

In-process and small: a hand-made session of 4 ticks checked field by field, trials.jsonl records,
the session directory's confinement, twin recordings (dead sensors, two people), the participant
validator `twin` and `synth` share, sweep keys by content, --jobs, and the Ray address probe.
"""
from __future__ import annotations

import json
import os
import re
import signal
import socket
from pathlib import Path

import numpy as np
import pytest

from bomi.errors import BomiError
from bomi.recording import NodeData, Recording
from sim.joystick import BUTTONS, FUNCTIONS
from tasks.trials.checks import (Fault, TrialRecord, check_against_record, check_attrs, check_indices, inside,
                                 read_records)
from tasks.trials.session import Controller

N_TICKS = 4


def good_session() -> tuple[dict, dict, int]:
    """(attrs, groups, stream bytes) of a 4-tick BoMI session with one trial (ticks 1-3), 2 frames, 1 decision."""
    plan = {"trials": 1, "countdown_s": 0.5, "time_limit_s": 8.0, "seed": 11, "first": 1, "ready_within_s": 120.0}
    attrs = {"controller": "bomi", "clock": "simulated", "dt": 1 / 60, "layout": "3-axis", "participant": "P1",
             "seed": 11, "stick_columns": json.dumps(FUNCTIONS), "pressed_columns": json.dumps(BUTTONS),
             "plan": json.dumps(plan), "neutral": json.dumps({"1": [1.0, 2.0, 3.0]}), "profile": "P1",
             "allowance": 5, "classes": json.dumps({"0": "neutral (neutral posture)", "1": "F (head up)"})}
    n, f = N_TICKS, np.zeros
    ticks = {"t": np.arange(n) / 60, "trial": np.array([0, 1, 1, 1]), "phase": np.array([1, 2, 2, 2]),
             "task_t": np.arange(n) / 60, "stick": f((n, len(FUNCTIONS))), "pressed": f((n, len(BUTTONS)), bool),
             "linear": f((n, 3)), "angular": f((n, 3)), "finger": f(n), "mode": np.array(["translation"] * n, object),
             "hand_pos": f((n, 3)), "arm_qpos": f((n, 6)), "closure": f(n), "cube_pos": f((n, 2, 3)),
             "touching": f((n, 2), bool), "frames": np.array([0, 1, 1, 0]), "byte_end": np.array([0, 32, 64, 64])}
    frames = {"tick": np.array([1, 2]), "node_id": np.array([1, 1]), "period_ms": np.array([16, 16]),
              "counter": np.array([0, 1]), "mag": f((2, 3), int), "gyro": f((2, 3), int), "acc": f((2, 3), int),
              "sample": np.array([0, 1]), "intended": np.array([-1, -1])}
    decisions = {"tick": np.array([2]), "frame_row": np.array([1]), "sample_index": np.array([1]),
                 "label": np.array([1]), "confidence": np.array([0.9]), "rejected": np.array([False]),
                 "gamma": np.array([0.5]), "nu": np.array([0.5]), "intended": np.array([-1])}
    trials = {"number": np.array([1]), "task_seed": np.array([11]), "go_tick": np.array([1]),
              "end_tick": np.array([4]), "first_command_tick": np.array([-1]), "success": np.array([False]),
              "completion_time": np.array([np.nan]), "failure": np.array(["time limit 8 s"], object)}
    return attrs, {"ticks": ticks, "frames": frames, "decisions": decisions, "trials": trials}, 64


def test_the_hand_made_session_passes():
    attrs, groups, size = good_session()
    check_attrs(attrs)
    check_indices(attrs, groups, size)


def _attr_case(key, value):
    def edit(attrs, groups):
        attrs[key] = value
    return edit


def _column_case(group, name, change):
    def edit(attrs, groups):
        groups[group][name] = change(groups[group][name])
    return edit


def _plan_case(key, value):
    def edit(attrs, groups):
        attrs["plan"] = json.dumps(json.loads(attrs["plan"]) | {key: value})
    return edit


@pytest.mark.parametrize("edit, field", [
    (_attr_case("controller", "telepathy"), "attribute controller"),
    (_attr_case("layout", "9-axis"), "attribute layout"),
    (_attr_case("dt", float("nan")), "attribute dt"),
    (_attr_case("seed", 2 ** 40), "attribute seed"),
    (_attr_case("neutral", "{oops"), "attribute neutral"),
    (_attr_case("neutral", "[1, 2, 3]"), "attribute neutral"),
    (_attr_case("neutral", json.dumps({"1": [1e5, 0, 0]})), "attribute neutral.1"),
    (_attr_case("stick_columns", json.dumps(["B", "F", "R", "L", "Rr", "Lr"])), "attribute stick_columns"),
    (_attr_case("classes", "[]"), "attribute classes"),
    (_plan_case("colour", "red"), "attribute plan"),
    (_plan_case("trials", "3"), "attribute plan.trials"),
    (_plan_case("time_limit_s", -1), "attribute plan.time_limit_s"),
    (lambda attrs, groups: attrs.pop("profile"), "attribute profile"),
    (_column_case("ticks", "t", lambda v: v[:2]), "ticks/t"),
    (_column_case("ticks", "t", lambda v: v[::-1]), "ticks/t"),
    (_column_case("ticks", "stick", lambda v: v + 2), "ticks/stick"),
    (_column_case("ticks", "stick", lambda v: np.full(len(v), "x", "S1")), "ticks/stick"),
    (_column_case("ticks", "hand_pos", lambda v: v * np.nan), "ticks/hand_pos"),
    (_column_case("ticks", "byte_end", lambda v: v * 2), "ticks/byte_end"),
    (_column_case("frames", "tick", lambda v: v + N_TICKS), "frames/tick"),
    (_column_case("frames", "acc", lambda v: v + 2 ** 16), "frames/acc"),
    (_column_case("decisions", "frame_row", lambda v: v + 2), "decisions/frame_row"),
    (_column_case("decisions", "tick", lambda v: v - 5), "decisions/tick"),
    (_column_case("trials", "go_tick", lambda v: v * 0 + 10 ** 9), "trials/go_tick"),
    (_column_case("trials", "end_tick", lambda v: v * 0 + 1), "trials/end_tick"),
    (_column_case("trials", "end_tick", lambda v: v + 1), "trials/end_tick"),
    (_column_case("trials", "first_command_tick", lambda v: v * 0 + 3 + N_TICKS), "trials/first_command_tick"),
    (_column_case("trials", "number", lambda v: v + 1), "trials/number"),
    (_column_case("trials", "task_seed", lambda v: v + 1), "trials/task_seed"),
    (lambda attrs, groups: groups["trials"].pop("go_tick"), "trials/go_tick"),
])
def test_each_field_out_of_its_range_is_named(edit, field):
    attrs, groups, size = good_session()
    edit(attrs, groups)
    with pytest.raises(Fault) as err:
        check_attrs(attrs)
        check_indices(attrs, groups, size)
    assert str(err.value).startswith(field + ":") and "\n" not in str(err.value)


def _records(tmp_path, lines: list[str]) -> Path:
    (tmp_path / "trials.jsonl").write_text("\n".join(lines) + "\n")
    return tmp_path


GOOD = {"trial": 1, "operator": "bomi", "success": False, "seed": 11}


@pytest.mark.parametrize("lines, fault", [
    (["[1, 2]"], "line 1: record: a JSON list, not an object"),
    (["{trial: 1"], "line 1 is not JSON"),
    ([json.dumps({k: v for k, v in GOOD.items() if k != "operator"})], "line 1: operator: None"),
    ([json.dumps(GOOD | {"operator": "../outside/evil"})], "line 1: operator: '../outside/evil' is not one of"),
    ([json.dumps(GOOD | {"trial": "1"})], "line 1: trial: '1' is not a trial number"),
    ([json.dumps(GOOD), json.dumps(GOOD)], "line 2: trial: trial 1 is recorded twice"),
    ([json.dumps(GOOD | {"seed": -1})], "line 1: seed"),
])
def test_a_bad_trial_record_is_one_line_naming_its_line_and_field(tmp_path, lines, fault):
    with pytest.raises(BomiError) as err:
        read_records(_records(tmp_path, lines))
    assert str(err.value).startswith(str(tmp_path / "trials.jsonl")) and fault in str(err.value)


def test_records_read_and_agree_with_their_session_row(tmp_path):
    records = read_records(_records(tmp_path, [json.dumps(GOOD), json.dumps(GOOD | {"trial": 2, "operator":
                                                                                     "joystick", "seed": 12})]))
    assert records[2] == TrialRecord(2, Controller.JOYSTICK, False, 12)
    trials = {"success": np.array([False]), "task_seed": np.array([11])}
    check_against_record(tmp_path / "bomi.h5", records[1], trials, 0)
    with pytest.raises(BomiError, match="different sessions"):  # another session's trials.jsonl beside it
        check_against_record(tmp_path / "bomi.h5", records[2], trials, 0)


def test_a_session_file_that_leads_outside_its_directory_is_not_read(tmp_path):
    session, outside = tmp_path / "s", tmp_path / "outside"
    session.mkdir()
    outside.mkdir()
    (outside / "evil").write_text("x")
    (session / "bomi.h5").symlink_to(outside / "evil")
    (session / "model.json").write_text("{}")
    assert inside(session, "model.json") == session / "model.json"
    for name in ("bomi.h5", "../outside/evil"):
        with pytest.raises(BomiError, match="leads outside the session directory"):
            inside(session, name)


# ------------------------------------------------------------------------------------ twins
def _recording(nodes=(1, 2), labels=(0, 1, 2), n=600, seed=0) -> Recording:
    rng = np.random.default_rng(seed)
    return Recording({i: NodeData(acc=rng.normal(0, 100, (n, 3)), gyro=rng.normal(0, 10, (n, 3)),
                                  mag=rng.normal(0, 1, (n, 3)), angles=rng.normal(0, 5, (n, 3))) for i in nodes},
                     np.resize(np.repeat(labels, 100), n), source=f"rec{seed}.csv")


def test_dead_sensor_channels_are_named_and_live_ones_pass():
    from tasks.participants.twin import dead_channels
    rec = _recording()
    assert dead_channels(rec, [1, 2]) == []
    rec.nodes[1].angles[:, 0] = 0.0                       # zero
    rec.nodes[2].gyro[:, 2] = 7.0                         # constant
    rec.nodes[2].acc[:200, 1] = rec.nodes[2].acc[:, 1].max()  # a third at its top: clipped
    assert dead_channels(rec, [1, 2]) == ["node 1 angles[0] constant at 0", "node 2 acc[1] saturated",
                                          "node 2 gyro[2] constant at 7"]
    assert dead_channels(rec, [2]) == ["node 2 acc[1] saturated", "node 2 gyro[2] constant at 7"]


def test_recordings_of_two_people_are_refused_as_one_twin():
    from tasks.participants.twin import same_person
    same_person([_recording(seed=0), _recording(seed=1)])
    with pytest.raises(BomiError, match="rec1.csv: nodes \\[1\\], classes \\[0, 1\\]; rec0.csv has nodes \\[1, 2\\]"):
        same_person([_recording(seed=0), _recording(nodes=(1,), labels=(0, 1), seed=1)])


def _p1_text() -> str:
    from tasks.participants.participant import PARTICIPANT_DIR
    return (PARTICIPANT_DIR / "P1.toml").read_text().replace('profile = "P1"', 'profile = "P1"', 1)


@pytest.mark.parametrize("old, new, fault", [
    ("posture_deg = [[", "posture_deg = [[1e5 + ", "beyond the 180 deg an angle"),
    ("rep_std_deg = [[", "rep_std_deg = [[95.0 + ", "beyond the 90 deg a standard deviation"),
    ("labels = [0", "labels = [1000000000", "not a finite number within"),
    ("durations_s = [", "durations_s = [-4.8, ", "[protocol] durations_s: must be as many durations in (0, 3600] s"),
])
def test_synth_s_validator_refuses_what_no_person_holds(old, new, fault):
    """The validator `bomi twin` runs on what it writes is the one `bomi synth` loads with."""
    from tasks.participants.participant import load_participant, parse_participant_text
    text = _p1_text()
    assert parse_participant_text(text, "t.toml").classes.keys() == load_participant("P1").classes.keys()
    assert old in text
    edited = text.replace(old, new, 1)
    if new.endswith("+ "):  # the first number of the matrix replaced: "[[1e5 + -2.5, ..." -> "[[1e5, ..."
        start = edited.index(new) + len(new)
        edited = edited[:edited.index(new) + len(new) - 3] + edited[edited.index(",", start):]
    with pytest.raises(ValueError, match=re.escape(fault)):
        parse_participant_text(edited, "t.toml")


# ------------------------------------------------------------------------------------ files named in files
def test_an_operator_file_s_human_model_is_beside_it_not_in_the_working_directory(tmp_path, monkeypatch):
    from tasks.operators.params import DEFAULT_OPERATOR_FILE, load_operator
    (tmp_path / "conf").mkdir()
    head = DEFAULT_OPERATOR_FILE.read_text().partition("[human]")[0]
    (tmp_path / "conf" / "op.toml").write_text(head + '[human]\nmodel = "h.toml"\n')
    monkeypatch.chdir(tmp_path)
    assert load_operator(Path("conf/op.toml")).human_model == str(tmp_path / "conf" / "h.toml")
    assert load_operator(DEFAULT_OPERATOR_FILE).human_model == load_operator().human_model  # a shipped name stays


# ------------------------------------------------------------------------------------ sweeps
def _grid(directory: Path, participant: str) -> Path:
    directory.mkdir(exist_ok=True)
    path = directory / "grid.toml"
    path.write_text(f'participants = ["{participant}"]\noperators = ["joystick"]\nseeds = [0]\n')
    return path


def test_a_sweep_key_follows_the_twin_s_content_not_its_path(tmp_path, monkeypatch):
    from tasks.experiments.sweep import cells, job_key, load_grid
    from tasks.participants.participant import PARTICIPANT_DIR
    twin = tmp_path / "g" / "twin.toml"
    grid = _grid(tmp_path / "g", "twin.toml")
    twin.write_text((PARTICIPANT_DIR / "P1.toml").read_text())

    def key(grid_path) -> str:
        return job_key(cells(load_grid(grid_path))[0].job(0))

    monkeypatch.chdir(tmp_path)
    before = key(Path("g/grid.toml"))
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    assert key(Path("../g/grid.toml")) == before           # resumed from another directory: the same episodes
    moved = tmp_path / "moved"
    (tmp_path / "g").rename(moved)
    assert key(moved / "grid.toml") == before              # the grid and twin moved: the same episodes
    (moved / "twin.toml").write_text(twin.name and (moved / "twin.toml").read_text() + "\n# edited\n")
    assert key(moved / "grid.toml") != before              # the twin edited: its episodes run again


def test_a_grid_participant_is_a_shipped_name_or_a_toml_file_beside_the_grid(tmp_path):
    from tasks.experiments.sweep import load_grid
    with pytest.raises(BomiError, match="'../../../tmp/x' is neither a shipped participant"):
        load_grid(_grid(tmp_path, "../../../tmp/x"))
    assert load_grid(_grid(tmp_path, "t.toml")).participants == (str(tmp_path / "t.toml"),)


def test_jobs_beyond_the_cpus_are_refused(monkeypatch):
    import argparse

    from tasks.cli.engine import engine_from_args
    from tasks.experiments import engine
    monkeypatch.setattr(engine, "MAX_JOBS", 2)
    args = argparse.Namespace(jobs=3, engine="local", address=None)
    with pytest.raises(BomiError, match="--jobs 3: at most 2"):
        engine_from_args(args)
    assert engine_from_args(argparse.Namespace(jobs=2, engine="local", address=None)).workers == 2


def test_a_ray_address_nobody_answers_is_one_line_at_once():
    from tasks.experiments.engine import check_ray_address
    with socket.socket() as s:  # a port bound but not listening: refused at once
        s.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{s.getsockname()[1]}"
        with pytest.raises(BomiError, match=f"--address {address}: no Ray cluster answers there"):
            check_ray_address(address, timeout_s=2.0)
    with pytest.raises(BomiError, match="expected HOST:PORT"):
        check_ray_address("nowhere")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        check_ray_address(f"ray://127.0.0.1:{s.getsockname()[1]}")


def _sigterm_handler(_):
    return signal.getsignal(signal.SIGTERM) == signal.SIG_DFL and signal.getsignal(signal.SIGHUP) == signal.SIG_DFL


def test_pool_workers_do_not_inherit_the_driver_s_sigterm_handler():
    """A driver that turns SIGTERM into KeyboardInterrupt (a sweep) must not have its workers print
    that traceback when it stops them (the full-disk case)."""
    from tasks.experiments.engine import ProcessPool
    from tasks.experiments.sweep import signals_interrupt
    with signals_interrupt():
        assert os.getpid() and dict(ProcessPool(1).run(_sigterm_handler, [0])) == {0: True}
