"""Where an episode's time and its irrelevant outputs go: pure functions over an ``EpisodeLog``.

**Time budget** (``time_budget``): every control tick up to the completion (the whole record for a
failure) belongs to exactly one ``Part``, the first of this order that holds, so the parts sum to
the completion time (the neutral calibration runs before the task's clock starts: never counted).
Per tick i (the step from ``t[i]`` to ``t[i + 1]``), the *stick class* is the BoMI decision in
force: the latest decision whose sample time is at or before ``t[i]`` (decisions reach the stick a
frame's delivery later, under two ticks: the split is that coarse); a *wrong* decision is an
active class that is not the intended one and not ``metrics.excused``.

1. ``RECOVERY``: inside a recovery action (``log.recoveries``, start to end).
2. ``MISREAD``: the stick class is wrong: the arm is driven by a class the person did not intend.
3. ``CORRECTION``: undoing a misread: after a run of misread ticks that moved the hand by D (at
   least ``CORRECTION_MIN_M``), the first push whose wanted direction points against D
   (``intended_dir . D / |D| < -0.5``) and the pushes against D after it, until the hand has gone
   back ``|D|`` along D's line, a push not against D begins, or the next misread does. (A misread
   press, a button class read but not meant, is undone by presses: ``MODE_SWITCH`` time.)
4. ``MODE_SWITCH``: within a mode change's span as ``metrics.mode_switch_time`` counts it (from the
   last tick the stick was pushed before the change to the first tick it is pushed after it).
5. ``REACTION``: a push held (``pushing``) that is not answered yet: from its first tick to its
   first answered tick. Through the BoMI a tick is answered when the decision in force is the
   intended class, active (the body's reaction and move, the window and the vote come first);
   through a stick (no decisions) every pushed tick is answered.
6. ``MOVEMENT``: a push held and answered.
7. ``LAPSE``: a push held, not answered, after it had been (the chain fell back to neutral, or to
   the previous class, during the hold).
8. ``WAIT``: no push held, the hand commanded (a late decision of the posture let go) or moving
   faster than ``still_speed`` (the person still, watching the arm coast).
9. ``REST``: no push held, the hand still: the person's own time (choice reactions, checks, looks,
   pauses; a press that changed no mode).

``commanded`` is the hand's linear velocity: a turn or a grip coasting after a let-go is ``REST``.

**Irrelevant decisions** (``metrics.irrelevant``: an active class neither intended nor the one
intended before the last change of intent; neutral is never irrelevant). Each is given the first
``Context`` of this order that holds, from the runs of equal intended class around it: its run
(class I, started s decisions before it), the run before (class P), the one before that (class Q),
and the transition ``allowance`` (``log.allowance`` decisions); a *short rest* is a neutral run
shorter than the allowance between two active runs.

1. ``BUTTON_HOLD``: a button class (B1, B2) is entered or held (I).
2. ``BUTTON_EXIT``: a button class was left within the allowance (P; or Q across a short rest).
3. ``OFFSET``: within the allowance of a neutral I entered from an active P: the body returning
   from a hold, whether another motion follows soon or not.
4. ``MOTION_TO_MOTION``: within the allowance of an active I entered from another active class
   straight (P active) or across a short rest (P neutral and short, Q active).
5. ``ONSET``: within the allowance of an active I entered from rest (a neutral P at least the
   allowance long, or the record's first run).
6. ``MODE_CHANGE``: past the allowance, at a tick within a mode change's span (part 4 above).
7. ``HOLD_DRIFT``: past the allowance of an active I: well inside a steady hold.
8. ``REST_DRIFT``: past the allowance of a neutral I: well inside a steady rest (the record's
   first run included).

**The vote** is not a moment of the person's behaviour but a stage of the chain: a majority over
the last ``vote_length`` labels, a tie going to the most recent of the tied labels
(``bomi.classifier.MajorityVote``); it can only output a label the window's classifier gave within
those labels. The record keeps only the voted output, so ``vote_effect`` needs the pre-vote labels
(a caller that recorded them): the irrelevant outputs the vote made (its input relevant) and the
irrelevant inputs it removed.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sim.joystick import BUTTONS
from tasks.stacking import metrics

if TYPE_CHECKING:
    from tasks.stacking.record import EpisodeLog

CORRECTION_MIN_M = 0.001  # a misread that moved the hand less than this has nothing to undo
AGAINST = -0.5  # a push undoes a misread's displacement D when its direction . D / |D| is below this


class Part(str, enum.Enum):
    """The parts of the time budget, in the order a tick is given the first that holds."""

    RECOVERY = "recovery"
    MISREAD = "misread"
    CORRECTION = "correction"
    MODE_SWITCH = "mode switch"
    REACTION = "reaction"
    MOVEMENT = "movement"
    LAPSE = "lapse"
    WAIT = "wait"
    REST = "rest"


class Context(str, enum.Enum):
    """Where an irrelevant decision falls, in the order the first that holds is given."""

    BUTTON_HOLD = "button hold"
    BUTTON_EXIT = "button exit"
    OFFSET = "offset"
    MOTION_TO_MOTION = "motion to motion"
    ONSET = "onset"
    MODE_CHANGE = "mode change"
    HOLD_DRIFT = "hold drift"
    REST_DRIFT = "rest drift"


# ------------------------------------------------------------------------------------ time budget
def task_ticks(log: EpisodeLog) -> int:
    """The ticks up to the completion (all of them for a failure)."""
    if log.completion_time is None:
        return len(log.t)
    return int(np.searchsorted(log.t, log.completion_time - 1e-9, side="left"))


def wrong_decisions(log: EpisodeLog) -> np.ndarray:
    """Per decision: an active class that is not the intended one and not excused (``metrics.excused``)."""
    d = log.decisions
    return ((d.decided != log.neutral) & (d.decided != d.intended)
            & ~metrics.excused(d.intended, d.decided, log.allowance, log.neutral))


def decision_in_force(log: EpisodeLog) -> np.ndarray:
    """Per tick: the index of the latest decision made at or before it (-1: none yet)."""
    return np.searchsorted(log.decisions.t, log.t + 1e-9, side="right") - 1


def misread_ticks(log: EpisodeLog) -> np.ndarray:
    """Per tick: the decision in force is wrong (``wrong_decisions``); never for a record without decisions."""
    if log.decisions is None or len(log.decisions.t) == 0:
        return np.zeros(len(log.t), dtype=bool)
    k = decision_in_force(log)
    return (k >= 0) & wrong_decisions(log)[np.maximum(k, 0)]


def correction_ticks(hand_pos: np.ndarray, intended_dir: np.ndarray, pushing: np.ndarray,
                     misread: np.ndarray) -> np.ndarray:
    """Per tick: a push undoing the displacement of the misread run before it (module docstring, part 3)."""
    hand_pos, intended_dir = np.asarray(hand_pos, float), np.asarray(intended_dir, float)
    n = len(hand_pos)
    pushes = [(a, a + length) for a, length in metrics.runs(pushing)]
    out = np.zeros(n, dtype=bool)
    misreads = metrics.runs(misread)
    for (start, length), following in zip(misreads, [s for s, _ in misreads[1:]] + [n]):
        end = start + length
        moved = hand_pos[min(end, n - 1)] - hand_pos[start]
        size = float(np.linalg.norm(moved))
        if size >= CORRECTION_MIN_M:
            _undo(hand_pos, intended_dir, pushes, end, following, moved / size, size, out)
    return out


def _undo(hand_pos: np.ndarray, intended_dir: np.ndarray, pushes: list[tuple[int, int]], end: int, following: int,
          unit: np.ndarray, size: float, out: np.ndarray) -> None:
    """Mark in ``out`` the ticks of the pushes in [end, following) against ``unit`` (from the first
    one on, while each push is against it), until the hand has gone back ``size`` along it."""
    undone = 0.0
    for a, b in pushes:
        a, b = max(a, end), min(b, following)
        if a >= b:
            if a >= following:
                return
            continue
        for i in range(a, b):
            if float(intended_dir[i] @ unit) >= AGAINST:
                return
            out[i] = True
            if i + 1 < len(hand_pos):
                undone += max(0.0, -float((hand_pos[i + 1] - hand_pos[i]) @ unit))
            if undone >= size:
                return


def answered_ticks(log: EpisodeLog) -> np.ndarray:
    """Per tick: the push held is answered (module docstring, part 5): a stick answers every push;
    through the BoMI the decision in force is the intended class, active."""
    pushing = np.asarray(log.pushing, dtype=bool)
    if log.decisions is None:
        return pushing
    d = log.decisions
    if len(d.t) == 0:
        return np.zeros(len(log.t), dtype=bool)
    k = decision_in_force(log)
    read = (d.decided == d.intended) & (d.decided != log.neutral)
    return pushing & (k >= 0) & read[np.maximum(k, 0)]


def push_parts(pushing: np.ndarray, answered: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(reaction, movement, lapse) masks over the ticks of pushes (module docstring, parts 5-7)."""
    pushing, answered = np.asarray(pushing, bool), np.asarray(answered, bool) & np.asarray(pushing, bool)
    reaction = np.zeros(len(pushing), dtype=bool)
    for start, length in metrics.runs(pushing):
        first = np.flatnonzero(answered[start:start + length])
        reaction[start:start + (first[0] if first.size else length)] = True
    return reaction, answered, pushing & ~answered & ~reaction


