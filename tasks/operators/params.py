"""The scripted user's parameters (``operator.toml``, configuration as data): its timing,
deflections, tolerances and heights, the human model around it and the recovery it has."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from bomi.config_files import beside, check_table, config_path, load_toml, number, typed
from tasks.stacking.vocabulary import NO_RECOVERY, RecoveryAction

DEFAULT_OPERATOR_FILE = Path(__file__).with_name("operator.toml")
NO_HUMAN_MODEL = "none"  # [human] model: the fixed timing of [timing] alone


@dataclass(frozen=True)
class RecoveryParams:
    """The operator file's optional ``[recovery]`` table (absent: no recovery, the paper's comparison)."""

    actions: frozenset[RecoveryAction] = frozenset()
    stuck_s: float = 90.0  # s without progress before the person acts
    obeyed_share: float = 0.8  # the arm answered at least this share of the stick moves asked: the interface works
    settle_s: float = 2.0  # rezero: s held still before the neutral is taken
    pause_s: float = 30.0  # pause: s of rest

    @property
    def label(self) -> str:
        """The actions as a results row names them ("none", "backoff+rezero")."""
        return "+".join(sorted(a.value for a in self.actions)) or NO_RECOVERY


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


@dataclass(frozen=True)
class OperatorParams:
    reaction_time: float
    pause_between_moves: float
    anticipation: float
    squeeze_time: float
    button_patience: float
    coarse: float
    fine: float
    turn: float
    coast_share: float
    full_speed: float
    full_turn_speed: float
    stop: float
    align: float
    placed: float
    target_zone: float
    yaw_deg: float
    tilt_deg: float
    hover: float
    carry_clearance: float
    grasp_offset: float
    release_gap: float
    retreat: float
    open_closure: float
    miss_time: float
    reach: float
    turn_reach: float
    turn_clearance: float
    settled_share: float
    rise_margin: float
    restart: float
    learning_rate: float
    max_anticipation: float
    max_wait: float
    still_speed: float
    coasting_min_speed: float
    stall_time: float
    human_model: str = NO_HUMAN_MODEL  # a human-model TOML (tasks.operators.human) around this user, or none
    recovery: RecoveryParams = RecoveryParams()


_SECTIONS = {
    "timing": ("reaction_time", "pause_between_moves", "anticipation", "squeeze_time", "button_patience"),
    "deflection": ("coarse", "fine", "turn", "coast_share", "full_speed", "full_turn_speed"),
    "tolerance": ("stop", "align", "placed", "target_zone", "yaw_deg", "tilt_deg"),
    "heights": ("hover", "carry_clearance", "grasp_offset", "release_gap", "retreat"),
    "fingers": ("open_closure", "miss_time"),
    "planner": ("reach", "turn_reach", "turn_clearance", "settled_share", "rise_margin", "restart"),
    "learning": ("learning_rate", "max_anticipation", "max_wait", "still_speed", "coasting_min_speed", "stall_time"),
}
_MAY_BE_NEGATIVE = {"grasp_offset"}


def load_operator(path: Path | str = DEFAULT_OPERATOR_FILE, overrides: Mapping[str, Any] | None = None) -> OperatorParams:
    """Read and validate an operator TOML file (a path, or a shipped one by name), with ``overrides``
    (dotted keys, ``{"timing.reaction_time": 0.4}``) set before validation; raise BomiError naming
    the file and the fault."""
    params = load_toml(path, DEFAULT_OPERATOR_FILE.parent, "operator", _parse_operator, overrides)
    # [human] model: a file relative to this operator file, not to the working directory
    return replace(params, human_model=beside(params.human_model, config_path(path, DEFAULT_OPERATOR_FILE.parent)))


def _parse_operator(data: dict, source: str) -> OperatorParams:
    """The operator tables as OperatorParams; ValueError names what is wrong (load_toml adds the file)."""
    values: dict[str, float] = {}
    for section, keys in _SECTIONS.items():
        table = check_table(data.get(section), f"[{section}]", keys)
        for key in keys:
            values[key] = number(table, key, f"[{section}]", -math.inf if key in _MAY_BE_NEGATIVE else 0.0)
    check_table(data, "operator", (*_SECTIONS, "human", "recovery"))
    human = check_table(data.get("human", {"model": NO_HUMAN_MODEL}), "[human]", ("model",), ("model",))
    model = typed(human, "model", str, "[human]")
    if not model:
        raise ValueError(f'[human]: model must name a human-model file, or be "{NO_HUMAN_MODEL}"')
    # what the person has seen the hand do at full deflection: the JACO moves at most 0.2 m/s and
    # turns its wrist at most about 0.6 rad/s, so a person's belief beyond 1 m/s or 2 pi rad/s (or of 0) is a typo
    if not 0 < values["full_speed"] <= 1 or not 0 < values["full_turn_speed"] <= 2 * math.pi:
        raise ValueError("[deflection] needs 0 < full_speed <= 1 (m/s) and 0 < full_turn_speed <= 6.28 (rad/s)")
    if not 0 < values["fine"] <= values["coarse"] <= 1 or not 0 < values["turn"] <= 1:
        raise ValueError("[deflection] needs 0 < fine <= coarse <= 1 and 0 < turn <= 1")
    if not 0 < values["open_closure"] < 1:
        raise ValueError("[fingers] open_closure must lie strictly between 0 and 1")
    if values["stop"] <= 0 or values["align"] <= 0 or values["placed"] <= 0:
        raise ValueError("[tolerance] stop, align and placed must be positive")
    if not 0 < values["learning_rate"] <= 1:
        raise ValueError("[learning] learning_rate must lie in (0, 1]")
    if values["settled_share"] <= 0:
        raise ValueError("[planner] settled_share must be positive")
    return OperatorParams(**values, human_model=model, recovery=_parse_recovery(data.get("recovery")))


def _parse_recovery(table: dict | None) -> RecoveryParams:
    """The ``[recovery]`` table (every key optional; absent: no recovery)."""
    if table is None:
        return RecoveryParams()
    check_table(table, "[recovery]", ("actions", "stuck_s", "obeyed_share", "settle_s", "pause_s"))
    d = RecoveryParams()
    actions = typed(table, "actions", str, "[recovery]", NO_RECOVERY)
    stuck_s = number(table, "stuck_s", "[recovery]", 0.0, default=d.stuck_s)
    if stuck_s <= 0:
        raise ValueError("[recovery] stuck_s must be positive")
    return RecoveryParams(parse_recovery_actions(actions, "[recovery] actions"), stuck_s,
                          number(table, "obeyed_share", "[recovery]", 0.0, 1.0, d.obeyed_share),
                          number(table, "settle_s", "[recovery]", 0.0, default=d.settle_s),
                          number(table, "pause_s", "[recovery]", 0.0, default=d.pause_s))

