"""Windows and FV1/FV2/FV3 against a naive loop implementation; streaming windows == batch windows."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bomi.features import WindowBuffer, _half_stats, _run_stats, component_index, features, single_label_windows, sliding_windows, window_features


def naive_components(state_row: list[float], n_nodes: int, kind: str) -> list[float]:
    """From one sample's per-node [pitch, roll, yaw, gx, gy, gz] blocks, as the paper lists them."""
    block = [state_row[6 * k:6 * k + 6] for k in range(n_nodes)]
    out = [block[0][0], block[0][1], block[0][2]]
    for k in range(1, n_nodes):
        out += [block[k][0], block[k][1]]
    if kind != "FV1":
        for k in range(n_nodes):
            out += block[k][3:6]
    return out


def naive_features(states: np.ndarray, n_nodes: int, kind: str, length: int, stride: int) -> np.ndarray:
    rows = []
    for end in range(length - 1, len(states), stride):
        window = [naive_components(list(states[i]), n_nodes, kind) for i in range(end - length + 1, end + 1)]
        n_comp = len(window[0])
        if kind in ("FV1", "FV2"):
            rows.append([sum(w[c] for w in window) / length for c in range(n_comp)])
            continue
        row = []
        for half in (window[: length // 2], window[length // 2:]):
            row += [min(w[c] for w in half) for c in range(n_comp)]
            row += [max(w[c] for w in half) for c in range(n_comp)]
            row += [sum(w[c] for w in half) / len(half) for c in range(n_comp)]
            row += [sum(abs(w[c]) for w in half) for c in range(n_comp)]
        rows.append(row)
    return np.array(rows)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_nodes=st.integers(1, 6), kind=st.sampled_from(["FV1", "FV2", "FV3"]),
       length=st.sampled_from([2, 4, 8, 10]), stride=st.integers(1, 3), n=st.integers(0, 40))
def test_features_match_naive_reference(seed, n_nodes, kind, length, stride, n):
    states = np.random.default_rng(seed).normal(scale=30, size=(n, 6 * n_nodes))
    got = features(kind, sliding_windows(states[:, component_index(n_nodes, kind)], length, stride))
    expected = naive_features(states, n_nodes, kind, length, stride)
    assert got.shape[0] == expected.shape[0] == max(0, (n - length) // stride + 1)
    if len(expected):
        assert np.allclose(got, expected, rtol=0, atol=1e-9)


def test_feature_sizes_for_three_nodes():
    # node states [p, r, y, gx, gy, gz] x 3: FV1 = p1 r1 y1 p2 r2 p3 r3, FV2 adds the 9 gyro values
    assert component_index(3, "FV1").tolist() == [0, 1, 2, 6, 7, 12, 13]
    assert component_index(3, "FV2").tolist() == [0, 1, 2, 6, 7, 12, 13, 3, 4, 5, 9, 10, 11, 15, 16, 17]
    assert features("FV3", np.zeros((1, 8, 16))).shape == (1, 2 * 4 * 16)
    with pytest.raises(ValueError, match="even window"):
        features("FV3", np.zeros((1, 7, 16)))
    with pytest.raises(ValueError, match="unknown feature vector"):
        component_index(3, "FV4")


@settings(max_examples=30, deadline=None)
@given(labels=st.lists(st.integers(0, 2), min_size=0, max_size=40), length=st.integers(1, 8))
def test_single_label_windows_never_straddle(labels, length):
    labels = np.array(labels, dtype=int)
    mask = single_label_windows(labels, length)
    naive = [len(set(labels[e - length + 1:e + 1].tolist())) == 1 for e in range(length - 1, len(labels))]
    assert mask.tolist() == naive


@pytest.mark.parametrize("stride", [1, 2, 3])
def test_window_buffer_streams_the_batch_windows_and_features(stride):
    rows = np.random.default_rng(stride).normal(size=(50, 16))
    buffer = WindowBuffer(8, 16, stride)
    streamed = [w.copy() for w in (buffer.push(r) for r in rows) if w is not None]
    batch = sliding_windows(rows, 8, stride)
    assert len(streamed) == len(batch) and all(np.array_equal(s, b) for s, b in zip(streamed, batch))
    for kind in ("FV2", "FV3"):
        one_by_one = np.vstack([features(kind, w[None]) for w in streamed])
        assert np.array_equal(one_by_one, features(kind, batch))   # same code, bit-identical


def test_fv3_by_hand():
    # one component, window of 8: halves [1, -2, 3, 0] and [5, 5, -1, 2]
    window = np.array([1, -2, 3, 0, 5, 5, -1, 2], dtype=float).reshape(1, 8, 1)
    assert features("FV3", window).tolist() == [[-2, 3, 0.5, 6, -1, 5, 2.75, 13]]
    assert features("FV1", window).tolist() == [[13 / 8]]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), channels=st.integers(1, 24), kind=st.sampled_from(["FV1", "FV2", "FV3"]),
       length=st.sampled_from([2, 4, 8, 10, 16, 32]), stride=st.integers(1, 3), n=st.integers(0, 80))