def time_budget(log: EpisodeLog, still_speed: float) -> dict[Part, float]:
    """Seconds per ``Part`` over ``task_ticks`` (the module docstring's definitions); they sum to
    ``task_ticks`` x dt, the completion time to within a tick. ``still_speed``: the hand speed (m/s)
    below which the person sees it at rest (the operator file's ``still_speed``)."""
    if log.pushing is None or log.commanded is None:
        raise ValueError(f"the record of {log.participant} {log.operator} seed {log.seed} has no per-tick pushing "
                         "and commanded arrays: no time budget")
    n = task_ticks(log)
    if n == 0:
        return {part: 0.0 for part in Part}
    dt = float(log.t[1] - log.t[0]) if len(log.t) > 1 else 0.0
    pushing = np.asarray(log.pushing, dtype=bool)
    commanded = np.asarray(log.commanded, dtype=float)
    step = np.linalg.norm(np.diff(np.asarray(log.hand_pos, float), axis=0), axis=1)
    speed = np.r_[step / dt if dt > 0 else step, 0.0]
    misread = misread_ticks(log)
    recovery = np.zeros(len(log.t), dtype=bool)
    for event in log.recoveries:
        recovery[(log.t >= event.start_s) & (log.t < event.end_s)] = True
    reaction, movement, lapse = push_parts(pushing, answered_ticks(log))
    moving = (np.linalg.norm(commanded, axis=1) > 0) | (speed > still_speed)
    masks = {
        Part.RECOVERY: recovery,
        Part.MISREAD: misread,
        Part.CORRECTION: correction_ticks(log.hand_pos, log.intended_dir, pushing, misread),
        Part.MODE_SWITCH: metrics.mode_switch_ticks(list(log.mode), pushing),
        Part.REACTION: reaction,
        Part.MOVEMENT: movement,
        Part.LAPSE: lapse,
        Part.WAIT: ~pushing & moving,
        Part.REST: np.ones(len(log.t), dtype=bool),
    }
    taken = np.zeros(len(log.t), dtype=bool)
    out = {}
    for part, mask in masks.items():
        mine = mask & ~taken
        out[part] = float(mine[:n].sum() * dt)
        taken |= mine
    return out


