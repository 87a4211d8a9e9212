"""benchmarks/tick_floor.py replays a taped episode layer by layer: each replay must be the same
simulation as the episode (its claim that a layer's cost is the floor of that episode rests on it)."""
from __future__ import annotations

from pathlib import Path

import pytest

from helpers import benchmark_script
from sim.env import ArmSim
from tasks.experiments.jobs import EpisodeJob, run_job

SEED = 3  # development seed


@pytest.fixture(scope="module")
def floor():
    benchmarks = str(Path(__file__).resolve().parents[1] / "benchmarks")
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(benchmarks)  # tick_floor imports side_by_side beside it
        yield benchmark_script("tick_floor")


@pytest.fixture(scope="module")
def limit_arm():
    return ArmSim()


@pytest.fixture
def limit(floor, limit_arm):
    return floor.InterleavedLimit(limit_arm, every=30, physics_s=20.0)


@pytest.fixture(scope="module")
def taped(floor):
    with floor.Tape() as tape:  # the episode's first 6 s (ended by the time limit): enough to replay, and quick
        log = run_job(EpisodeJob("joystick", "P1", SEED, time_limit=6.0))
    return tape, log, tape.arm.data.qpos.copy()


def test_the_tape_holds_every_tick_of_the_episode(taped):
    tape, log, _ = taped
    assert len(tape.states) == len(tape.twists) == len(tape.ctrl) == len(log.t)


@pytest.mark.parametrize("layer", ["physics", "+ IK", "+ joystick", "+ task"])
def test_every_layer_replays_the_episode_to_its_final_state_bit_for_bit(floor, taped, limit, layer):
    tape, _, final = taped
    assert floor.replay(tape, SEED, layer, final, limit) > 0
    # the limit ran between the layer's ticks: a chunk after every 30 of them, 30 ticks of physics each
    assert limit.sim_s == pytest.approx(len(tape.states) // 30 * 30 * tape.arm.dt)
    assert 0 < limit.cpu <= limit.excluded


def test_a_replay_that_leaves_the_episode_is_refused(floor, taped, limit):
    tape, _, final = taped
    twists = list(tape.twists)
    tape.twists[len(twists) // 2] = ([0.05, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0)  # one tick pushed another way
    try:
        with pytest.raises(RuntimeError, match="did not end where the episode did"):
            floor.replay(tape, SEED, "+ IK", final, limit)
    finally:
        tape.twists[:] = twists
