"""benchmarks/records_identity.py's comparison of stored records, on hand-made records."""
import importlib.util
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "records_identity.py"


@pytest.fixture(scope="module")
def identity():
    spec = importlib.util.spec_from_file_location("records_identity", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def record(**changes) -> dict:
    base = {"participant": "P1", "operator": "bomi", "seed": 0, "success": True, "completion_time": 98.25,
            "sim_time": 98.25, "unintended_displacement_mm": 12.5, "latency_onsets_ms": [464.0, 736.0],
            "accuracy_all_decisions": 0.547, "wall_time": 30.1, "cpu_time": 29.8, "realtime_factor": 3.26,
            "realtime_factor_cpu": 3.3}
    return base | changes


def test_equal_records_but_for_timing_have_no_difference(identity):
    before = identity.stored_records([record(), record(operator="joystick", completion_time=20.5)])
    after = identity.stored_records([record(wall_time=99.0, cpu_time=98.0, realtime_factor=1.0,
                                            realtime_factor_cpu=1.0), record(operator="joystick", completion_time=20.5)])
    assert set(before) == {"P1 bomi seed 0", "P1 joystick seed 0"}
    assert "wall_time" not in before["P1 bomi seed 0"]
    assert identity.differences(before, after) == []


def test_one_field_differing_in_its_last_bit_is_named(identity):
    nudged = 98.25 + 1.4210854715202004e-14  # the next double above 98.25
    before = identity.stored_records([record()])
    after = identity.stored_records([record(completion_time=nudged)])
    assert identity.differences(before, after) == [f"P1 bomi seed 0: completion_time: 98.25 -> {nudged!r}"]


def test_a_field_or_episode_on_one_side_only_and_an_int_for_a_float_differ(identity):
    before = identity.stored_records([record(), record(seed=1)])
    after = {**identity.stored_records([record(latency_onsets_ms=[464, 736.0])])}
    del after["P1 bomi seed 0"]["sim_time"]
    assert identity.differences(before, after) == [
        "P1 bomi seed 0: latency_onsets_ms: [464.0, 736.0] -> [464, 736.0]",
        "P1 bomi seed 0: sim_time: 98.25 -> '(absent)'",
        "P1 bomi seed 1: run before only"]