# ------------------------------------------------------------------------------------ irrelevant outputs
def button_labels(log: EpisodeLog) -> frozenset[int]:
    """The labels of the button classes: ``class_names`` lists the functions by label, from 0 (neutral)."""
    return frozenset(label for label, name in enumerate(log.class_names) if name in BUTTONS)


@dataclass(frozen=True)
class IntentRun:
    """A run of decisions of one intended class: [start, end)."""

    start: int
    end: int
    label: int


def intent_runs(intended: np.ndarray) -> list[IntentRun]:
    """The runs of equal intended class, in order."""
    intended = np.asarray(intended)
    edges = np.r_[0, np.flatnonzero(intended[1:] != intended[:-1]) + 1, len(intended)]
    return [IntentRun(int(a), int(b), int(intended[a])) for a, b in zip(edges[:-1], edges[1:])]


def decision_contexts(log: EpisodeLog) -> list[Context]:
    """The ``Context`` of every decision (module docstring), whether irrelevant or not."""
    d, neutral, allowance = log.decisions, log.neutral, log.allowance
    buttons = button_labels(log)
    runs = intent_runs(d.intended)
    switching = np.zeros(len(d.t), dtype=bool)
    if log.pushing is not None and len(log.t):
        spans = metrics.mode_switch_ticks(list(log.mode), np.asarray(log.pushing, bool))
        tick = np.clip(np.searchsorted(log.t, d.t, side="right") - 1, 0, len(log.t) - 1)
        switching = spans[tick]

    def short_rest(r: int) -> bool:
        run = runs[r]
        return (run.label == neutral and run.end - run.start < allowance and 0 < r < len(runs) - 1
                and runs[r - 1].label != neutral and runs[r + 1].label != neutral)

    out: list[Context] = []
    for r, run in enumerate(runs):
        p = runs[r - 1] if r > 0 else None
        q = runs[r - 2] if r > 1 else None
        across = p is not None and short_rest(r - 1)  # this run follows a short rest
        for k in range(run.start, run.end):
            s = k - run.start
            early = s < allowance
            left = ({p.label} if p is not None and early else set()) | ({q.label} if across and early else set())
            if run.label in buttons:
                out.append(Context.BUTTON_HOLD)
            elif left & buttons:
                out.append(Context.BUTTON_EXIT)
            elif early and run.label == neutral and p is not None:
                out.append(Context.OFFSET)
            elif early and run.label != neutral and p is not None and (p.label != neutral or across):
                out.append(Context.MOTION_TO_MOTION)
            elif early and run.label != neutral:
                out.append(Context.ONSET)
            elif switching[k]:
                out.append(Context.MODE_CHANGE)
            else:
                out.append(Context.HOLD_DRIFT if run.label != neutral else Context.REST_DRIFT)
    return out


