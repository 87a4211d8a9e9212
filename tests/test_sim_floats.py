"""The control tick's scalar helpers against the builtin forms they replace, bit for bit."""
import math
import struct

import numpy as np

from sim.kernels import clip

SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.5, -0.5, math.inf, -math.inf, math.nan, 1e-300, -1e-300]


def bits(x: float) -> bytes:
    return struct.pack("<d", x)


def test_clip_is_min_of_max_bit_for_bit():
    """Random values and bounds (crossed bounds too), signed zeros, infinities and NaN anywhere:
    clip(v, lo, hi) is min(max(v, lo), hi), the same object bits."""
    rng = np.random.default_rng(7)
    values = SPECIAL + (rng.normal(size=300) * 10.0 ** rng.integers(-5, 5, size=300)).tolist()
    bounds = SPECIAL + rng.normal(size=40).tolist()
    for v in values:
        for lo in bounds:
            for hi in bounds:
                assert bits(clip(v, lo, hi)) == bits(min(max(v, lo), hi)), (v, lo, hi)
    assert clip(0, -1.0, 1.0) == 0 and type(clip(0, -1.0, 1.0)) is int  # an int in range stays as it was
