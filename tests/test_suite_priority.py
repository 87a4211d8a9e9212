"""The suite's own scheduling (tests/conftest.py): tests paced on the wall clock get the CPU first; one
BLAS thread per process."""
import os
import subprocess
import sys

import pytest
from conftest import BLAS_THREADS, OTHERS_NICENESS
from threadpoolctl import threadpool_info

NO_PRIORITIES = pytest.mark.skipif(not hasattr(os, "setpriority"), reason="no process priorities on this platform")


@NO_PRIORITIES
def test_a_test_not_paced_on_the_wall_clock_runs_niced_and_so_do_the_processes_it_starts():
    assert os.getpriority(os.PRIO_PROCESS, 0) >= OTHERS_NICENESS
    child = subprocess.run([sys.executable, "-c", "import os; print(os.getpriority(os.PRIO_PROCESS, 0))"],
                           capture_output=True, text=True, check=True)
    assert int(child.stdout) >= OTHERS_NICENESS


def test_blas_runs_the_threads_the_suite_sets_here_and_in_the_processes_it_starts():
    wanted = int(BLAS_THREADS["OPENBLAS_NUM_THREADS"])   # 1 unless the environment set it
    here = [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]
    assert here and all(threads == wanted for threads in here), here
    child = subprocess.run([sys.executable, "-c", "import numpy, threadpoolctl; print(max(p['num_threads'] for p in "
                            "threadpoolctl.threadpool_info() if p['user_api'] == 'blas'))"],
                           capture_output=True, text=True, check=True)
    assert int(child.stdout) == wanted
