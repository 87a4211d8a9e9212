"""bomi.compiled: the chain runs without numba (interpreted kernels), to the results of the compiled ones
(to a tolerance: the two forms may round differently where libm's code paths differ)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from bomi.compiled import COMPILED, interpreted, kernel
from helpers import assert_same_angles

# a process in which numba cannot be imported (as on a machine without it): prints the fused angles
# of a fixed pseudo-random stream, and whether bomi.compiled compiled anything
WITHOUT_NUMBA = """
import json, sys
sys.modules["numba"] = None  # 'import numba' raises ImportError
import numpy as np
import bomi.chain, bomi.compiled
from bomi.fusion import NodeCalibration, NodeFusion
rng = np.random.default_rng(7)
acc, gyro, mag = (rng.integers(-20000, 20000, (500, 3)) for _ in range(3))
fusion = NodeFusion(NodeCalibration())
angles = fusion.update_many(acc, gyro, mag)
print(json.dumps({"compiled": bomi.compiled.COMPILED, "angles": angles.tolist(), "state": fusion.state.tolist()}))
"""


def test_the_chain_imports_and_fuses_without_numba_as_compiled():
    from bomi.fusion import NodeCalibration, NodeFusion
    env = {k: v for k, v in os.environ.items() if k != "BOMI_NO_JIT"}
    done = subprocess.run([sys.executable, "-c", WITHOUT_NUMBA], capture_output=True, text=True, env=env, check=True)
    result = json.loads(done.stdout)
    assert result["compiled"] is False
    rng = np.random.default_rng(7)
    acc, gyro, mag = (rng.integers(-20000, 20000, (500, 3)) for _ in range(3))
    fusion = NodeFusion(NodeCalibration())
    here = fusion.update_many(acc, gyro, mag)
    assert_same_angles(result["angles"], here)   # floats through JSON: repr, exact
    assert_same_angles(result["state"], fusion.state)   # the filter's state too (tests/test_fusion.py: why)


def test_a_kernel_is_compiled_at_its_first_call_where_numba_is_installed_and_keeps_its_python_function():
    def cumulative(values: np.ndarray, out: np.ndarray) -> None:
        total = 0.0
        for i in range(values.shape[0]):
            total += values[i]
            out[i] = total

    compiled = kernel(cumulative)
    assert interpreted(compiled) is cumulative
    values = np.random.default_rng(0).normal(size=1000)
    out = np.empty(1000)
    compiled(values, out)
    assert np.array_equal(out, np.cumsum(values))  # a left-to-right sum, as np.cumsum's
    if COMPILED:  # numba made machine code of it
        assert compiled._call is not cumulative and compiled._call.py_func.__code__ is cumulative.__code__
    else:
        assert compiled._call is cumulative


def test_importing_the_chain_does_not_import_numba():
    """numba costs ~0.35 s to import: a command that runs no kernel must not pay it."""
    done = subprocess.run([sys.executable, "-c", "import sys, bomi.chain, bomi.fusion; print('numba' in sys.modules)"],
                          capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"


@kernel
def _square(x: float) -> float:
    return x * x


@kernel
def _sum_of_squares(values: np.ndarray) -> float:
    total = 0.0
    for i in range(values.shape[0]):
        total += _square(values[i])
    return total


def test_a_kernel_calls_another_kernel_compiled_or_not():
    values = np.arange(10.0)
    assert _sum_of_squares(values) == 285.0 == interpreted(_sum_of_squares)(values)


# BOMI_NO_JIT=1 (numba installed, every kernel run as its Python function): a stream fused sample by
# sample then in one chunk, as the live loop and a recording do; prints its angles and filter state
NO_JIT_STREAM = """
import json
import numpy as np
import bomi.compiled
from bomi.fusion import NodeCalibration, NodeFusion
rng = np.random.default_rng(11)
acc, gyro, mag = (rng.integers(-20000, 20000, (800, 3)) for _ in range(3))
fusion = NodeFusion(NodeCalibration())
angles = [fusion.update(a, g, m) for a, g, m in zip(acc[:300], gyro[:300], mag[:300])]
angles += fusion.update_many(acc[300:], gyro[300:], mag[300:]).tolist()
print(json.dumps({"compiled": bomi.compiled.COMPILED, "angles": angles, "state": fusion.state.tolist()}))
"""


def test_the_filter_state_with_bomi_no_jit_is_the_compiled_one_to_the_filters_tolerance():
    """The fusion filter's angles and state after a stream, BOMI_NO_JIT=1 against this process (compiled
    where numba is installed), to FILTER_FORMS_DEG (tests/test_fusion.py: why that tolerance holds)."""
    from bomi.fusion import NodeCalibration, NodeFusion
    env = os.environ | {"BOMI_NO_JIT": "1"}
    done = subprocess.run([sys.executable, "-c", NO_JIT_STREAM], capture_output=True, text=True, env=env, check=True)
    result = json.loads(done.stdout)
    assert result["compiled"] is False
    rng = np.random.default_rng(11)
    acc, gyro, mag = (rng.integers(-20000, 20000, (800, 3)) for _ in range(3))
    fusion = NodeFusion(NodeCalibration())
    angles = [fusion.update(a, g, m) for a, g, m in zip(acc[:300], gyro[:300], mag[:300])]
    angles += fusion.update_many(acc[300:], gyro[300:], mag[300:]).tolist()
    assert_same_angles(result["angles"], angles)
    assert_same_angles(result["state"], fusion.state)
    assert not np.allclose(fusion.state, 0.0)