def test_recording_features_equal_the_streamed_windows_bit_for_bit(seed, channels, kind, length, stride, n):
    """window_features (a recording at once, FV3 from per-run statistics) = features of each window
    the stream sees, to the bit, and = the naive loop of the paper's definition."""
    samples = np.random.default_rng(seed).normal(scale=30, size=(n, channels))
    samples[::5] = -0.0   # signed zeros: the sums must start where the stream's do
    batch = window_features(samples, kind, length, stride)
    buffer = WindowBuffer(length, channels, stride)
    streamed = [features(kind, w[None])[0] for w in (buffer.push(r) for r in samples) if w is not None]
    assert batch.shape[0] == len(streamed) == max(0, (n - length) // stride + 1)
    if streamed:
        assert np.array_equal(batch.view(np.int64), np.array(streamed).view(np.int64))
        assert np.allclose(batch, naive_window_features(samples, kind, length, stride), rtol=0, atol=1e-9)


def naive_window_features(samples: np.ndarray, kind: str, length: int, stride: int) -> np.ndarray:
    """The paper's definition, one window and one component at a time."""
    rows = []
    for end in range(length - 1, len(samples), stride):
        window = samples[end - length + 1:end + 1].tolist()
        if kind != "FV3":
            rows.append([sum(w[c] for w in window) / length for c in range(samples.shape[1])])
            continue
        row = []
        for half in (window[:length // 2], window[length // 2:]):
            for stat in (min, max, lambda v: sum(v) / len(v), lambda v: sum(abs(x) for x in v)):
                row += [stat([w[c] for w in half]) for c in range(samples.shape[1])]
        rows.append(row)
    return np.array(rows)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["FV1", "FV2", "FV3"]), length=st.sampled_from([2, 4, 8, 16, 32]),
       stride=st.integers(1, 3), n=st.integers(0, 60), channels=st.integers(1, 6))
def test_features_of_selected_windows_are_those_windows_features_bit_for_bit(seed, kind, length, stride, n, channels):
    rng = np.random.default_rng(seed)
    samples = rng.normal(scale=30, size=(n, channels))
    samples[::3] = -0.0
    every = window_features(samples, kind, length, stride)
    select = rng.random(len(every)) < 0.4
    assert np.array_equal(window_features(samples, kind, length, stride, select).view(np.int64),
                          every[select].view(np.int64))


@pytest.mark.parametrize("size", [1, 2, 3, 4, 5, 8, 16])
@pytest.mark.parametrize("channels", [2, 3, 16])
def test_run_statistics_are_each_runs_half_statistics_bit_for_bit(size, channels):
    """``_run_stats`` (whole-column passes over a recording) = ``_half_stats`` of each run cut out
    alone, as the stream cuts a window's halves (a contiguous copy), to the bit: signed zeros and
    values of very different sizes, whose sums depend on their order."""
    rng = np.random.default_rng(size * 100 + channels)
    samples = rng.normal(size=(300, channels)) * 10.0 ** rng.integers(-8, 9, size=(300, channels))
    samples[::4] = -0.0
    samples[7:7 + 2 * size] = -0.0   # whole runs of negative zeros
    runs = np.ascontiguousarray(sliding_windows(samples, size))
    expected = np.array([_half_stats(run[None])[0] for run in runs])
    assert np.array_equal(_run_stats(samples, size).view(np.int64), expected.view(np.int64))
