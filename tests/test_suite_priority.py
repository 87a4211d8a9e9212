"""The suite's own scheduling (tests/conftest.py): tests paced on the wall clock get the CPU first."""
import os
import subprocess
import sys

import pytest
from conftest import OTHERS_NICENESS

pytestmark = pytest.mark.skipif(not hasattr(os, "setpriority"), reason="no process priorities on this platform")


def test_a_test_not_paced_on_the_wall_clock_runs_niced_and_so_do_the_processes_it_starts():
    assert os.getpriority(os.PRIO_PROCESS, 0) >= OTHERS_NICENESS
    child = subprocess.run([sys.executable, "-c", "import os; print(os.getpriority(os.PRIO_PROCESS, 0))"],
                           capture_output=True, text=True, check=True)
    assert int(child.stdout) >= OTHERS_NICENESS
