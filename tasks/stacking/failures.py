"""Why an episode failed or was slow: its mechanism, measured from what it recorded.

Progress is read from the record alone: a task phase reached for the first time (reach cube k,
carry cube k, finish: ``metrics.task_phases``), or, within a phase, the distance to its target (the
hand to the cube reached for; the carried cube to its place at B) at a new best by ``progress_m``.
An episode's *stuck period* is its longest span without progress; its mechanism is the first of
these rules that holds over that span (``Rules``; docs/task.md justifies each threshold):

1. cube lost: a cube knocked off the table, or dropped during the span, just before it, or (when the
   span repeats a phase done before, e.g. a stack undone on release) since that phase's first run;
2. arm at a limit: the stick commanded the hand to move but it did not (IK, a joint or a wall);
3. classifier stuck: a long run of decisions read as neutral while a motion was intended;
4. mode-switch storm: the mode switched far more often than a working episode switches it;
5. planner stuck: the classifier was mostly right (or there was none) and still no progress;
6. misread motion: none of the above: the decisions went mostly to other classes.

An episode is explained (``needs_mechanism``) when it failed or took more than ``SLOW_FACTOR``
times its participant's median completion time.
"""
from __future__ import annotations

import enum
import json
import statistics
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from tasks.stacking import metrics
from tasks.stacking.vocabulary import NO_RECOVERY

if TYPE_CHECKING:
    from tasks.stacking.record import EpisodeLog

SLOW_FACTOR = 2.0  # an episode slower than this many times its participant's median needs a mechanism


class Mechanism(str, enum.Enum):
    CUBE_LOST = "cube lost"
    ARM_AT_LIMIT = "arm at a limit"
    CLASSIFIER_STUCK = "classifier stuck"
    MODE_SWITCH_STORM = "mode-switch storm"
    PLANNER_STUCK = "planner stuck"
    MISREAD_MOTION = "misread motion"


@dataclass(frozen=True)
class Rules:
    """The thresholds of the mechanism rules (docs/task.md, "Why episodes fail")."""

    progress_m: float = 0.02  # a new best distance to the phase's target by this much is progress
    drop_before_s: float = 5.0  # a drop this long before the stuck span still explains it
    blocked_ratio: float = 0.25  # a commanded tick moving the hand less than this share of the command is blocked
    blocked_share: float = 0.5  # arm at a limit: at least this share of the span's commanded ticks blocked ...
    blocked_min_s: float = 5.0  # ... adding up to at least this long
    neutral_run_s: float = 10.0  # classifier stuck: a run of motion read as neutral at least this long ...
    neutral_share: float = 0.5  # ... or at least this share of the span's motion decisions read as neutral
    storm_per_min: float = 20.0  # mode-switch storm: at least this many user mode switches a minute
    planner_accuracy: float = 0.8  # planner stuck: at least this share of the span's decisions right


@dataclass(frozen=True)
class StuckPeriod:
    """The longest span without progress and what happened in it (the mechanism's evidence)."""

    mechanism: Mechanism
    start_s: float
    end_s: float
    phase: str  # the task phase the span started in
    drops: int  # cube drops in the span, just before it, or since its phase's first run (a repeated phase)
    blocked_s: float  # ticks the stick commanded a hand move that did not happen
    blocked_share: float | None  # of the span's commanded ticks (None: nothing commanded)
    hand_pos: tuple[float, float, float]  # where the hand was at the span's end (m)
    mode_switches: int  # the user's, in the span
    switches_per_min: float
    accuracy: float | None  # decisions equal to the intended class, transitions excused (None: no decisions)
    neutral_share: float | None  # of the decisions with a motion intended, those read as neutral
    neutral_run_s: float  # the longest run of a motion read as neutral
    lean: float | None  # the intended lean (0-1 of the range) during the motion read as neutral, median
    body_deg: float | None  # the body's true angle from the calibrated neutral then, median
    neutral_drift_deg: float | None  # that angle while the person meant to rest in the span, median

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    def as_dict(self) -> dict:
        out = asdict(self)
        out.update(mechanism=self.mechanism.value, duration_s=self.duration_s, hand_pos=list(self.hand_pos))
        return out


def phase_distance(phase: str, hand_pos: np.ndarray, cube_pos: np.ndarray, target_pos: np.ndarray,
                   rest_z: float) -> float | None:
    """How far one tick is from the target of ``phase`` (m): "reach k": the hand from cube k; "carry k":
    cube k from its place over B (on the table: its centre at ``rest_z``, a cube's resting height; on
    the other cube when that one is within 3 cm of B); None for a phase without a target (finish)."""
    kind, _, number = phase.partition(" ")
    if kind not in ("reach", "carry") or not number.isdigit():
        return None
    k = int(number) - 1
    if kind == "reach":
        return float(np.linalg.norm(hand_pos - cube_pos[k]))
    goal_z = rest_z
    for j in range(len(cube_pos)):
        if j != k and np.linalg.norm(cube_pos[j, :2] - target_pos[:2]) <= 0.03:
            goal_z = float(cube_pos[j, 2]) + 2 * (rest_z - float(target_pos[2]))  # a cube's height above it
    return float(np.linalg.norm(cube_pos[k] - np.array([target_pos[0], target_pos[1], goal_z])))


