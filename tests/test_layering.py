"""The signal chain (bomi/) stands alone: importing any of its modules loads neither sim/ nor tasks/."""
import json
import pkgutil
import subprocess
import sys

import bomi

BOMI_MODULES = sorted(info.name for info in pkgutil.walk_packages(bomi.__path__, "bomi."))


def test_bomi_has_modules_to_check():
    assert "bomi.chain" in BOMI_MODULES and "bomi.profiles" in BOMI_MODULES


def test_importing_every_bomi_module_loads_no_sim_tasks_or_mujoco():
    # A fresh interpreter: the test process itself has sim/ and tasks/ loaded already.
    code = ("import importlib, json, sys\n"
            f"for name in {BOMI_MODULES!r}: importlib.import_module(name)\n"
            "print(json.dumps(sorted(m for m in sys.modules "
            "if m.split('.')[0] in ('sim', 'tasks', 'mujoco', 'dm_control', 'pinocchio'))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(done.stdout) == []


def test_version_answers():
    done = subprocess.run([sys.executable, "-m", "tasks.cli", "--version"], capture_output=True, text=True)
    assert done.returncode == 0
    name, number = done.stdout.split()
    assert name == "bomi" and number.count(".") >= 1
