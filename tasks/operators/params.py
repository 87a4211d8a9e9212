"""The scripted user's parameters (``operator.toml``, configuration as data): its timing,
deflections, tolerances and heights, the human model around it and the recovery it has.

The file is read by ``bomi.config_files``: each of its tables is a dataclass below (its keys the
fields, its checks the ``__post_init__``), ``_OperatorFile`` the whole file. ``OperatorParams``, what the
planner reads, holds every key of the sections at once: it is each section's dataclass (their subclass).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Annotated, Any

from bomi.config_files import (at_most, beside, coerce, config_path, from_table, load_toml, positive, section_keys,
                               within)
from tasks.stacking.vocabulary import NO_RECOVERY, RecoveryAction

DEFAULT_OPERATOR_FILE = Path(__file__).with_name("operator.toml")
NO_HUMAN_MODEL = "none"  # [human] model: the fixed timing of [timing] alone


def parse_recovery_actions(text: str, where: str) -> frozenset[RecoveryAction]:
    """``none`` or a comma list of actions (``rezero,backoff``); ValueError names ``where`` (if any) and the fault."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if names == [NO_RECOVERY]:
        return frozenset()
    known = {a.value: a for a in RecoveryAction}
    bad = [n for n in names if n not in known]
    if not names or bad:
        raise ValueError(f"{where + ': ' if where else ''}{', '.join(bad) or 'an empty list'} is not {NO_RECOVERY} "
                         f"or a comma list of {', '.join(known)}")
    return frozenset(known[n] for n in names)


def _recovery_actions(value: Any) -> frozenset[RecoveryAction]:
    """[recovery] actions as the file writes them: a string (``parse_recovery_actions``)."""
    return parse_recovery_actions(coerce(value, str), "")


@dataclass(frozen=True)
class RecoveryParams:
    """The operator file's optional ``[recovery]`` table (absent: no recovery, the paper's comparison)."""

    actions: Annotated[frozenset[RecoveryAction], _recovery_actions] = frozenset()
    stuck_s: float = 90.0  # s without progress before the person acts
    obeyed_share: float = 0.8  # the arm answered at least this share of the stick moves asked: the interface works
    settle_s: float = 2.0  # rezero: s held still before the neutral is taken
    pause_s: float = 30.0  # pause: s of rest

    def __post_init__(self) -> None:
        positive(self, "stuck_s")
        within(self, 0.0, 1.0, "obeyed_share")
        within(self, 0.0, math.inf, "settle_s", "pause_s")

    @property
    def label(self) -> str:
        """The actions as a results row names them ("none", "backoff+rezero")."""
        return "+".join(sorted(a.value for a in self.actions)) or NO_RECOVERY


def _at_least_0(section: Any, cls: type, *but: str) -> None:
    """Every key of the section ``cls`` (but ``but``) is a number >= 0 (distances, times, shares) in
    ``section`` (a ``cls``, or the OperatorParams that is one)."""
    within(section, 0.0, math.inf, *(f.name for f in fields(cls) if f.name not in but))


@dataclass(frozen=True)
class _Timing:
    reaction_time: float
    pause_between_moves: float
    anticipation: float
    squeeze_time: float
    button_patience: float

    def __post_init__(self) -> None:
        _at_least_0(self, _Timing)


@dataclass(frozen=True)
class _Deflection:
    coarse: float
    fine: float
    turn: float
    coast_share: float
    full_speed: float
    full_turn_speed: float

    def __post_init__(self) -> None:
        _at_least_0(self, _Deflection)
        positive(self, "fine", "turn", "full_speed", "full_turn_speed")
        # full_speed, full_turn_speed: what the person has seen the hand do at full deflection; the JACO moves at
        # most 0.2 m/s and turns its wrist at most about 0.6 rad/s, so a belief beyond 1 m/s or 2 pi rad/s is a typo
        at_most(self, 1.0, "coarse", "turn", "full_speed")
        within(self, 0.0, 2 * math.pi, "full_turn_speed")
        if self.fine > self.coarse:
            raise ValueError(f"fine: must be at most coarse ({self.coarse!r}), got {self.fine!r}")


