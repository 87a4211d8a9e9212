"""Assistance between the decided joystick function and the arm (beyond the paper).

    decided JoystickState -> Assistance.step(view, state, arm) -> JoystickState -> arm

It sees what a real system could: the arm (hand pose, fingers, mode), the scene's objects (the
cubes' poses and contacts, the target B; ``planner.View`` as the task builds it from the
simulation) and the user's commands so far.  It never sees the scripted user's plan or goal.

``Assist.AUTO_MODE``: automatic time-optimal mode switching after Herlant, Holladay and Srinivasa
(HRI 2016).  A belief over candidate goals taken from the scene (grasp each cube; with a cube in
the hand, set it down at B or on the other cube) is raised for the goals the user's recent motion
heads toward.  For each goal, a careful pick-and-place path (open the hand if need be, rise to the
travel height when low and far, travel over the goal, line the hand up with the cube, descend,
close or open) gives which step comes next, each step "still needed" with a probability that
falls smoothly as its error reaches the tolerance; each step needs a mode of the layout.  The time
to the goal from a mode m is the steps' share that depends on m: the user's own presses from m to
the mode of the next step (``press_time`` each, with the buttons the person has), in expectation
over the goals and over which step is next.  When the stick has rested ``rest_time``, the
automation puts the arm in the mode that minimises that time if it saves at least ``min_gain``;
at most once per rest.  The user's own button press always wins (it is passed on untouched) and
pauses the automation for ``pause_after_press``.  The steps' tolerances start as ``[path]`` says
and are then this user's, learnt online (``LearntTolerance``) whenever the user leaves a mode by a
press: a refusal of an automatic switch (a press out of the switch's mode before any move in it) or
their own switch after moving in a mode.  The step they make next was not done if the automation
judged it done then; the step it expected next in the mode they left (the one the switch was made
for), if they skip it, was done (for the rise before a travel: the user travels that far without
rising first).  The turn to a cube's faces and the travel over it come in either order: a user
who leaves a mode to turn while the travel is still to be made shows that they turn first from
that far from the cube (``turn_first_within``), and the path puts the turn first there.

A user without a mode button (``buttons`` empty: a profile with no class left for one) cannot
refuse a switch by a press: for them a mode is one automatic switch away (``presses``), the rest
is their answer, and the automation offers a mode once per ``rest_refusal`` of rest: a rest held on
that long after an offer (a switch, or the mode kept at ``rest_time``) refuses the arm's mode, and
the arm goes to the best mode this rest has not refused (``_refused_by_rest``; all refused, the
round starts again), so the mode the user waits for comes within one round of the layout's modes.

``Assist.GRASP_HELP``: when the open hand is around a cube (centre within ``xy_tol``/``z_tol`` of
the pinch point, lined up within ``yaw_tol_deg``) and the user has held still for ``hold_still``,
the arm is put in the finger mode and closes until the fingers have touched the cube for
``squeeze`` (or are closed); any command of the user stops it.

Every switch the assistance makes is an ``AutomaticSwitch`` (tick, time, from, to, which
assistance, the goal it served); the arm counts them apart from the button presses
(``ArmSim.automatic_switches``).
"""
from __future__ import annotations

import argparse
import enum
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from collections.abc import Iterable, Mapping
from typing import Protocol

import numpy as np

from bomi.config_files import load_toml
from bomi.errors import BomiError
from bomi.profiles import Profile
from sim.joystick import BUTTONS, JoystickState, Kind, Layout, Mode, combine
from tasks.operators.planner import CUBE_SYMMETRY, View, wrapped_angle

DEFAULT_ASSIST_FILE = Path(__file__).with_name("assist.toml")
NONE = "none"


class Assist(enum.Enum):
    """The assistances one may choose (``--assist``, a profile's ``[assist] options``)."""

    AUTO_MODE = "auto-mode"
    GRASP_HELP = "grasp-help"


def parse_assist(names: str | list[str] | tuple[str, ...], what: str = "--assist") -> frozenset[Assist]:
    """``"none"``, one name or a comma list (or a list of names) -> the set of assistances."""
    items = [n.strip() for n in names.split(",")] if isinstance(names, str) else [str(n).strip() for n in names]
    items = [n for n in items if n]
    what = f"{what}: " if what else ""
    allowed = ", ".join([NONE] + [a.value for a in Assist])
    if not items:
        raise BomiError(f"{what}empty (expected {allowed})")
    if NONE in items:
        if len(items) > 1:
            raise BomiError(f"{what}{NONE!r} cannot be combined with {', '.join(n for n in items if n != NONE)}")
        return frozenset()
    by_name = {a.value: a for a in Assist}
    bad = [n for n in items if n not in by_name]
    if bad:
        raise BomiError(f"{what}unknown {', '.join(bad)} (expected {allowed})")
    return frozenset(by_name[n] for n in items)


def assist_option(text: str) -> frozenset[Assist]:
    """``--assist`` for argparse."""
    try:
        return parse_assist(text, "")
    except BomiError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


