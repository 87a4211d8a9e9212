"""The careful path to a goal, step by step (each with the mode it needs and the odds it is still to be
made), and the time the user's presses to the next step's mode take from each mode."""
from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from sim.joystick import Kind, Layout, Mode
from tasks.operators.assist.goals import Goal
from tasks.operators.assist.params import PathParams
from tasks.operators.judgement import CUBE_SYMMETRY, wrapped_angle
from tasks.stacking.vocabulary import View


def _needed(error: float, tolerance: float, softness: float) -> float:
    """Probability that a step with this error is still to be made: 1/2 at the tolerance.  The exponent
    is capped at 700 (exp overflows past ~709; 1/(1 + e^700) ~ 1e-304 is already 0 for any use) for an
    error far below a small softness (seen: bomi design's candidate with auto-mode, OverflowError)."""
    return float(1.0 / (1.0 + math.exp(min(-(error - tolerance) / softness, 700.0))))


def yaw_offset(hand_yaw: float, cube_yaw: float) -> float:
    """Turn (rad) that lines the hand up with a face of the cube, in [-pi/4, pi/4)."""
    return wrapped_angle(cube_yaw - hand_yaw, CUBE_SYMMETRY)


class PathStep(enum.Enum):
    """The steps of a careful path to a goal, in their order."""

    OPEN_HAND = "open"
    RISE = "rise"
    TRAVEL = "travel"
    TURN = "turn"
    DESCEND = "descend"
    CLOSE = "close"
    RELEASE = "release"


PATH_ORDER = tuple(PathStep)
# the turn about the vertical and the travel over the goal reach the same pose in either order: which
# one a user makes first near a cube is learnt per user (``Assistance.turn_first_within``)
EITHER_ORDER = frozenset({PathStep.TRAVEL, PathStep.TURN})


def path_order(turn_first: bool) -> tuple[PathStep, ...]:
    """The steps in the order the user makes them: ``PATH_ORDER``, or with the turn before the
    travel (``turn_first``)."""
    if not turn_first:
        return PATH_ORDER
    return tuple(PathStep.TURN if step is PathStep.TRAVEL else PathStep.TRAVEL if step is PathStep.TURN else step
                 for step in PATH_ORDER)


def user_order(view: View, goal: Goal, turn_first_within: float | None) -> tuple[PathStep, ...]:
    """The order of the path to ``goal`` for a user seen turning to a cube's faces before the end of
    the travel from as far as ``turn_first_within`` (xy, m; None: never seen): the turn first when
    the goal has a heading and the hand is that near it."""
    near = turn_first_within is not None and goal.yaw is not None \
        and float(np.linalg.norm(goal.point[:2] - view.hand_pos[:2])) <= turn_first_within
    return path_order(near)


@dataclass(frozen=True)
class Step:
    """One step of the path to a goal: the mode it needs and the probability that it is still to be made."""

    name: PathStep
    mode: Mode
    needed: float


def step_errors(view: View, goal: Goal, path: PathParams) -> dict[PathStep, tuple[float, float]]:
    """The steps whose "done" is a precision, each as (how far off the hand is, the tolerance it is
    done within before anything is learnt of the user): the travel over the goal (xy, m), the turn
    to the cube's faces (degrees; grasps only) and the descent onto it (height, m)."""
    error = goal.point - view.hand_pos
    out = {PathStep.TRAVEL: (float(np.linalg.norm(error[:2])), goal.near)}
    if goal.yaw is not None:
        out[PathStep.TURN] = (abs(math.degrees(yaw_offset(view.hand_yaw, goal.yaw))), path.yaw_tol_deg)
    out[PathStep.DESCEND] = (abs(float(error[2])), goal.height_tol)
    return out


def rise_error(view: View, goal: Goal) -> tuple[float, float]:
    """The rise before a travel as a precision: (how far the goal is in xy, the distance from which
    a careful user rises first when low: its nearness).  A user who travels where the rise was
    expected shows that they travel this far without rising (``_learn_precision``)."""
    return float(np.linalg.norm(goal.point[:2] - view.hand_pos[:2])), goal.near


def revisit_scale(path: PathParams, working_on: PathStep | None, order: tuple[PathStep, ...] = PATH_ORDER
                  ) -> dict[PathStep, float]:
    """Per step, the factor on its tolerance while the user was last seen making ``working_on``:
    ``revisit`` for the steps before it both in ``PATH_ORDER`` and in the user's ``order`` (a person
    who has moved on goes back only for a clearly larger error; one who turns before the end of the
    travel has not left the travel behind by turning, nor the turn by travelling there), 1 for the others."""
    if working_on is None:
        return {step: 1.0 for step in PathStep}
    passed = set(PATH_ORDER[:PATH_ORDER.index(working_on)]) & set(order[:order.index(working_on)])
    return {step: path.revisit if step in passed else 1.0 for step in PathStep}