@dataclass
class ProgressWatch:
    """Progress tick by tick (the definition of the module docstring), for a record read back
    (``progress_ticks``) or an episode under way (``tasks.operators.recovery``)."""

    progress_m: float
    phase: str | None = None
    best: float | None = None
    seen: set[str] = field(default_factory=set)

    def update(self, phase: str, distance: float | None) -> bool:
        """Whether a tick in ``phase`` at ``distance`` from its target (None: a phase without one) is
        progress: a phase reached for the first time (not the first tick's), or a new best distance by
        ``progress_m`` within a run of the phase (a new run starts from its first distance)."""
        progress = False
        if phase != self.phase:
            progress = self.phase is not None and phase not in self.seen
            self.phase, self.best = phase, None
            self.seen.add(phase)
        if distance is None:
            return progress
        if self.best is None:
            self.best = distance
        elif distance < self.best - self.progress_m:
            self.best, progress = distance, True
        return progress


def progress_ticks(goals: Sequence[str], hand_pos: np.ndarray, cube_pos: np.ndarray, target_pos: np.ndarray,
                   progress_m: float) -> np.ndarray:
    """The ticks that made progress (``ProgressWatch``; the first tick counts)."""
    watch, progress = ProgressWatch(progress_m), [0]
    rest_z = float(np.asarray(cube_pos)[0, :, 2].min())  # the cubes start on the table
    for start, end, phase in metrics.task_phases(goals):
        for i in range(start, end):
            d = phase_distance(phase, hand_pos[i], cube_pos[i], target_pos, rest_z)
            if watch.update(phase, d):
                progress.append(i)
            if d is None:
                break
    return np.unique(progress)


def longest_gap(progress: np.ndarray, ticks: int) -> tuple[int, int]:
    """(first tick, tick after the last) of the longest span between progress ticks (the episode's
    end closes the last span)."""
    bounds = np.r_[progress, ticks]
    k = int(np.argmax(np.diff(bounds)))
    return int(bounds[k]), int(bounds[k + 1])


