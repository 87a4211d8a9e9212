"""The pieces a virtual participant's body is made of: minimum-jerk moves, coloured noise (sway,
tremor) and the ground truth of what the body did."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.signal

from bomi.frames import SAMPLE_RATE_HZ

SWAY_CUTOFF_HZ = 1.0          # sway below, tremor above: the split used by the P1 fit


def minimum_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk position profile 10 s^3 - 15 s^4 + 6 s^5 for s in [0, 1] (clipped outside)."""
    s = np.clip(s, 0.0, 1.0)
    return s ** 3 * (10.0 - 15.0 * s + 6.0 * s ** 2)


@dataclass
class ColouredNoise:
    """Unit-variance Gaussian noise through a fixed filter (b, a), streamed (filter state kept between calls)."""

    b: np.ndarray
    a: np.ndarray
    channels: int
    rng: np.random.Generator
    gain: float = field(init=False)
    state: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        impulse = scipy.signal.lfilter(self.b, self.a, np.r_[1.0, np.zeros(8191)])
        self.gain = 1.0 / float(np.sqrt(np.sum(impulse ** 2)))
        self.state = np.zeros((max(len(self.a), len(self.b)) - 1, self.channels))
        # start in the stationary regime: run the filter over a few seconds of noise first
        self.next(int(10 * SAMPLE_RATE_HZ))

    def next(self, n: int) -> np.ndarray:
        noise = self.rng.standard_normal((n, self.channels))
        if len(self.a) == 1 and self.a[0] == 1.0:   # FIR (the tremor's)
            out, self.state = fir_filter(self.b, noise, self.state)
        else:
            out, self.state = scipy.signal.lfilter(self.b, self.a, noise, axis=0, zi=self.state)
        return out * self.gain


def fir_filter(b: np.ndarray, x: np.ndarray, zi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.lfilter(b, [1.0], x, axis=0, zi=zi)`` of (n, C) ``x`` by scipy's own FIR arithmetic
    (``np.convolve`` of each channel, the state added to the first outputs): the same bits
    (tests/test_participant.py), without its ``np.apply_along_axis``, 2/3 of the cost of a stream's
    chunk of a few dozen samples. Returns (output, final state)."""
    full = np.empty((len(x) + len(b) - 1, x.shape[1]))
    for channel in range(x.shape[1]):
        full[:, channel] = np.convolve(b, x[:, channel])
    full[:len(zi)] += zi
    return full[:len(x)], full[len(x):]


def sway_filter() -> tuple[np.ndarray, np.ndarray]:
    """Fourth-order Butterworth low-pass at SWAY_CUTOFF_HZ (little leakage into the tremor band)."""
    return scipy.signal.butter(4, SWAY_CUTOFF_HZ, "low", fs=SAMPLE_RATE_HZ)


def tremor_filter(spectrum: tuple[np.ndarray, np.ndarray], taps: int = 255) -> tuple[np.ndarray, np.ndarray]:
    """FIR filter whose power response follows the tremor spectrum (amplitude = sqrt of power)."""
    freqs, power = spectrum
    nyquist = SAMPLE_RATE_HZ / 2
    if freqs[-1] < nyquist:
        freqs, power = np.r_[freqs, nyquist], np.r_[power, 0.0]
    return scipy.signal.firwin2(taps, freqs, np.sqrt(power), fs=SAMPLE_RATE_HZ), np.array([1.0])


@dataclass(frozen=True)
class PostureMove:
    """A min-jerk move from ``start`` to ``target`` (absolute angles, (nodes, 3)) beginning at ``t0``."""

    t0: float
    duration: float
    start: np.ndarray
    target: np.ndarray
    label: int
    amplitude: float

    def progress(self, t: np.ndarray) -> np.ndarray:
        """Share of the move done at times ``t`` (0 before, 1 after)."""
        return minimum_jerk((t - self.t0) / self.duration)

    def at(self, t: np.ndarray) -> np.ndarray:
        """Posture at times ``t``, (n, nodes, 3)."""
        return self.posture(self.progress(t))

    def posture(self, progress: np.ndarray) -> np.ndarray:
        """Posture at (n,) shares ``progress`` of the move, (n, nodes, 3)."""
        return self.start[None] + progress[:, None, None] * (self.target - self.start)[None]

    @cached_property
    def done(self) -> np.ndarray:
        """The posture once the move is done, (nodes, 3): ``posture`` at progress 1.0, bit for bit
        (start + (target - start), which need not be ``target``'s bits)."""
        return self.posture(np.ones(1))[0]


@dataclass(frozen=True)
class Truth:
    """Ground truth per generated sample: time, intent (label, amplitude) and true angles (n, nodes, 3)."""

    time_s: np.ndarray
    intent: np.ndarray
    amplitude: np.ndarray
    angles: np.ndarray