@dataclass(frozen=True)
class _Tolerance:
    stop: float
    align: float
    placed: float
    target_zone: float
    yaw_deg: float
    tilt_deg: float

    def __post_init__(self) -> None:
        _at_least_0(self, _Tolerance)
        positive(self, "stop", "align", "placed")


@dataclass(frozen=True)
class _Heights:
    hover: float
    carry_clearance: float
    grasp_offset: float  # of either sign
    release_gap: float
    retreat: float

    def __post_init__(self) -> None:
        _at_least_0(self, _Heights, "grasp_offset")


@dataclass(frozen=True)
class _Fingers:
    open_closure: float
    miss_time: float

    def __post_init__(self) -> None:
        _at_least_0(self, _Fingers)
        if not 0 < self.open_closure < 1:
            raise ValueError(f"open_closure: must lie strictly between 0 and 1, got {self.open_closure!r}")


@dataclass(frozen=True)
class _Planner:
    reach: float
    turn_reach: float
    turn_clearance: float
    settled_share: float
    rise_margin: float
    restart: float

    def __post_init__(self) -> None:
        _at_least_0(self, _Planner)
        positive(self, "settled_share")


@dataclass(frozen=True)
class _Learning:
    learning_rate: float
    max_anticipation: float
    max_wait: float
    still_speed: float
    coasting_min_speed: float
    stall_time: float

    def __post_init__(self) -> None:
        _at_least_0(self, _Learning)
        positive(self, "learning_rate")
        at_most(self, 1.0, "learning_rate")


@dataclass(frozen=True)
class _Human:
    model: str

    def __post_init__(self) -> None:
        if not self.model:
            raise ValueError(f'model: must name a human-model file, or be "{NO_HUMAN_MODEL}"')


@dataclass(frozen=True)
class OperatorParams(_Learning, _Planner, _Fingers, _Heights, _Tolerance, _Deflection, _Timing):
    """Every key of the operator file's sections (fields in the file's order: [timing] first), its
    [human] model and its [recovery]."""

    human_model: str = NO_HUMAN_MODEL  # a human-model TOML (tasks.operators.human) around this user, or none
    recovery: RecoveryParams = RecoveryParams()

    def __post_init__(self) -> None:
        for section in OperatorParams.__bases__:
            section.__post_init__(self)


@dataclass(frozen=True)
class _OperatorFile:
    timing: _Timing
    deflection: _Deflection
    tolerance: _Tolerance
    heights: _Heights
    fingers: _Fingers
    planner: _Planner
    learning: _Learning
    human: _Human = _Human(NO_HUMAN_MODEL)
    recovery: RecoveryParams = RecoveryParams()


def load_operator(path: Path | str = DEFAULT_OPERATOR_FILE, overrides: Mapping[str, Any] | None = None) -> OperatorParams:
    """Read and validate an operator TOML file (a path, or a shipped one by name), with ``overrides``
    (dotted keys, ``{"timing.reaction_time": 0.4}``) set before validation; raise BomiError naming
    the file and the fault."""
    params = load_toml(path, DEFAULT_OPERATOR_FILE.parent, "operator", _parse_operator, overrides)
    # [human] model: a file relative to this operator file, not to the working directory
    return replace(params, human_model=beside(params.human_model, config_path(path, DEFAULT_OPERATOR_FILE.parent)))


def _parse_operator(data: dict, source: str) -> OperatorParams:
    """The operator file as OperatorParams; ValueError names what is wrong (load_toml adds the file)."""
    file = from_table(_OperatorFile, data)
    keys = section_keys(file.timing, file.deflection, file.tolerance, file.heights, file.fingers, file.planner,
                        file.learning)
    return OperatorParams(**keys, human_model=file.human.model, recovery=file.recovery)