ASSIST_HELP = ("assistance between the stick and the arm: none, or a comma list of "
               f"{', '.join(a.value for a in Assist)} (default: the profile's [assist] options; joystick: none)")


def profile_assist(profile: Profile) -> frozenset[Assist]:
    """The assistances a profile switches on (its ``[assist] options``)."""
    return parse_assist(list(profile.assist), f"{profile.source}: [assist] options") if profile.assist else frozenset()


def assist_label(options: frozenset[Assist]) -> str:
    """The set as ``--assist`` spells it (enum order): "none", "auto-mode", "auto-mode,grasp-help"."""
    return ",".join(a.value for a in Assist if a in options) or NONE


# ------------------------------------------------------------------------------------ parameters
@dataclass(frozen=True)
class AutoModeParams:
    rest_time: float
    mask_time: float
    pause_after_press: float
    press_grace: float
    response_samples: float
    press_time: float
    min_gain: float
    memory: float
    sharpness: float
    proximity: float
    off_target_prior: float
    refusal_share: float
    rest_refusal: float


@dataclass(frozen=True)
class PathParams:
    clearance: float
    release_gap: float
    grasp_near: float
    grasp_height: float
    place_near: float
    place_height: float
    yaw_tol_deg: float
    softness: float
    yaw_softness_deg: float
    open_closure: float
    squeeze: float
    revisit: float


@dataclass(frozen=True)
class GraspHelpParams:
    hold_still: float
    xy_tol: float
    z_tol: float
    yaw_tol_deg: float


@dataclass(frozen=True)
class AssistParams:
    auto_mode: AutoModeParams
    path: PathParams
    grasp_help: GraspHelpParams


_TABLES = {"auto_mode": AutoModeParams, "path": PathParams, "grasp_help": GraspHelpParams}
_MAY_BE_NEGATIVE = {"off_target_prior"}


def load_assist(path: Path | str = DEFAULT_ASSIST_FILE) -> AssistParams:
    """Read and validate an assistance TOML file; BomiError names the file and the fault."""
    return load_toml(path, DEFAULT_ASSIST_FILE.parent, "assist", _parse_assist)


def _parse_assist(data: dict, source: str) -> AssistParams:
    unknown = set(data) - set(_TABLES)
    if unknown:
        raise ValueError(f"unknown table(s): {', '.join(sorted(unknown))}")
    tables = {}
    for name, cls in _TABLES.items():
        table = data.get(name)
        if not isinstance(table, dict):
            raise ValueError(f"missing table [{name}]")
        keys = [f.name for f in fields(cls)]
        extra = set(table) - set(keys)
        if extra:
            raise ValueError(f"unknown key(s) in [{name}]: {', '.join(sorted(extra))}")
        values = {}
        for key in keys:
            value = table.get(key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"[{name}] {key} must be a finite number, got {value!r}")
            if value <= 0 and key not in _MAY_BE_NEGATIVE:
                raise ValueError(f"[{name}] {key} must be positive, got {value}")
            values[key] = float(value)
        tables[name] = cls(**values)
    if not tables["path"].open_closure < 1:
        raise ValueError("[path] open_closure must be below 1")
    if not tables["auto_mode"].refusal_share < 1:
        raise ValueError("[auto_mode] refusal_share must be below 1")
    return AssistParams(**tables)


# ------------------------------------------------------------------------------------ goals
@dataclass(frozen=True)
class Goal:
    """Where a step of the task would bring the hand, as the scene shows it."""

    label: str
    point: np.ndarray  # (3,) the pinch point at the goal
    travel_z: float  # the height a careful user travels at toward it
    act: float  # the finger action at the goal: +1 close (grasp), -1 open (set down)
    near: float  # the hand is over the goal when this close in xy
    height_tol: float  # and at its height when this close
    yaw: float | None = None  # the hand heading to line up with (a grasp), modulo a quarter turn
    prior: float = 0.0  # log-odds before any motion is seen


def held_cube(view: View, open_closure: float) -> int | None:
    """The cube the fingers hold (touching and not open); the nearest to the pinch point if two."""
    touching = [k for k, touch in enumerate(view.touching) if touch]
    if not touching or view.closure <= open_closure:
        return None
    return min(touching, key=lambda k: float(np.linalg.norm(view.cube_pos[k] - view.hand_pos)))


def _rest_z(view: View) -> float:
    return view.table_z + view.cube_size / 2


def _at_target(view: View, k: int, zone: float) -> bool:
    return bool(np.linalg.norm(view.cube_pos[k][:2] - view.target_xy) <= zone)


def _in_the_way(view: View, others: list[int], goal_xy: np.ndarray) -> float:
    """The top of the highest cube near the straight way from the hand to ``goal_xy`` (within one
    and a half cube widths of it), or the table."""
    start, way = view.hand_pos[:2], goal_xy - view.hand_pos[:2]
    length2 = float(np.dot(way, way))
    top = view.table_z
    for k in others:
        xy = view.cube_pos[k][:2]
        along = 0.0 if length2 == 0 else float(np.clip(np.dot(xy - start, way) / length2, 0.0, 1.0))
        if np.linalg.norm(start + along * way - xy) <= 1.5 * view.cube_size:
            top = max(top, float(view.cube_pos[k][2]) + view.cube_size / 2)
    return top


