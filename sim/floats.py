"""Scalar helpers of the control tick's Python-float paths (the arm's, the scripted user's): the
results of the builtin or numpy forms, bit for bit, at a fraction of their call overhead."""
from __future__ import annotations


def clip(value: float, lower: float, upper: float) -> float:
    """``min(max(value, lower), upper)``: the same two comparisons, made in the same order with the
    same operands (so the same result, NaN and signed zeros included), without two builtin calls."""
    value = lower if lower > value else value
    return upper if upper < value else value