def blocked_ticks(hand_pos: np.ndarray, commanded: np.ndarray, dt: float, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """(commanded, blocked) masks over the steps i -> i+1: the stick commanded a hand velocity; the
    hand then moved along it less than ``ratio`` of the commanded distance."""
    step = np.diff(np.asarray(hand_pos, dtype=float), axis=0)
    command = np.asarray(commanded, dtype=float)[: len(step)]
    speed = np.linalg.norm(command, axis=1)
    moving = speed > 0
    along = np.einsum("ij,ij->i", step, command) / np.where(moving, speed, 1.0)
    return moving, moving & (along < ratio * speed * dt)


def _median(values: np.ndarray) -> float | None:
    values = np.asarray(values, dtype=float)
    values = values[~np.isnan(values)]
    return float(np.median(values)) if values.size else None


def stuck_period(log: "EpisodeLog", rules: Rules = Rules()) -> StuckPeriod | None:
    """The episode's longest span without progress, its evidence and mechanism (None for a record of
    fewer than two ticks)."""
    t, n = log.t, len(log.t)
    if n < 2:
        return None
    dt = float(t[1] - t[0])
    a, b = longest_gap(progress_ticks(log.goals, log.hand_pos, log.cube_pos, log.target_pos, rules.progress_m), n)
    start_s, end_s = float(t[a]), float(t[b - 1]) + dt
    runs = metrics.task_phases(log.goals)
    phase = next((p for s, e, p in runs if s <= a < e), "task")
    before = drop_window_start(runs, phase, a, int(round(rules.drop_before_s / dt)))
    drops = metrics.cube_drops(log.cube_pos[before:b, :, 2], log.touching[before:b])
    commanded, blocked = (blocked_ticks(log.hand_pos[a:b + 1], log.commanded[a:b + 1], dt, rules.blocked_ratio)
                          if log.commanded is not None else (np.zeros(0, bool), np.zeros(0, bool)))
    automatic = [s.tick - a for s in log.automatic if a <= s.tick < b]
    switches = metrics.user_mode_switches(list(log.mode[a:b]), automatic)
    minutes = (end_s - start_s) / 60.0
    evidence = dict(mechanism=Mechanism.MISREAD_MOTION, start_s=start_s, end_s=end_s, phase=phase, drops=drops,
                    blocked_s=float(blocked.sum() * dt),
                    blocked_share=float(blocked.sum() / commanded.sum()) if commanded.any() else None,
                    hand_pos=tuple(float(v) for v in log.hand_pos[b - 1]), mode_switches=switches,
                    switches_per_min=switches / minutes if minutes > 0 else 0.0, accuracy=None, neutral_share=None,
                    neutral_run_s=0.0, lean=None, body_deg=None, neutral_drift_deg=None)
    d = log.decisions
    if d is not None:
        evidence.update(decision_evidence(log, start_s, end_s))
    evidence["mechanism"] = classify(evidence, failure=log.failure, rules=rules)
    return StuckPeriod(**evidence)


def drop_window_start(runs: list[tuple[int, int, str]], phase: str, start: int, before_ticks: int) -> int:
    """The first tick whose drops explain a stuck span beginning at ``start`` in ``phase``: ``before_ticks``
    before it; or, when the span repeats a phase the task had left (``runs``: ``metrics.task_phases``), the
    end of that phase's first run, for a drop since then is what sent the task back (a stack knocked over
    as the hand let go, and the cubes taken up again)."""
    first = next((e for s, e, p in runs if p == phase), start)
    return max(0, min(start - before_ticks, first if first < start else start))


def decision_evidence(log: "EpisodeLog", start_s: float, end_s: float) -> dict:
    """What the classifier did in the span: accuracy, the motion read as neutral (share, longest run,
    the lean and the body's angle then) and the neutral posture's drift."""
    d = log.decisions
    settled = ~metrics.in_transition(d.intended, log.allowance)
    to_neutral = (d.intended != log.neutral) & (d.decided == log.neutral) & settled
    inside = (d.t >= start_s) & (d.t < end_s)
    motion = inside & (d.intended != log.neutral)
    runs = [length for first, length in metrics.runs(to_neutral & inside)]
    resting = inside & (d.intended == log.neutral) & settled
    stuck = to_neutral & inside
    return dict(
        accuracy=float(np.mean(d.intended[inside & settled] == d.decided[inside & settled]))
        if (inside & settled).any() else None,
        neutral_share=float(stuck.sum() / motion.sum()) if motion.any() else None,
        neutral_run_s=max(runs, default=0) * log.sample_period,
        lean=_median(d.lean[stuck]) if d.lean is not None else None,
        body_deg=_median(d.body_deg[stuck]) if d.body_deg is not None else None,
        neutral_drift_deg=_median(d.body_deg[resting]) if d.body_deg is not None else None)


def classify(evidence: dict, failure: str | None, rules: Rules = Rules()) -> Mechanism:
    """The first rule that holds over the stuck span (the module docstring's order)."""
    if (failure or "").endswith("knocked off the table") or evidence["drops"] > 0:
        return Mechanism.CUBE_LOST
    if (evidence["blocked_share"] or 0.0) >= rules.blocked_share and evidence["blocked_s"] >= rules.blocked_min_s:
        return Mechanism.ARM_AT_LIMIT
    if evidence["neutral_run_s"] >= rules.neutral_run_s or (evidence["neutral_share"] or 0.0) >= rules.neutral_share:
        return Mechanism.CLASSIFIER_STUCK
    if evidence["switches_per_min"] >= rules.storm_per_min:
        return Mechanism.MODE_SWITCH_STORM
    if evidence["accuracy"] is None or evidence["accuracy"] >= rules.planner_accuracy:
        return Mechanism.PLANNER_STUCK
    return Mechanism.MISREAD_MOTION


def needs_mechanism(records: list[dict]) -> list[bool]:
    """Per record (``episode.summarize``, one participant and operator): failed, or slower than
    ``SLOW_FACTOR`` times the median completion time of the successes."""
    times = [r["completion_time"] for r in records if r["success"]]
    median = statistics.median(times) if times else None
    return [not r["success"] or (median is not None and r["completion_time"] > SLOW_FACTOR * median)
            for r in records]


NOT_RECORDED = "not recorded"  # a record written before the mechanisms were (a resumed sweep's older episodes)


def mechanism_rows(records: list[dict]) -> list[dict]:
    """Per participant, operator, (a sweep's) settings and recovery: the episodes, how many failed or were
    slow, and the seeds each mechanism explains among those."""
    groups: dict[str, list[dict]] = {}
    for r in records:
        key = [r["participant"], r["operator"], r.get("settings", {}), r.get("recovery", NO_RECOVERY)]
        groups.setdefault(json.dumps(key), []).append(r)
    rows = []
    for key, rs in groups.items():
        participant, operator, settings, recovery = json.loads(key)
        explained = [r for r, needed in zip(rs, needs_mechanism(rs)) if needed]
        seeds: dict[str, list[int]] = {m.value: [] for m in Mechanism}
        for r in explained:
            seeds.setdefault((r.get("stuck") or {}).get("mechanism", NOT_RECORDED), []).append(r["seed"])
        rows.append({"participant": participant, "operator": operator, "settings": settings, "recovery": recovery,
                     "episodes": len(rs),
                     "failed": sum(not r["success"] for r in rs), "slow": sum(r["success"] for r in explained),
                     "mechanisms": seeds})
    return rows


def summary(log: "EpisodeLog") -> dict | None:
    """``stuck_period`` as a JSON-ready dict (None for a record of fewer than two ticks)."""
    period = stuck_period(log)
    return None if period is None else period.as_dict()
