"""A stand-in for the original recording software's files: passes of the protocol in one MATLAB
file, on the logger's own clock.

The logger writes ``Time`` as an int32 millisecond clock, one row every LOGGER_STEP_MS (its median
step), that keeps running while recording is paused: it pauses for seconds at the start (after the
first row or rows, before the protocol begins) and between two passes of the protocol. A file
written here has that layout, so that bomi.recording reads its clock and bomi.passes finds its
passes as they would in the logger's own file.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from bomi.errors import BomiError
from bomi.passes import join
from bomi.recording import LOGGER_TICKS_PER_S, Recording, write_logger_mat

LOGGER_STEP_MS = 16      # the logger's median step (62.5 Hz)
START_PAUSE_S = 3.0      # the pause after the first row(s), before the protocol starts
PASS_PAUSE_S = 6.2       # the pause between two passes (issue 41's real two-pass file paused 6.2 s)
LEAD_ROWS = 1            # rows written before the start pause


def _steps_ms(rec: Recording) -> np.ndarray:
    """The steps (ms) between ``rec``'s rows: its own clock's, or the logger's median step without one."""
    if rec.time is None:
        return np.full(len(rec) - 1, LOGGER_STEP_MS, dtype=np.int64)
    return np.round(np.diff(rec.time) * LOGGER_TICKS_PER_S).astype(np.int64)


def logger_clock(passes: Sequence[Recording], *, start_pause_s: float = START_PAUSE_S,
                 pass_pause_s: float = PASS_PAUSE_S, lead_rows: int = LEAD_ROWS) -> np.ndarray:
    """The logger's ``Time`` (int32 ms, from 0) over ``passes`` written one after the other: each
    pass's own steps (LOGGER_STEP_MS without a clock), ``start_pause_s`` after the first
    ``lead_rows`` rows, ``pass_pause_s`` between two passes."""
    if not passes or lead_rows < 1 or lead_rows >= len(passes[0]):
        raise BomiError(f"logger clock: needs passes and 1 <= lead_rows < the first pass's rows, got {lead_rows}")
    steps = []
    for k, rec in enumerate(passes):
        if k:
            steps.append(np.array([round(pass_pause_s * LOGGER_TICKS_PER_S)]))
        steps.append(_steps_ms(rec))
    ms = np.concatenate(steps)
    ms[lead_rows - 1] += round(start_pause_s * LOGGER_TICKS_PER_S)
    return np.r_[0, np.cumsum(ms)].astype(np.int32)


def logger_recording(passes: Sequence[Recording], source: str, *, start_pause_s: float = START_PAUSE_S,
                     pass_pause_s: float = PASS_PAUSE_S, lead_rows: int = LEAD_ROWS) -> Recording:
    """``passes`` as one recording named ``source`` on the logger's clock (``logger_clock``), in seconds."""
    clock = logger_clock(passes, start_pause_s=start_pause_s, pass_pause_s=pass_pause_s, lead_rows=lead_rows)
    return replace(join(passes, source), time=clock / LOGGER_TICKS_PER_S)


def write_logger_passes(path: str | os.PathLike, passes: Sequence[Recording], *, overwrite: bool = False,
                        start_pause_s: float = START_PAUSE_S, pass_pause_s: float = PASS_PAUSE_S,
                        lead_rows: int = LEAD_ROWS) -> Recording:
    """Write ``passes`` as the logger's one .mat file (``logger_recording``); the recording written."""
    rec = logger_recording(passes, str(path), start_pause_s=start_pause_s, pass_pause_s=pass_pause_s,
                           lead_rows=lead_rows)
    write_logger_mat(path, rec, overwrite=overwrite)
    return rec