def candidate_goals(view: View, params: AssistParams, clearance: float | None = None) -> list[Goal]:
    """The goals the scene offers: grasp any cube; with a cube in the hand, set it down at B (if
    free) or on another cube.  Goals that leave the stack at B unfinished (grasping a cube that is
    already there, setting one down on a cube elsewhere) start less likely (``off_target_prior``).  The way there clears the cubes near
    it by ``clearance`` (the open fingers, or the held cube, reach half a cube below the pinch point):
    the one this user has been seen travelling at, else ``[path] clearance``."""
    path, size = params.path, view.cube_size
    clearance = path.clearance if clearance is None else clearance
    held = held_cube(view, path.open_closure)
    others = [k for k in range(len(view.cube_pos)) if k != held]
    zone = size  # a cube counts as at B when its centre is within a cube's width of B
    if held is None:
        goals = []
        for k in others:
            prior = params.auto_mode.off_target_prior if _at_target(view, k, zone) else 0.0  # already placed
            point = np.asarray(view.cube_pos[k], dtype=float)
            travel_z = _in_the_way(view, others, point[:2]) + clearance + size / 2
            goals.append(Goal(f"grasp cube {k + 1}", point, travel_z, +1.0, path.grasp_near, path.grasp_height,
                              view.cube_yaw[k], prior))
        return goals
    grip = view.hand_pos - view.cube_pos[held]  # where the hand holds the cube
    goals = []
    free_b = not any(_at_target(view, k, zone) and abs(view.cube_pos[k][2] - _rest_z(view)) < size / 4 for k in others)
    lift = grip[2] + path.release_gap  # the hand lets go with the cube just above its support
    places = [(f"set cube {held + 1} down at B", np.r_[view.target_xy + grip[:2], _rest_z(view) + lift], 0.0)] \
        if free_b else []
    places += [(f"set cube {held + 1} on cube {k + 1}", np.r_[view.cube_pos[k][:2] + grip[:2], view.cube_pos[k][2] + size + lift],
                0.0 if _at_target(view, k, zone) else params.auto_mode.off_target_prior) for k in others]
    for label, point, prior in places:
        travel_z = _in_the_way(view, others, point[:2]) + clearance + size / 2 + grip[2]
        goals.append(Goal(label, point, travel_z, -1.0, path.place_near, path.place_height, prior=prior))
    return goals


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


@dataclass
class LearntTolerance:
    """What one user's presses out of a mode showed of the error within which they count a path
    step done (for one kind of goal), and the tolerance that follows.  Two kinds of evidence, each
    from the user leaving a mode by a press (``SwitchContext``: a refusal of an automatic switch,
    or their own switch after moving in the mode):

    - ``not_done_at``: the automation judged the step done, and the user's first move afterwards
      made it: their tolerance is below that error (the smallest such error is kept);
    - ``done_within``: the automation expected this step next in the mode left, and the user's
      first move made a later one: the step was done for them at that error (the largest such
      error is kept).

    The tolerance is the middle of the two bounds; with one bound only, ``share`` of the upper one
    or the lower one over ``share`` (with ``share`` = 1/2: halving or doubling, as a bisection);
    the starting tolerance while nothing is known, and within the one bound seen if it is looser.
    Evidence that contradicts the other bound (the user's tolerance depends on more than the error)
    replaces it: the latest refusal counts."""

    start: float
    not_done_at: float | None = None
    done_within: float | None = None

    def saw_not_done(self, error: float) -> None:
        self.not_done_at = error if self.not_done_at is None else min(self.not_done_at, error)
        if self.done_within is not None and self.done_within >= self.not_done_at:
            self.done_within = None

    def saw_done(self, error: float) -> None:
        self.done_within = error if self.done_within is None else max(self.done_within, error)
        if self.not_done_at is not None and self.not_done_at <= self.done_within:
            self.not_done_at = None

    def tolerance(self, share: float) -> float:
        low, high = self.done_within, self.not_done_at
        if low is not None and high is not None:
            return (low + high) / 2
        if high is not None:
            return min(self.start, share * high)
        if low is not None:
            return max(self.start, low / share)
        return self.start


