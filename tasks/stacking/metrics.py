"""Per-episode metrics: pure functions over the arrays an episode logs.

Decision-stream metrics take one entry per classifier decision (one per IMU sample once the
window is full): the class the virtual participant intended and the class the chain output.
Two accuracies over the same decisions, every one: the share right (``accuracy_all_decisions``),
and the share right or excused (``accuracy_excused_transitions``): a decision within ``allowance``
samples of a change of the intended class that is still the previous class, or neutral, is excused
(the window still holds the previous posture, or the move between); ``excused_share`` says how
many were. The excused figure is never below the other.  Arm metrics take one entry per 60 Hz
control tick.  docs/task.md defines every metric.
"""
from __future__ import annotations

import enum
import re
from collections.abc import Sequence

import numpy as np

from bomi.classifier import NEUTRAL_LABEL


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, length) of every run of True in a boolean array."""
    padded = np.r_[False, np.asarray(mask, dtype=bool), False].astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b - a)) for a, b in zip(edges[::2], edges[1::2])]


def in_transition(intended: np.ndarray, allowance: int) -> np.ndarray:
    """True for the first ``allowance`` decisions after each change of the intended class."""
    intended = np.asarray(intended)
    mask = np.zeros(intended.shape, dtype=bool)
    for change in np.flatnonzero(intended[1:] != intended[:-1]) + 1:
        mask[change:change + allowance] = True
    return mask


def excused(intended: np.ndarray, decided: np.ndarray, allowance: int, neutral: int = NEUTRAL_LABEL) -> np.ndarray:
    """Wrong decisions made within ``allowance`` samples of a change of the intended class that are
    still the previous class, or neutral: late, not mistaken."""
    intended, decided = np.asarray(intended), np.asarray(decided)
    late = (decided == previous_intended(intended)) | (decided == neutral)
    return (intended != decided) & in_transition(intended, allowance) & late


def misclassified(intended: np.ndarray, decided: np.ndarray, allowance: int, neutral: int = NEUTRAL_LABEL) -> np.ndarray:
    """Decisions that differ from the intended class and are not ``excused``."""
    intended, decided = np.asarray(intended), np.asarray(decided)
    return (intended != decided) & ~excused(intended, decided, allowance, neutral)


def accuracy_excused_transitions(intended: np.ndarray, decided: np.ndarray, allowance: int,
                                 neutral: int = NEUTRAL_LABEL) -> float:
    """Share of every decision that is the intended class or ``excused``; never below
    ``accuracy_all_decisions`` of the same decisions; NaN when empty."""
    errors = misclassified(intended, decided, allowance, neutral)
    return float(1.0 - np.mean(errors)) if errors.size else float("nan")


def accuracy_all_decisions(intended: np.ndarray, decided: np.ndarray) -> float:
    """Fraction of every decision equal to the intended class (nothing excused); NaN when empty."""
    intended, decided = np.asarray(intended), np.asarray(decided)
    return float(np.mean(intended == decided)) if intended.size else float("nan")


def excused_share(intended: np.ndarray, decided: np.ndarray, allowance: int, neutral: int = NEUTRAL_LABEL) -> float:
    """Share of the decisions that are ``excused`` (the gap between the two accuracies)."""
    mask = excused(intended, decided, allowance, neutral)
    return float(np.mean(mask)) if mask.size else float("nan")


def accuracy_vs_allowance(intended: np.ndarray, decided: np.ndarray, allowances: np.ndarray) -> np.ndarray:
    """``accuracy_excused_transitions`` for each allowance (in samples) of ``allowances``."""
    return np.array([accuracy_excused_transitions(intended, decided, int(a)) for a in allowances])


def previous_intended(intended: np.ndarray) -> np.ndarray:
    """For each decision, the intended class before the last change (the class itself before any change)."""
    intended = np.asarray(intended)
    previous = intended.copy()
    changes = np.flatnonzero(intended[1:] != intended[:-1]) + 1
    for start, end in zip(changes, np.r_[changes[1:], len(intended)]):
        previous[start:end] = intended[start - 1]
    return previous


def irrelevant(intended: np.ndarray, decided: np.ndarray, neutral: int) -> np.ndarray:
    """Decisions of an active class that is neither the intended one nor the one intended before
    the last change: outputs that fit nothing the person was doing (the paper's "irrelevancy").
    Neutral outputs move nothing and are never irrelevant; a late output of the previous class is
    a transition, not irrelevant."""
    intended, decided = np.asarray(intended), np.asarray(decided)
    return (decided != neutral) & (decided != intended) & (decided != previous_intended(intended))


def longest_error_run_ms(errors: np.ndarray, sample_period_s: float) -> float:
    """Duration of the longest run of consecutive misclassified decisions, in ms."""
    longest = max((length for _, length in runs(errors)), default=0)
    return 1000.0 * longest * sample_period_s


def error_destinations(decided: np.ndarray, errors: np.ndarray, neutral: int) -> dict[str, int]:
    """How many misclassified decisions fell to neutral and how many to another active class."""
    wrong = np.asarray(decided)[np.asarray(errors, dtype=bool)]
    return {"to_neutral": int(np.sum(wrong == neutral)), "to_other_class": int(np.sum(wrong != neutral))}


def per_minute(count: int, decisions: int, sample_period_s: float) -> float:
    """``count`` events over ``decisions`` decisions made every ``sample_period_s``, per minute."""
    minutes = decisions * sample_period_s / 60.0
    return count / minutes if minutes > 0 else float("nan")


def onset_latencies(intended: np.ndarray, decided: np.ndarray, neutral: int) -> list[int | None]:
    """For each motion onset (intended change to an active class): samples to the first decision of
    that class, or None when the intent ended before the chain output it (never recognised)."""
    intended, decided = np.asarray(intended), np.asarray(decided)
    outcomes: list[int | None] = []
    for onset in np.flatnonzero(np.r_[True, intended[1:] != intended[:-1]]):
        label = intended[onset]
        if label == neutral:
            continue
        end = onset
        while end < len(intended) and intended[end] == label:
            end += 1
        hits = np.flatnonzero(decided[onset:end] == label)
        outcomes.append(int(hits[0]) if hits.size else None)
    return outcomes


def recognised(onsets: list[int | None]) -> np.ndarray:
    """The latencies (samples) of the onsets of ``onset_latencies`` that the chain recognised."""
    return np.asarray([n for n in onsets if n is not None], dtype=int)


def decision_latencies(intended: np.ndarray, decided: np.ndarray, neutral: int) -> np.ndarray:
    """``onset_latencies`` of the onsets the chain recognised, in samples."""
    return recognised(onset_latencies(intended, decided, neutral))


def unintended_displacement_mm(hand_pos: np.ndarray, intended_dir: np.ndarray) -> float:
    """Hand travel (mm) not along the direction the person wanted at that tick.

    ``intended_dir[i]`` is the wanted unit direction for the step i -> i+1, or zero when the
    person wanted the hand still (then all of the step is unintended); travel backwards along
    the wanted direction is unintended too.
    """
    step = np.diff(np.asarray(hand_pos, dtype=float), axis=0)
    wanted = np.asarray(intended_dir, dtype=float)[: len(step)]
    along = np.einsum("ij,ij->i", step, wanted)
    sideways = step - np.clip(along, 0.0, None)[:, None] * wanted
    return 1000.0 * float(np.sum(np.linalg.norm(sideways, axis=1)))


def count_changes(values: list | np.ndarray) -> int:
    """Number of ticks where the value differs from the previous tick (e.g. mode switches)."""
    values = list(values)
    return sum(a != b for a, b in zip(values, values[1:]))


def user_mode_switches(mode: list | np.ndarray, automatic_ticks: list[int]) -> int:
    """Mode changes the user made: ``mode[i]`` is the mode at tick i, before its step; a change
    from tick i to i + 1 at a tick in ``automatic_ticks`` was the assistance's."""
    automatic = set(automatic_ticks)
    return sum(a != b and i not in automatic for i, (a, b) in enumerate(zip(mode, mode[1:])))


def wrong_goal_switches(t: np.ndarray, mode: list | np.ndarray, automatic_ticks: list[int], window_s: float) -> int:
    """Automatic switches whose mode the user left by their own switch within ``window_s``: the
    next change of mode after an automatic switch at tick a is the user's, at a tick j with
    t[j] - t[a] <= window_s."""
    automatic = set(automatic_ticks)
    changes = [i for i, (a, b) in enumerate(zip(mode, mode[1:])) if a != b]
    wrong = 0
    for a in sorted(automatic):
        later = [j for j in changes if j > a]
        if later and later[0] not in automatic and t[later[0]] - t[a] <= window_s + 1e-9:
            wrong += 1
    return wrong


def cube_drops(cube_z: np.ndarray, touching: np.ndarray, fall_m: float = 0.02) -> int:
    """Times a cube left the fingers and then fell more than ``fall_m`` before they touched it again.

    ``cube_z`` and ``touching`` are (ticks, cubes).  A cube set down on its support falls only
    the release gap, so a placement is not a drop; a stack that slides off seconds after the
    release is one (the whole untouched time counts, not a fixed horizon).
    """
    cube_z, touching = np.asarray(cube_z, dtype=float), np.asarray(touching, dtype=bool)
    drops = 0
    for k in range(cube_z.shape[1]):
        touched = np.flatnonzero(touching[:, k])
        for release in np.flatnonzero(touching[:-1, k] & ~touching[1:, k]) + 1:
            later = touched[touched > release]
            untouched = cube_z[release:later[0] if later.size else len(cube_z), k]
            drops += int(cube_z[release, k] - untouched.min() > fall_m)
    return drops


class TaskPhase(str, enum.Enum):
    """The phases of the stacking task, told apart by the scripted user's step (``Goal.step``)."""

    REACH = "reach"  # to a cube and down to it
    GRASP = "grasp"  # closing on it (and a missed grasp opened again)
    CARRY = "carry"  # the held cube up and over its place
    PLACE = "place"  # the held cube lowered onto its place
    RELEASE = "release"  # opening the hand, rising clear
    OTHER = "other"  # levelling a tipped hand, opening the hand before a grasp


def phase_of(step: str, stage: str = "") -> TaskPhase:
    """The phase a step of the scripted user ("reach cube 1", "carry cube 2", ...) belongs to, at
    ``stage`` of its approach (planner ``Phase`` value: a carry's descent is the placing)."""
    if step.startswith("carry") and stage == "descend":
        return TaskPhase.PLACE
    for phase, starts in ((TaskPhase.REACH, ("reach",)), (TaskPhase.GRASP, ("grasp", "missed")),
                          (TaskPhase.CARRY, ("carry",)), (TaskPhase.RELEASE, ("release", "retreat", "done"))):
        if step.startswith(starts):
            return phase
    return TaskPhase.OTHER


def phase_times(steps: Sequence[str], dt: float, until: int | None = None,
                stages: Sequence[str] | None = None) -> dict[str, float]:
    """Seconds spent in each phase over the first ``until`` ticks (all by default); ``stages``: the
    approach stage per tick (without them no time counts as placing)."""
    out = {phase.value: 0.0 for phase in TaskPhase}
    stages = stages if stages is not None else [""] * len(steps)
    for step, stage in zip(steps[:until], stages[:until]):
        out[phase_of(step, stage).value] += dt
    return out


def mode_switch_ticks(mode: list[str], pushing: np.ndarray) -> np.ndarray:
    """Per tick: switching modes (Herlant et al. 2016): from the last tick the stick was held before a
    mode change to the first tick it is held after it (overlapping spans once)."""
    pushing = np.asarray(pushing, dtype=bool)
    held = np.flatnonzero(pushing)
    spent = np.zeros(len(pushing), dtype=bool)
    for i in (i for i in range(1, len(pushing)) if mode[i] != mode[i - 1]):
        before, after = held[held < i], held[held >= i]
        spent[before[-1] + 1 if len(before) else 0:after[0] if len(after) else len(pushing)] = True
    return spent


def mode_switch_time(mode: list[str], pushing: np.ndarray, dt: float, until: int | None = None) -> float:
    """Seconds spent switching modes (``mode_switch_ticks``), up to tick ``until``."""
    return float(mode_switch_ticks(mode, np.asarray(pushing, dtype=bool)[:until]).sum() * dt)


_CUBE = re.compile(r"cube (\d+)")


def task_phase(goal: str) -> str | None:
    """The phase of the task a step of the scripted user (``tasks.operators.planner.Goal.step``) belongs to: "reach k" until cube k is
    held, "carry k" while it is carried and set down, "finish" once both are stacked; None for a
    goal that only interrupts a phase (opening the hand, levelling it, resting)."""
    if goal.startswith(("release cube", "carry cube")):
        return f"carry {_CUBE.search(goal).group(1)}"
    found = _CUBE.search(goal)
    if found:
        return f"reach {found.group(1)}"
    if goal.startswith(("release", "retreat", "done")):
        return "finish"
    return None


def task_phases(goals: Sequence[str]) -> list[tuple[int, int, str]]:
    """(first tick, tick after the last, phase) for each run of ticks in one phase; a goal that only
    interrupts a phase stays in the phase it interrupts (at the start: the first phase)."""
    phases = [task_phase(goal) for goal in goals]
    known = [p for p in phases if p is not None]
    current = known[0] if known else "task"
    filled = []
    for phase in phases:
        current = phase or current
        filled.append(current)
    runs = []
    for k, phase in enumerate(filled):
        if runs and runs[-1][2] == phase:
            runs[-1] = (runs[-1][0], k + 1, phase)
        else:
            runs.append((k, k + 1, phase))
    return runs
