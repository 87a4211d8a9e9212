"""What "identical" means (benchmarks/records_identity.py's docstring): the same build on the same
machine gives bit-identical episodes.  Across CPUs, and between the numba kernels and
``BOMI_NO_JIT=1``, only distributions hold (``records_identity.py --no-jit``); no test here
compares two implementations bit for bit."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from helpers import benchmark_script
from tasks.experiments.jobs import EpisodeJob, run_job

TIMING = {"wall_time", "cpu_time"}  # the only fields allowed to differ between two runs


def unequal_fields(a, b, prefix: str = "") -> list[str]:
    """The fields of two (nested) dataclasses that are not exactly equal, arrays element by element."""
    out = []
    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if field.name in TIMING:
            continue
        if dataclasses.is_dataclass(x) and not isinstance(x, type):
            out += unequal_fields(x, y, f"{prefix}{field.name}.")
        elif isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not (isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and x.dtype == y.dtype
                    and np.array_equal(x, y, equal_nan=x.dtype.kind == "f")):
                out.append(prefix + field.name)
        elif x != y:
            out.append(prefix + field.name)
    return out


def test_one_episode_run_twice_in_one_process_is_bit_identical():
    # the BoMI: the participant's calibration protocol, the LDA trained on it, then the task; the
    # second run reuses the process's arm (tasks.stacking.episode.process_arm), reset by the task
    job = EpisodeJob("bomi", "P1", 0, time_limit=4.0)
    first, second = run_job(job), run_job(job)
    assert len(first.t) == 241 and np.sum(first.decisions.decided != first.neutral) > 50  # functions decided
    assert not np.array_equal(first.hand_pos[0], first.hand_pos[-1])  # the hand moved
    assert unequal_fields(first, second) == []


def test_unequal_fields_sees_one_changed_bit():
    job = EpisodeJob("joystick", "P1", 0, time_limit=1.0)
    log = run_job(job)
    nudged = log.hand_pos.copy()
    nudged[-1, 0] = np.nextafter(nudged[-1, 0], np.inf)
    changed = dataclasses.replace(log, hand_pos=nudged, wall_time=log.wall_time + 1.0)
    assert unequal_fields(log, changed) == ["hand_pos"]  # the timing field is not compared


@pytest.fixture(scope="module")
def records_identity():
    return benchmark_script("records_identity")


def test_records_differences_name_each_field(records_identity):
    before = {"P1 bomi seed 0": {"success": True, "completion_time": 93.85, "gamma": float("nan")},
              "P1 bomi seed 1": {"success": False, "completion_time": None}}
    after = {"P1 bomi seed 0": {"success": True, "completion_time": 93.85000000000001, "gamma": float("nan"),
                                "decisions": 5}}
    assert records_identity.differences(before, after) == [
        "P1 bomi seed 0: completion_time: 93.85 -> 93.85000000000001",  # NaN equals NaN; one ulp does not pass
        "P1 bomi seed 0: decisions: '(absent)' -> 5",
        "P1 bomi seed 1: run before only"]


@pytest.mark.parametrize("argv, fault", [(["no-such-commit"], "BEFORE: 'no-such-commit' is not a commit"),
                                         (["HEAD", "no-such-commit"], "AFTER: 'no-such-commit' is not a commit"),
                                         (["--seeds", "1001", "HEAD"], "--seeds: 1001"),
                                         (["--no-jit", "HEAD", "HEAD"], "at most one commit")])
def test_records_identity_bad_input_is_one_line_before_any_episode(records_identity, capsys, argv, fault):
    assert records_identity.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("bomi: error: ") and fault in err and err.count("\n") == 1