@dataclass
class PressResponse:
    """How soon one user presses a mode button after they decide to, learnt from their own presses:
    the time from the end of their last move, or from their last press, to the press (no automatic
    switch between): it holds at least one decision and the whole press (through a body interface
    a second or two of posture and classifier).  A press after an automatic switch sooner than the
    fastest of them was on its way before the switch could be seen (an answer to the switch holds
    a decision and a press too): it is meant for the mode before it.  The fastest, not a typical
    one: a body user's answer to a switch comes as fast as their fastest presses (P4, development
    seed 979: a refusal 1.20 s after a switch, presses from 1.17 s), and taking one for a press
    under way costs a one-button user the whole cycle."""

    grace: float  # before enough presses are seen: a human reaction to a seen change takes longer
    samples: int  # presses needed before they are trusted
    answers: list[float] = field(default_factory=list)
    _since: float | None = None  # the end of the last move or the last press (None: an automatic switch since)

    def moved(self, t: float) -> None:
        self._since = t

    def pressed(self, t: float) -> None:
        if self._since is not None:
            self.answers.append(t - self._since)
        self._since = t

    def switched(self) -> None:
        """An automatic switch: the next press may answer it."""
        self._since = None

    def unseen_within(self) -> float:
        """Presses sooner than this after an automatic switch were decided before it."""
        if len(self.answers) < self.samples:
            return self.grace
        return max(self.grace, min(self.answers))


# ------------------------------------------------------------------------------------ the layer
@dataclass(frozen=True)
class AutomaticSwitch:
    """A mode switch the assistance made."""

    tick: int
    t: float
    before: Mode
    after: Mode
    by: Assist
    goal: str
    undone: bool = False  # a press came sooner than the user answers a change they see (PressResponse): undone
    # the user left its mode by a press before moving in it (and not before seeing it), or, without a
    # mode button, rested on in it for ``rest_refusal`` (``Assistance._refused_by_rest``)
    refused: bool = False


@dataclass(frozen=True)
class SwitchContext:
    """What the automation judged when the user had a mode (an automatic switch to it, or the
    user's own press out of it): the likely goal's finger action, its steps' (error, starting
    tolerance) (``step_errors``; the error over ``revisit`` for a step before the one the user was
    last seen making, whose tolerance was scaled by it: ``revisit_scale``; and the rise's,
    ``rise_error``, never among those judged done), the step made for
    that mode (of its steps, the likeliest to be the next), the other steps of ``step_errors``
    it judged done (less than even odds of being needed) and those it judged needed."""

    act: float
    errors: dict[PathStep, tuple[float, float]]
    made_for: PathStep | None
    judged_done: frozenset[PathStep]
    below: bool  # the hand was below the goal's point and over it (a move up makes the descent's step)
    needed: frozenset[PathStep]  # the steps of ``step_errors`` with at least even odds of being needed
    xy: float  # the hand's distance from the goal in xy (m)


class Switchable(Protocol):
    """What the assistance needs of the arm (``sim.env.ArmSim``)."""

    dt: float

    @property
    def mode(self) -> Mode: ...

    def switch_mode(self, mode: Mode) -> None: ...


@dataclass
class GoalBelief:
    """Log-odds per goal label: raised for goals the user's motion heads toward; while the user
    moves, what was seen earlier fades toward the prior (time constant ``memory``)."""

    logits: dict[str, float] = field(default_factory=dict)

    def probabilities(self, goals: list[Goal], hand_xy: np.ndarray, proximity: float) -> np.ndarray:
        """P(goal): the log-odds seen so far, less the goal's horizontal distance over ``proximity``
        (a user who has stopped over a goal most likely wants that one)."""
        distance = np.array([np.linalg.norm(g.point[:2] - hand_xy) for g in goals])
        values = np.array([self.logits.get(g.label, g.prior) for g in goals]) - distance / proximity
        weights = np.exp(values - values.max())
        return weights / weights.sum()

    def update(self, goals: list[Goal], scores: np.ndarray, dt: float, params: AutoModeParams) -> None:
        keep = math.exp(-dt / params.memory)
        self.logits = {g.label: keep * self.logits.get(g.label, g.prior) + (1 - keep) * g.prior
                       + params.sharpness * dt * float(s) for g, s in zip(goals, scores)}


def motion_scores(view: View, goals: list[Goal], state: JoystickState, layout: Layout, path: PathParams
                  ) -> np.ndarray:
    """How well the commanded motion fits each goal, in [-1, 1]: the cosine between the commanded
    horizontal motion and the way to the goal (over it already: -0.5, it asks for none); a descent
    fits the goals below the hand (over them within ``revisit`` times their nearness: +1, the
    others -0.5: a person goes down only onto their goal); a turn about the vertical toward a
    grasp's heading.  Rising tells nothing: every goal is left upward."""
    linear = combine(state.deflection, layout.axes(view.mode, Kind.LINEAR))
    angular = combine(state.deflection, layout.axes(view.mode, Kind.ANGULAR))
    scores = np.zeros(len(goals))
    for i, goal in enumerate(goals):
        wanted = goal.point - view.hand_pos
        xy = float(np.linalg.norm(wanted[:2]))
        if np.linalg.norm(linear[:2]) > 0:
            scores[i] = float(np.dot(linear[:2], wanted[:2]) / (np.linalg.norm(linear[:2]) * xy)) if xy > goal.near \
                else -0.5
        elif linear[2] < 0:
            scores[i] = 1.0 if xy <= path.revisit * goal.near and wanted[2] < 0 else -0.5
        elif abs(angular[2]) > 0 and goal.yaw is not None:
            turn = yaw_offset(view.hand_yaw, goal.yaw)
            lined_up = abs(math.degrees(turn)) <= path.yaw_tol_deg / 2
            scores[i] = -0.5 if lined_up else math.copysign(1.0, turn * angular[2])
    return scores


