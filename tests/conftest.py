"""Shared fixtures: the published P1 recordings (read once per session) and day-1 models.

Every test that needs the shared recordings asks for the ``shared_data`` fixture (directly or
through ``p1_days``): without them it is skipped, always with the same reason naming the directory."""
from __future__ import annotations

import os

import pytest

# Headless rendering: must be set before anything imports mujoco.
os.environ.setdefault("MUJOCO_GL", "egl")
# One BLAS (and OpenMP) thread per process, this one and those the tests start, unless the environment says
# otherwise (set before anything loads numpy's BLAS; tests/test_suite_priority.py checks it): three workers
# run on two cores, where a threaded BLAS in each only oversubscribes them (why the library's fits run
# single-threaded: bomi.classifier.single_threaded_blas).
BLAS_THREADS = {name: os.environ.setdefault(name, "1") for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                                     "MKL_NUM_THREADS")}

from bomi.chain import train
from bomi.dataset import data_dir
from bomi.features import FeatureSpec
from bomi.profiles import load_profile
from bomi.recording import read_recording


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Tests marked ``real_time`` (a stream paced on the wall clock: an emulator into a pty or socket,
    a window) run one after another on one worker of pytest-xdist (``--dist loadgroup``): two of them
    side by side would compete for the CPU their timing assumes, while the rest spread over the others.
    First among the hooks: pytest-xdist's worker reads the xdist_group marks in its own hook of this name
    (turning them into the "@group" its scheduler goes by), which would otherwise run before this one."""
    for item in items:
        if item.get_closest_marker("real_time"):
            item.add_marker(pytest.mark.xdist_group("real-time"))
    # The longest first, in the order pytest-xdist hands the work out in (the longest-processing-time-first
    # rule, so that no long test starts late and runs alone at the end while the other workers wait): the
    # real-time tests (one worker's queue of several minutes), then the modules with a test marked ``long``
    # (whole modules, in their own order: a module's fixtures are made once).
    long_files = {item.nodeid.split("::")[0] for item in items if item.get_closest_marker("long")}
    items.sort(key=lambda item: (item.get_closest_marker("real_time") is None, item.nodeid.split("::")[0] not in long_files))


# The niceness the other tests run at (their worker's thread, and the processes they start): a test paced on
# the wall clock then gets the CPU its timing assumes whatever runs beside it. On a loaded 2-core machine at
# equal priority, `bomi live`'s loop beside two busy workers ran at 14 Hz and its film lost 306 of its
# frames, and `bomi record` in another test printed no prompt within 40 s: load, not the code under test.
OTHERS_NICENESS = 10


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Every test not marked ``real_time`` runs at OTHERS_NICENESS, and its worker returns to its own
    priority after it (where lowering it again is not permitted, the worker stays there: every worker
    then does, and a real-time test is no worse off than at equal priority)."""
    if item.get_closest_marker("real_time") or not hasattr(os, "setpriority"):
        yield
        return
    own = os.getpriority(os.PRIO_PROCESS, 0)
    os.setpriority(os.PRIO_PROCESS, 0, max(own, OTHERS_NICENESS))
    yield
    try:
        os.setpriority(os.PRIO_PROCESS, 0, own)
    except PermissionError:
        pass


@pytest.fixture(scope="session")
def shared_data():
    """The directory of the published P1 recordings (days 1..5); skips the test when they are absent."""
    directory = data_dir()
    missing = [f"day{day}_testp.mat" for day in range(1, 6) if not (directory / f"day{day}_testp.mat").is_file()]
    if missing:
        pytest.skip(f"shared P1 recordings absent: {directory} lacks {', '.join(missing)} (set BOMI_DATA_DIR)")
    return directory


@pytest.fixture(scope="session")
def p1_days(shared_data):
    """day -> Recording of the published dataset (days 1..5)."""
    directory = shared_data
    return {day: read_recording(directory / f"day{day}_testp.mat") for day in range(1, 6)}


@pytest.fixture(scope="session")
def p1_profile():
    return load_profile("P1")


@pytest.fixture(scope="session")
def day1_fv3_model(p1_days, p1_profile):
    """The P1 profile's model (FV3, day-1 shrinkage) trained on day 1."""
    return train([p1_days[1]], p1_profile)


@pytest.fixture(scope="session")
def day1_fv1_model(p1_days, p1_profile):
    return train([p1_days[1]], p1_profile, FeatureSpec("FV1", p1_profile.node_indices))


@pytest.fixture(scope="session")
def p1_model_file(tmp_path_factory):
    """A model file trained on the virtual P1's short calibration session (another day: seed 1)."""
    from bomi.model_io import save_model
    from tasks.participants.participant import calibration_session, load_participant, session_recording

    params, profile = load_participant("P1"), load_profile("P1")
    session = calibration_session(params, profile, 1, repetitions=1, hold_s=2.0, neutral_s=2.0)
    path = tmp_path_factory.mktemp("model") / "p1.json"
    save_model(path, train([session_recording(session, profile)], profile))
    return path
