"""Compiled kernels: numba's ``njit`` where numba is installed, the same Python function where not.

A kernel is a plain function of floats, ints and numpy arrays (loops written out, no Python
objects) that runs once per sample or per control tick, where numpy's per-call overhead is larger
than the work.  numba compiles it to machine code with the same IEEE operations in the same order
(no fastmath, so no reassociation or fused multiply-adds; libm's transcendental functions, as
CPython's ``math`` calls them), so compiled and interpreted runs give the same bits
(tests/test_compiled.py).  The chain (``bomi/``) stays importable and correct with numpy, scipy and
scikit-learn alone: without numba a kernel runs as the Python function it is, only slower.
``BOMI_NO_JIT=1`` runs every kernel interpreted (to compare, or to debug one with pdb).

numba itself (~0.35 s to import) is imported at a kernel's first call, not with the module: a
command that never runs a kernel (``--help``, file checks) does not wait for it.  A kernel may call
other kernels (module globals): they are compiled with it.
"""
from __future__ import annotations

import importlib.util
import os
import types
from collections.abc import Callable
from functools import update_wrapper
from typing import Any

COMPILED = importlib.util.find_spec("numba") is not None and os.environ.get("BOMI_NO_JIT", "") in ("", "0")


class Kernel:
    """A kernel function: compiled by numba at its first call (the machine code cached on disk beside
    the module, so the next process loads it instead of compiling), or run as the Python function."""

    def __init__(self, function: Callable) -> None:
        self.py_func = function
        self._call: Callable | None = None if COMPILED else function
        update_wrapper(self, function)

    def __call__(self, *args: Any) -> Any:
        if self._call is None:
            self._call = self._compiled()
        return self._call(*args)

    def _compiled(self) -> Callable:
        """numba's dispatcher of the function, the kernels it names compiled first (numba calls
        compiled functions only: the function is rebound to a namespace that holds theirs)."""
        import numba
        function = self.py_func
        namespace = dict(function.__globals__)
        for name in function.__code__.co_names:
            if isinstance(namespace.get(name), Kernel):
                callee = namespace[name]
                if callee._call is None:
                    callee._call = callee._compiled()
                namespace[name] = callee._call
        rebound = types.FunctionType(function.__code__, namespace, function.__name__, function.__defaults__,
                                     function.__closure__)
        rebound.__qualname__, rebound.__module__ = function.__qualname__, function.__module__
        return numba.njit(cache=True, nogil=True)(rebound)


def kernel(function: Callable) -> Kernel:
    """Make ``function`` a ``Kernel``."""
    return Kernel(function)


def interpreted(function: Kernel | Callable) -> Callable:
    """The Python function a ``kernel`` was made from."""
    return getattr(function, "py_func", function)
