"""Compiled kernels: numba's ``njit`` where numba is installed, the same Python function where not.

A kernel is a plain function of floats, ints and numpy arrays (loops written out, no Python
objects) that runs once per sample or per control tick, where numpy's per-call overhead is larger
than the work.  numba compiles it to machine code with the same IEEE operations in the same order
(no fastmath, so no reassociation or fused multiply-adds; libm's transcendental functions, as
CPython's ``math`` calls them), so compiled and interpreted runs give the same bits
(tests/test_compiled.py).  The chain (``bomi/``) stays importable and correct with numpy, scipy and
scikit-learn alone: without numba a kernel runs as the Python function it is, only slower.
``BOMI_NO_JIT=1`` runs every kernel interpreted (to compare, or to debug one with pdb).
"""
from __future__ import annotations

import os
from collections.abc import Callable
from typing import TypeVar

try:
    import numba
except ImportError:  # an optional speed-up: everything runs without it
    numba = None

F = TypeVar("F", bound=Callable)

COMPILED = numba is not None and os.environ.get("BOMI_NO_JIT", "") in ("", "0")


def kernel(function: F) -> F:
    """``function`` compiled by numba (lazily, at its first call; the machine code cached on disk
    beside the module so the next process loads it), or ``function`` itself without numba.

    A kernel that calls another must live in the same file as it: numba's cache checks only the
    file of the cached function, so a caller cached from another file keeps running the callee's
    old code after the callee's file is edited."""
    if not COMPILED:
        return function
    return numba.njit(cache=True, nogil=True)(function)


def interpreted(function: Callable) -> Callable:
    """The Python function a ``kernel`` was made from (itself where nothing was compiled)."""
    return getattr(function, "py_func", function)