def path_steps(view: View, goal: Goal, layout: Layout, path: PathParams, working_on: PathStep | None = None,
               precision: Mapping[PathStep, float] | None = None, order: tuple[PathStep, ...] = PATH_ORDER
               ) -> list[Step]:
    """The careful path to ``goal``, step by step in the user's ``order`` (``user_order``), each with
    the mode of ``layout`` that makes it.
    ``working_on``: the step the user was last seen making; the steps before it are done as the
    user sees them unless they are off by ``revisit`` times their tolerance (a person who has moved
    on to a later step goes back only for a clearly larger error).  ``precision``: per step, the
    share of its tolerance this user has been seen to need (``Assistance.precision``; 1 if absent)."""
    revisit = revisit_scale(path, working_on, order)
    scale = {step: revisit[step] * (precision or {}).get(step, 1.0) for step in PathStep}
    hand = view.hand_pos
    errors = step_errors(view, goal, path)
    xy = errors[PathStep.TRAVEL][0]
    up, _ = layout.find(Kind.LINEAR, (0.0, 0.0, 1.0))
    across, _ = layout.find(Kind.LINEAR, (1.0, 0.0, 0.0))
    fingers, _ = layout.find(Kind.FINGERS, goal.act)
    steps = []
    if goal.act > 0:  # a grasp needs the hand open first
        opener, _ = layout.find(Kind.FINGERS, -1.0)
        steps.append(Step(PathStep.OPEN_HAND, opener, float(view.closure > path.open_closure)))
    # far: beyond the xy within which this user travels without rising first (``rise_error``)
    far = _needed(xy, goal.near * (precision or {}).get(PathStep.RISE, 1.0), path.softness)
    low = _needed(goal.travel_z - hand[2], goal.height_tol * revisit[PathStep.RISE], path.softness)
    steps.append(Step(PathStep.RISE, up, far * low))
    steps.append(Step(PathStep.TRAVEL, across, _needed(xy, goal.near * scale[PathStep.TRAVEL], path.softness)))
    if PathStep.TURN in errors:
        turn = yaw_offset(view.hand_yaw, goal.yaw)
        turner, _ = layout.find(Kind.ANGULAR, (0.0, 0.0, 1.0 if turn >= 0 else -1.0))
        steps.append(Step(PathStep.TURN, turner, _needed(errors[PathStep.TURN][0],
                                                         path.yaw_tol_deg * scale[PathStep.TURN], path.yaw_softness_deg)))
    steps.append(Step(PathStep.DESCEND, up, _needed(errors[PathStep.DESCEND][0],
                                                    goal.height_tol * scale[PathStep.DESCEND], path.softness)))
    steps.append(Step(PathStep.CLOSE if goal.act > 0 else PathStep.RELEASE, fingers, 1.0))
    return sorted(steps, key=lambda step: order.index(step.name))


def step_of_move(layout: Layout, mode: Mode, functions: Iterable[str], holding_cube: bool) -> PathStep | None:
    """The path step a move of the user makes: what the held functions do in ``mode`` (the latest
    in the path's order if several; None for a tilt of the hand, which no path step needs)."""
    found = []
    for fn in functions:
        effect = layout.effects[mode].get(fn)
        if effect is None:
            continue
        if effect.kind is Kind.FINGERS:
            found.append(PathStep.CLOSE if effect.axis > 0 else PathStep.RELEASE if holding_cube else PathStep.OPEN_HAND)
        elif effect.kind is Kind.LINEAR:
            found.append(PathStep.TRAVEL if effect.axis[2] == 0 else PathStep.RISE if effect.axis[2] > 0
                         else PathStep.DESCEND)
        elif effect.axis[2] != 0:
            found.append(PathStep.TURN)
    return max(found, key=PATH_ORDER.index) if found else None


def next_step_shares(steps: list[Step]) -> dict[PathStep, float]:
    """Probability that each step is the next one to be made (the first still needed)."""
    out: dict[PathStep, float] = {}
    left = 1.0
    for step in steps:
        out[step.name] = left * step.needed
        left -= out[step.name]
    return out


def next_step_modes(steps: list[Step]) -> dict[Mode, float]:
    """Probability that each mode is the one of the next step to be made."""
    out: dict[Mode, float] = {}
    for step, share in zip(steps, next_step_shares(steps).values()):
        out[step.mode] = out.get(step.mode, 0.0) + share
    return out


def presses(layout: Layout, buttons: tuple[str, ...], current: Mode, wanted: Mode) -> int:
    """The fewest presses of the person's buttons from ``current`` to ``wanted``; without a button,
    the automatic switches the person waits for (one, unless the arm is in ``wanted`` already)."""
    if not buttons:
        return int(current is not wanted)
    return min(layout.presses(current, wanted, b) for b in buttons)


def time_to_goal(layout: Layout, buttons: tuple[str, ...], next_modes: dict[Mode, float], press_time: float
                 ) -> dict[Mode, float]:
    """Per mode m of the layout: the expected time the user's presses from m to the next step's
    mode take (the part of the time to the goal that depends on the mode the arm is in)."""
    return {m: press_time * sum(p * presses(layout, buttons, m, need) for need, p in next_modes.items())
            for m in layout.modes}