class Assistance:
    """The chosen assistances for one run; ``step`` once per control tick, before the arm's step."""

    def __init__(self, options: frozenset[Assist], layout: Layout, buttons: tuple[str, ...] = BUTTONS,
                 params: AssistParams | None = None):
        self.options = frozenset(options)
        self.layout, self.buttons = layout, tuple(buttons)
        self.params = params or load_assist()
        self.belief = GoalBelief()
        self.switches: list[AutomaticSwitch] = []
        self.grasp_helps = 0  # closes the grasp help started
        self._tick = 0
        self._active_at = -math.inf  # when the user last held a function or pressed a button
        self._paused_until = -math.inf
        self._paused_until_move = False  # after the user's press: paused until they move in a mode
        self._switched_this_rest = False
        self._rest_refused: set[Mode] = set()  # without a mode button: the modes this rest has refused
        self._offered_at = -math.inf  # without a mode button: when this rest's latest offer of a mode was made
        self._closing_since: float | None = None  # the grasp help is closing the fingers
        self._touch_since: float | None = None  # the fingers have touched a cube since
        # functions held across an automatic switch: off until the stick rests, for at most mask_time
        self._mask: frozenset[str] = frozenset()
        self._masked_at = -math.inf
        self._moved_since_switch = False  # the user has held a function since our last switch
        # a mode the user left by their own press before moving in it, and where the hand was: not
        # proposed again until the hand has gone ``near`` from there
        self._refused: tuple[Mode, np.ndarray] | None = None
        # the step the user's latest move made, and the cube held then (a grasp or a release starts anew)
        self._working_on: tuple[int | None, PathStep] | None = None
        # how high above the cubes in its way this user travels (None: not seen yet), and whether the
        # user's latest moves were a rise (a travel right after it shows the height they chose)
        self._clearance: float | None = None
        self._rose = False
        # this user's tolerances as their refusals showed them: per (goal's finger action, step)
        self._learnt: dict[tuple[float, PathStep], LearntTolerance] = {}
        # how far from a cube (xy) this user has been seen to turn to its faces before the end of the travel
        self._turn_first: float | None = None
        # at our last switch: the likely goal's finger action, its steps' (error, starting tolerance)
        # and the step the switch was made for (the first one still needed, in the mode switched to)
        self._switched_at: SwitchContext | None = None
        # set when the user leaves a mode by a press (a refusal of our switch, or their own switch
        # after moving in it): what we judged of that mode, and whether it was a refusal; the
        # user's next move tells which step they still wanted
        self._left: tuple[SwitchContext | None, bool] | None = None
        auto = self.params.auto_mode
        self.press_response = PressResponse(auto.press_grace, int(auto.response_samples))

    def step(self, view: View, state: JoystickState, arm: Switchable) -> JoystickState:
        """The stick the arm gets this tick; may put ``arm`` in another mode first."""
        tick, self._tick = self._tick, self._tick + 1
        self._touch_since = (self._touch_since if self._touch_since is not None else view.t) if any(view.touching) \
            else None
        state = self._unmasked(state, view.t)
        if not (state.deflection or state.pressed):
            return self._at_rest(tick, view, state, arm)
        self._active_at, self._switched_this_rest, self._closing_since = view.t, False, None
        self._rest_refused.clear()
        if state.pressed:  # the user's own press wins and pauses the automation
            last = self.switches[-1] if self.switches else None
            undone = self._undo_unseen_switch(view, arm)  # decided before the switch could be seen: no refusal
            if not undone and last is not None and arm.mode is last.after and not self._moved_since_switch \
                    and not last.refused:
                self._refused = (last.after, view.hand_pos.copy())
                self._left = (self._switched_at, True)
                self.switches[-1] = replace(last, refused=True)
            elif not self._paused_until_move and Assist.AUTO_MODE in self.options:
                # the first press since the user moved: they leave the mode they moved in
                goals = candidate_goals(view, self.params, self.clearance)
                self._left = (self._context(view, arm.mode, self._likely(view, goals).label), False) if goals \
                    else None
            self.press_response.pressed(view.t)
            self._paused_until = view.t + self.params.auto_mode.pause_after_press
            self._paused_until_move = True
            return state
        self._paused_until_move, self._moved_since_switch = False, True
        self.press_response.moved(view.t)
        held = held_cube(view, self.params.path.open_closure)
        working_on = step_of_move(self.layout, view.mode, state.deflection, held is not None)
        if working_on is not None:
            self._working_on = (held, working_on)
            self._learn_precision(working_on)
        if Assist.AUTO_MODE in self.options:
            goals = candidate_goals(view, self.params, self.clearance)
            if working_on is PathStep.TRAVEL:
                self._learn_clearance(view, goals)
            elif working_on is not None:
                self._rose = working_on is PathStep.RISE
            self.belief.update(goals, motion_scores(view, goals, state, self.layout, self.params.path), arm.dt,
                               self.params.auto_mode)
            if self._fingers_done(view, state) and view.t >= self._paused_until:
                best, goal = self.best_mode(view)
                if best is not None:  # switch now; the finger function still held does nothing from here
                    self._switch(tick, view, arm, best, Assist.AUTO_MODE, goal)
                    self._mask, self._masked_at = frozenset(state.deflection), view.t
                    return JoystickState()
        return state

    def _unmasked(self, state: JoystickState, t: float) -> JoystickState:
        """The stick without the functions held across an early switch: until it rests, or for
        ``mask_time`` (longer than the interface answers an old posture; a user who goes on holding
        the same function means it in the new mode)."""
        if not state.deflection or t - self._masked_at > self.params.auto_mode.mask_time:
            self._mask = frozenset()
        if not self._mask:
            return state
        return JoystickState({fn: v for fn, v in state.deflection.items() if fn not in self._mask}, state.pressed)

    def _fingers_done(self, view: View, state: JoystickState) -> bool:
        """The user holds a finger function that can do no more: opening fingers that are open, or
        closing fingers that have held a cube for ``squeeze`` (the interface may still be
        answering an earlier posture for a second: the next step's mode need not wait for it)."""
        fingers = self.layout.axes(view.mode, Kind.FINGERS)
        held = [fingers[fn] for fn in state.deflection if fn in fingers]
        if not held or len(held) != len(state.deflection):
            return False
        if all(direction < 0 for direction in held):
            return view.closure <= self.params.path.open_closure
        return all(direction > 0 for direction in held) and self._touch_since is not None \
            and view.t - self._touch_since >= self.params.path.squeeze
    def _at_rest(self, tick: int, view: View, state: JoystickState, arm: Switchable) -> JoystickState:
        if self._closing_since is not None:
            return self._close(view, state)
        rested = view.t - self._active_at
        if self._switched_this_rest and not self.buttons and Assist.AUTO_MODE in self.options:
            self._refused_by_rest(tick, view, arm)
        if view.t < self._paused_until or self._paused_until_move or self._switched_this_rest:
            return state  # one switch per rest: the user's next move (or press) decides what comes after
        if Assist.GRASP_HELP in self.options and rested >= self.params.grasp_help.hold_still:
            cube = self._around(view)
            if cube is not None:
                fingers, _ = self.layout.find(Kind.FINGERS, 1.0)
                self._switch(tick, view, arm, fingers, Assist.GRASP_HELP, f"grasp cube {cube + 1}")
                self._closing_since = view.t
                self.grasp_helps += 1
                return self._close(view, state)
        if Assist.AUTO_MODE in self.options and rested >= self.params.auto_mode.rest_time:
            best, goal = self.best_mode(view)
            if best is not None:
                self._switch(tick, view, arm, best, Assist.AUTO_MODE, goal)
            if not self.buttons:  # offered (switched, or the mode kept): the rest may refuse it
                self._switched_this_rest, self._offered_at = True, view.t
        return state

    def _refused_by_rest(self, tick: int, view: View, arm: Switchable) -> None:
        """A user without a mode button can answer a mode only with the stick: resting on for
        ``rest_refusal`` after the offer (our switch, or the mode kept) and after the stick came to
        rest refuses the arm's mode. The arm goes to the best mode this rest has not refused (all
        refused: the round starts again), so the mode the user waits for comes within one round of
        the layout's modes."""
        if view.t - max(self._offered_at, self._active_at) < self.params.auto_mode.rest_refusal:
            return
        last = self.switches[-1] if self.switches else None
        if last is not None and last.t >= self._active_at and arm.mode is last.after:
            self.switches[-1] = replace(last, refused=True)
            if self._left is None:  # the rest's first refusal: the user's next move teaches what they wanted
                self._left = (self._switched_at, True)
        self._offered_at = view.t
        self._rest_refused.add(arm.mode)
        if self._rest_refused.issuperset(self.layout.modes):
            self._rest_refused = {arm.mode}
        expected, likely = self.expected_times(view)
        if not expected:
            return
        best = min((m for m in self.layout.modes if m not in self._rest_refused), key=expected.get)
        self._switch(tick, view, arm, best, Assist.AUTO_MODE, likely)

    def precision(self, act: float) -> dict[PathStep, float]:
        """Per step of a path to a goal with finger action ``act`` (+1 grasp, -1 set down): this
        user's tolerance for it as a share of the starting one (``LearntTolerance``; steps no
        refusal has taught anything about: absent, the whole tolerance)."""
        share = self.params.auto_mode.refusal_share
        return {step: learnt.tolerance(share) / learnt.start for (kind, step), learnt in self._learnt.items()
                if kind == act}

    def _learn_precision(self, working_on: PathStep) -> None:
        """After the user left a mode by a press (a refusal of our switch, or their own switch), their
        first move is the step they still wanted: if we judged it done then (less than even odds of
        being needed), it was not done at its error then; the step made for the mode they left (the
        one the switch was made for), if it comes before theirs (they went past it), was done for
        them at its error then (``LearntTolerance``); a step after theirs tells nothing (they may
        just take the steps in another order), nor do the turn and the travel of each other
        (``EITHER_ORDER``): which of them this user makes first is their order
        (``_learn_order``).  A refusal that taught something is explained: the refused mode may be
        proposed again."""
        if self._left is None:
            return
        (context, refusal), self._left = self._left, None
        if context is None:
            return
        if working_on is PathStep.RISE and context.below:  # up to a goal above the hand: the descent's overshoot corrected
            working_on = PathStep.DESCEND
        lessons = []
        if working_on in context.judged_done:
            lessons.append((working_on, LearntTolerance.saw_not_done))
        if context.made_for in context.errors and working_on in PATH_ORDER \
                and PATH_ORDER.index(context.made_for) < PATH_ORDER.index(working_on) \
                and {context.made_for, working_on} != EITHER_ORDER:
            lessons.append((context.made_for, LearntTolerance.saw_done))
        for step, lesson in lessons:
            error, start = context.errors[step]
            lesson(self._learnt.setdefault((context.act, step), LearntTolerance(start)), error)
        if (self._learn_order(context, working_on) or lessons) and refusal:
            self._refused = None

    @property
    def turn_first_within(self) -> float | None:
        """How far from a cube (xy, m) this user turns the hand to its faces before the end of the
        travel over it, as seen (None: not seen; ``user_order``)."""
        return self._turn_first

    def _learn_order(self, context: SwitchContext, working_on: PathStep) -> bool:
        """Which of the turn and the travel this user makes first near a cube, from their first move
        after leaving a mode by a press when both were needed: a turn shows that they turn first
        from that far (the farthest such distance is kept); a travel from no farther than that shows
        they do not (forgotten: the latest counts).  True if it taught something."""
        if not EITHER_ORDER <= context.needed:
            return False
        if working_on is PathStep.TURN and (self._turn_first is None or context.xy > self._turn_first):
            self._turn_first = context.xy
            return True
        if working_on is PathStep.TRAVEL and self._turn_first is not None and context.xy <= self._turn_first:
            self._turn_first = None
            return True
        return False

    @property
    def clearance(self) -> float | None:
        """How high above the cubes in its way this user travels, as seen (None before any travel
        told it)."""
        return self._clearance

    def _learn_clearance(self, view: View, goals: list[Goal]) -> None:
        """A travel toward the likely goal from farther than ``revisit`` times its nearness (not a
        correction over it): right after a rise, its height is the one this user chose; otherwise
        the user travels at whatever height they are, and it only shows that they need no more."""
        goal = self._likely(view, goals)
        if np.linalg.norm(goal.point[:2] - view.hand_pos[:2]) <= self.params.path.revisit * goal.near:
            return
        clearance = self.params.path.clearance if self._clearance is None else self._clearance
        seen = float(view.hand_pos[2]) - (goal.travel_z - clearance)
        self._clearance = seen if self._rose else min(clearance, seen)

    def _likely(self, view: View, goals: list[Goal]) -> Goal:
        """The most likely of ``goals`` (``GoalBelief.probabilities``)."""
        weights = self.belief.probabilities(goals, view.hand_pos[:2], self.params.auto_mode.proximity)
        return goals[int(np.argmax(weights))]

    def _seen_step(self, view: View) -> PathStep | None:
        """The step the user was last seen making, if they hold the same cube (or none) as then."""
        held = held_cube(view, self.params.path.open_closure)
        return self._working_on[1] if self._working_on is not None and self._working_on[0] == held else None

    def best_mode(self, view: View) -> tuple[Mode | None, str]:
        """The mode that minimises the expected time to the likely goals, if it saves ``min_gain``
        over the current one (else None), and the most likely goal's label."""
        expected, likely = self.expected_times(view)
        if not expected:
            return None, likely
        best = min(self.layout.modes, key=lambda m: (expected[m], m is not view.mode))
        if best is view.mode or expected[view.mode] - expected[best] < self.params.auto_mode.min_gain:
            return None, likely
        return best, likely

    def expected_times(self, view: View) -> tuple[dict[Mode, float], str]:
        """Per mode of the layout, the expected time to the likely goals from it (empty: no goal in
        the scene), and the most likely goal's label."""
        goals = candidate_goals(view, self.params, self.clearance)
        if not goals:
            return {}, ""
        weights = self.belief.probabilities(goals, view.hand_pos[:2], self.params.auto_mode.proximity)
        working_on = self._seen_step(view)
        expected = {m: 0.0 for m in self.layout.modes}
        for goal, weight in zip(goals, weights):
            steps = path_steps(view, goal, self.layout, self.params.path, working_on, self.precision(goal.act),
                               user_order(view, goal, self._turn_first))
            for m, seconds in time_to_goal(self.layout, self.buttons, next_step_modes(steps),
                                           self.params.auto_mode.press_time).items():
                expected[m] += weight * seconds
        return expected, goals[int(np.argmax(weights))].label

    def _undo_unseen_switch(self, view: View, arm: Switchable) -> bool:
        """A press that comes sooner after a switch of ours than this user's presses come after they
        decide (``PressResponse``; ``press_grace`` before their presses have shown it) was decided
        before they could see it: it is meant for the mode before the switch, which is restored (True)."""
        last = self.switches[-1] if self.switches else None
        if last is not None and not last.undone and not self._moved_since_switch and arm.mode is last.after \
                and view.t - last.t < self.press_response.unseen_within():
            arm.switch_mode(last.before)
            self.switches[-1] = replace(last, undone=True)
            return True
        return False

    def _switch(self, tick: int, view: View, arm: Switchable, mode: Mode, by: Assist, goal: str) -> None:
        self._switched_this_rest = True
        if self._refused is not None and np.linalg.norm(view.hand_pos - self._refused[1]) > self.params.path.place_near:
            self._refused = None
        if mode is arm.mode or (self._refused is not None and mode is self._refused[0] and by is Assist.AUTO_MODE):
            return
        self._moved_since_switch, self._offered_at = False, view.t
        self.press_response.switched()
        self._switched_at = self._context(view, mode, goal)
        self.switches.append(AutomaticSwitch(tick, view.t, arm.mode, mode, by, goal))
        arm.switch_mode(mode)

    def _context(self, view: View, mode: Mode, label: str) -> SwitchContext | None:
        """What the user leaving ``mode`` (a refusal of our switch to it, or their own press out of
        it) while the likely goal is ``label`` could teach."""
        likely = [g for g in candidate_goals(view, self.params, self.clearance) if g.label == label]
        if not likely:
            return None
        goal, working_on = likely[0], self._seen_step(view)
        order = user_order(view, goal, self._turn_first)
        steps = path_steps(view, goal, self.layout, self.params.path, working_on, self.precision(goal.act), order)
        shares = next_step_shares(steps)
        made_for = max((step for step in steps if step.mode is mode), key=lambda step: shares[step.name],
                       default=None)
        made_for = made_for.name if made_for is not None and shares[made_for.name] > 0 else None
        revisit = revisit_scale(self.params.path, working_on, order)
        errors = {step: (error / revisit[step], start) for step, (error, start) in
                  step_errors(view, goal, self.params.path).items()}
        judged_done = frozenset(step.name for step in steps if step.needed < 0.5 and step.name in errors
                                and step.name is not made_for)
        needed = frozenset(step.name for step in steps if step.needed >= 0.5 and step.name in errors)
        errors[PathStep.RISE] = rise_error(view, goal)  # a lesson of "done" only: a person rises for other reasons too
        xy = errors[PathStep.RISE][0]
        # over the goal (as a descent onto it, ``motion_scores``), a move up corrects the descent;
        # farther, it is a rise before the travel
        below = bool(goal.point[2] > view.hand_pos[2]) and xy <= self.params.path.revisit * goal.near
        return SwitchContext(goal.act, errors, made_for, judged_done, below, needed, xy)

    def _around(self, view: View) -> int | None:
        """The cube the open hand is around, lined up with it (None if none)."""
        g, path = self.params.grasp_help, self.params.path
        if view.closure > path.open_closure:
            return None
        for k, cube in enumerate(view.cube_pos):
            offset = cube - view.hand_pos
            if (np.linalg.norm(offset[:2]) <= g.xy_tol and abs(offset[2]) <= g.z_tol
                    and abs(math.degrees(yaw_offset(view.hand_yaw, view.cube_yaw[k]))) <= g.yaw_tol_deg):
                return k
        return None

    def _close(self, view: View, state: JoystickState) -> JoystickState:
        """The grasp help's stick: close until the fingers have squeezed the cube (or are closed)."""
        done = (self._touch_since is not None and view.t - self._touch_since >= self.params.path.squeeze) \
            or view.closure >= 0.95
        if done:  # the automatic mode switching may then take the arm on to the next step
            self._closing_since = None
            self._switched_this_rest = False
            return state
        _, close = self.layout.find(Kind.FINGERS, 1.0)
        return JoystickState({close: 1.0})

    def caption(self, t: float, shown_for: float = 2.0) -> str:
        """A caption line (the same number of lines every frame): the last automatic switch for
        ``shown_for`` seconds, else which assistances are on."""
        if not self.switches or t - self.switches[-1].t > shown_for:
            return f"assist: {assist_label(self.options)}"
        last = self.switches[-1]
        return f"AUTO {last.by.value}: {last.before.value} -> {last.after.value} ({last.goal})"
