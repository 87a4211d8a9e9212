"""Engines: an episode's record depends only on its settings and seed, never on the engine (process
pool or Ray), the worker or the order; Ray retries a failed episode once and says so."""
import os
import sys

import pytest

from tasks.cli import main
from tasks.experiments.engine import PRIVATE_RAY, EpisodeFailed, ProcessPool, RayCluster, run_private
from tasks.experiments.jobs import EpisodeJob, benchmark_jobs, episode_record
from tests.network import ServedSockets, descendants_running

# how fast the machine ran the episode, not what happened in it
TIMING_FIELDS = ("wall_time", "cpu_time", "realtime_factor", "realtime_factor_cpu")
# a handful of short episodes: joystick ones are cheapest; one BoMI episode brings the calibration,
# the classifier and the virtual participant's random draws in
JOBS = benchmark_jobs(["P1"], ["joystick"], 3, 2.0, "operator") + [EpisodeJob("bomi", "P4", 2, time_limit=1.0,
                                                                              operator_file="operator")]


def outcome(record: dict) -> dict:
    return {k: v for k, v in record.items() if k not in TIMING_FIELDS}


def in_order(engine, jobs) -> list[dict]:
    results = dict(engine.run(episode_record, jobs))
    assert sorted(results) == list(range(len(jobs)))
    return [outcome(results[i]) for i in range(len(jobs))]


# The tests that start a Ray (here, and test_sweep.py's SIGTERM on a Ray sweep)
# share an xdist group: one Ray at a time on this 2-core machine, and each module fixture made once.
RAY = pytest.mark.xdist_group("ray")


@pytest.fixture(scope="module")
def pool_records():
    return in_order(ProcessPool(2), JOBS)


@RAY
def test_records_do_not_depend_on_the_order_or_the_worker(pool_records):
    # one worker runs them all in the opposite order: whatever an episode leaves behind in the
    # process (caches, global random state) would show here
    backwards = in_order(ProcessPool(1), JOBS[::-1])[::-1]
    assert backwards == pool_records
    assert pool_records[-1]["decisions"] > 0 and len({r["unintended_displacement_mm"] for r in pool_records}) > 1


@pytest.fixture(scope="module")
def ray_cluster():
    """A Ray this process has joined (RayCluster uses it as it is): the retry rules, without a
    private Ray's start-up per test."""
    ray = pytest.importorskip("ray", reason="Ray is the optional extra: pip install -e \".[ray]\"")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="warning")
    yield ray
    ray.shutdown()


@RAY
@pytest.mark.long
def test_ray_gives_the_process_pool_s_records_field_by_field_and_listens_on_the_loopback_only(pool_records):
    """The private local Ray `--engine ray` starts gives the pool's records; over its whole run (start-up,
    episodes, idle workers, shut-down) no process of it listens (TCP) or receives (UDP) on anything but
    the loopback, as each process's own network namespace sees it (tasks/experiments/private_ray.py)."""
    pytest.importorskip("ray", reason="Ray is the optional extra: pip install -e \".[ray]\"")
    with ServedSockets(lambda: descendants_running(os.getpid(), PRIVATE_RAY)) as served:
        results = dict(run_private(episode_record, JOBS, 2))
    assert "gcs_server" in served.commands() and "raylet" in served.commands()  # Ray's servers were seen, listening
    assert not served.beyond_loopback(), f"listening beyond the loopback: {served.beyond_loopback()}"
    assert sorted(results) == list(range(len(JOBS)))
    ray_records = [outcome(results[i]) for i in range(len(JOBS))]
    for job, ours, theirs in zip(JOBS, ray_records, pool_records):
        assert ours.keys() == theirs.keys(), job
        for field in ours:
            assert ours[field] == theirs[field], f"{job}: {field}"


@RAY
def test_ray_retries_a_failed_episode_once_and_names_it(ray_cluster, tmp_path, capsys):
    marker = tmp_path / "crashed-once"

    def crash_once(x):
        try:  # created atomically: of two workers starting together, only one crashes
            os.close(os.open(marker, os.O_CREAT | os.O_EXCL))
        except FileExistsError:
            return x * 10
        os._exit(1)  # the worker process dies, as on a lost node

    assert dict(RayCluster().run(crash_once, ["a", "b"])) == {0: "a" * 10, 1: "b" * 10}
    err = capsys.readouterr().err
    assert err.count("retrying once") == 1 and "failed on a Ray worker" in err


@RAY
def test_ray_stops_on_an_episode_that_fails_twice(ray_cluster):
    def always_fails(x):
        raise ValueError(f"no good: {x}")

    with pytest.raises(EpisodeFailed, match="job-7: failed twice on Ray workers"):
        list(RayCluster().run(always_fails, ["job-7"]))


def test_without_ray_the_ray_engine_says_how_to_install_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails as if not installed
    out = tmp_path / "bench.json"
    assert main(["benchmark", "--operators", "joystick", "--seeds", "1", "--engine", "ray", "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == 'bomi: error: --engine ray: Ray is not installed; install the optional extra: pip install -e ".[ray]"'
    assert not out.exists()


def test_the_process_pool_names_the_episode_that_failed():
    with pytest.raises(EpisodeFailed, match="episode P9 bomi seed 0"):
        list(ProcessPool(1).run(episode_record, [EpisodeJob("bomi", "P9", 0)]))