def irrelevant_mask(log: EpisodeLog) -> np.ndarray:
    """``metrics.irrelevant`` of the record's decisions."""
    d = log.decisions
    return metrics.irrelevant(d.intended, d.decided, log.neutral)


def irrelevant_by_context(log: EpisodeLog) -> dict[Context, int]:
    """How many irrelevant decisions fall in each ``Context``."""
    contexts = decision_contexts(log)
    wild = irrelevant_mask(log)
    counts = {context: 0 for context in Context}
    for k in np.flatnonzero(wild):
        counts[contexts[k]] += 1
    return counts


@dataclass(frozen=True)
class IrrelevantRun:
    """A run of consecutive irrelevant decisions: when, how long, what was intended around it and
    the context of its decisions (the most frequent; the first on a tie)."""

    t: float
    duration_ms: float
    context: Context
    intended: tuple[int, ...]  # the intended classes over the run, in order, each once
    decided: tuple[int, ...]  # the decided classes over the run, in order, each once


def irrelevant_runs(log: EpisodeLog) -> list[IrrelevantRun]:
    """Every run of irrelevant decisions, longest first."""
    d = log.decisions
    contexts = decision_contexts(log)
    out = []
    for start, length in metrics.runs(irrelevant_mask(log)):
        mine = contexts[start:start + length]
        context = max(dict.fromkeys(mine), key=mine.count)
        out.append(IrrelevantRun(float(d.t[start]), 1000.0 * length * log.sample_period, context,
                                 tuple(dict.fromkeys(d.intended[start:start + length].tolist())),
                                 tuple(dict.fromkeys(d.decided[start:start + length].tolist()))))
    return sorted(out, key=lambda run: -run.duration_ms)


@dataclass(frozen=True)
class VoteEffect:
    """What the majority vote did to the irrelevant outputs: ``made``, irrelevant outputs whose
    pre-vote label was relevant; ``removed``, irrelevant pre-vote labels output as relevant ones."""

    made: int
    removed: int
    before: int  # irrelevant pre-vote labels
    after: int  # irrelevant outputs


def vote_effect(log: EpisodeLog, raw: np.ndarray) -> VoteEffect:
    """``VoteEffect`` from the pre-vote labels ``raw`` (one per decision of the record)."""
    d = log.decisions
    before = metrics.irrelevant(d.intended, np.asarray(raw), log.neutral)
    after = irrelevant_mask(log)
    return VoteEffect(int(np.sum(after & ~before)), int(np.sum(before & ~after)), int(before.sum()), int(after.sum()))
