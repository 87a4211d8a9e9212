"""The scripted JACO user: a person who knows the stacking task and picks joystick functions.

``plan`` is a pure function of what the person sees (``View``) and a little memory; it re-plans
every tick from where the hand and the cubes really are, so overshoots, misclassified BoMI
outputs and slipped cubes are corrected rather than ignored.  ``ScriptedUser`` adds the human
timing on top: reaction time before a new move, pauses between moves, stopping early by
anticipation.  One set of parameters (``tasks/operators/operator.toml``) serves both channels; the only
difference between channels is whether several axes may be combined (a 3-axis joystick can, a
BoMI gives one class at a time).
"""
from __future__ import annotations

import enum
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cache
from typing import Protocol

import numpy as np

from sim.joystick import BUTTONS, Kind, Layout, Mode
from tasks.operators.judgement import (Memory, Pace, cube_to_take, deflection_for, held_cube, missed_faces_of,
                                       missed_grasp, norm, placed_cubes, turn_deflection_for, xy_distance, yaw_error)
from tasks.operators.params import OperatorParams
from tasks.stacking.vocabulary import REST, Controls, Goal, Phase, StickIntent, View

OPENING_PROGRESS = 0.02  # closure the fingers must lose to be seen opening (0 open .. 1 closed)



# ---------------------------------------------------------------------------------------------
# the decision

class ActionKind(enum.Enum):
    MOVE = "move"
    TURN = "turn"
    OPEN = "open"
    CLOSE = "close"
    REST = "rest"


@dataclass(frozen=True)
class Action:
    """A step of the task: move the hand to a point, turn the wrist, open or close the fingers."""

    kind: ActionKind
    goal: Goal
    point: np.ndarray | None = None  # for MOVE
    turn: np.ndarray | None = None  # for TURN: wanted rotation about world x, y, z (rad)


# The plan names the same few goals (and opens and closes) tick after tick: each is made once (they are immutable).
@cache
def _goal(step: str, phase: Phase | None = None) -> Goal:
    return Goal(step, phase)


@cache
def _open(step: str) -> Action:
    return Action(ActionKind.OPEN, _goal(step))


@cache
def _close(step: str) -> Action:
    return Action(ActionKind.CLOSE, _goal(step))


def _move(step: str, phase: Phase | None, point: np.ndarray) -> Action:
    return Action(ActionKind.MOVE, _goal(step, phase), point)


def _turn(step: str, turn: np.ndarray) -> Action:
    return Action(ActionKind.TURN, _goal(step), turn=turn)


def next_action(view: View, memory: Memory, p: OperatorParams) -> Action:
    """The next step of the task from the current view (the person's plan, re-made every tick):
    finish a release under way, level a tilted hand, then by what is on the table: retreat from a
    finished stack, carry the held cube, or take the next one."""
    bottom, top = placed_cubes(view, p)
    stack_top = view.table_z + view.cube_size * (int(bottom is not None) + int(top is not None))
    open_hand = view.closure <= p.open_closure
    if memory.backoff_z is not None:  # stuck for a while: lift clear, then take the task up afresh
        return _move("back off", Phase.RISE, np.array([view.hand_pos[0], view.hand_pos[1], memory.backoff_z]))
    if memory.fingers_blocked is not None and not open_hand:  # the fingers are caught: lift them clear first
        return _move("free the fingers", Phase.RISE, np.array([view.hand_pos[0], view.hand_pos[1],
                                                               memory.fingers_blocked + p.hover]))
    if memory.opening and not open_hand:  # a release is not taken back half-way (the touch may flicker)
        return _open("open hand")
    tilt_tolerance = math.radians(p.tilt_deg) * (p.settled_share if memory.turning else 1.0)
    at_cube = any(view.touching) and not open_hand
    tilt_x, tilt_y = view.hand_tilt
    # e.g. after a stray wrist command (a layout that cannot tilt the hand cannot level it either)
    if not at_cube and max(abs(tilt_x), abs(tilt_y)) > tilt_tolerance and memory.controls.layout.levels:
        return _turn("level the hand", np.array([tilt_x, tilt_y, 0.0]))
    if top is not None:
        return _finish(view, stack_top, open_hand, p)
    held = held_cube(view, memory, p)
    if held is not None:
        return _carry(view, memory, held, bottom, stack_top, p)
    return _take(view, memory, cube_to_take(view, bottom), stack_top, open_hand, p)


def _finish(view: View, stack_top: float, open_hand: bool, p: OperatorParams) -> Action:
    """Both cubes stacked: let go, rise, rest."""
    if not open_hand:
        return _open("release")
    hand = view.hand_pos
    above = np.array([hand[0], hand[1], stack_top + p.retreat])
    if hand[2] < above[2] - p.stop:
        return _move("retreat", None, above)
    return Action(ActionKind.REST, Goal("done"))


def _carry(view: View, memory: Memory, held: int, bottom: int | None, stack_top: float, p: OperatorParams
           ) -> Action:
    """Take the held cube over B (or onto the cube at B) and set it down.  (The points on Python floats:
    the array forms' elementwise sums and differences.)"""
    hand, cube = view.hand_pos.tolist(), view.cube_pos[held].tolist()
    grip = [h - c for h, c in zip(hand, cube)]  # where the hand holds the cube (it is not centred)
    dest_xy = view.target_xy.tolist() if bottom is None else view.cube_pos[bottom].tolist()[:2]
    support = view.table_z if bottom is None else view.cube_pos[bottom][2] + view.cube_size / 2
    release = [dest_xy[0] + grip[0], dest_xy[1] + grip[1], support + view.cube_size / 2 + p.release_gap + grip[2]]
    off = xy_distance(cube, dest_xy)
    if off <= p.placed and cube[2] - view.cube_size / 2 - support <= p.release_gap + p.stop:
        return _open(f"release cube {held + 1}")
    carry_z = stack_top + p.carry_clearance + view.cube_size / 2 + grip[2]
    step = f"carry cube {held + 1}"
    # down at the release height (within the approach's align tolerance) but farther from its place than
    # placed_cubes accepts: slide it there first, or it would be taken up and let go of again and again
    accepted = p.target_zone if bottom is None else p.placed
    arrival = (_open(f"release cube {held + 1}") if off <= accepted
               else _move(step, Phase.TRAVEL, np.array([release[0], release[1], hand[2]])))
    # an xy error no push could make smaller is left where the release tolerates it (its height is not: lower is blocked)
    # onto the other cube, lined up with it within the place's own tolerance before going down: an xy error
    # left for the bottom is slid away there, and a cube slid on top of the other drags or pushes it off B
    align = p.align if bottom is None else min(p.align, p.placed)
    return _approach(hand, release, carry_z, p, step, arrival, memory.descending, memory.stalled,
                     accepted=(min(memory.pulse_step / 2, accepted), 0.0), align=align)


def _take(view: View, memory: Memory, k: int, stack_top: float, open_hand: bool, p: OperatorParams) -> Action:
    """Reach cube ``k`` with an open hand lined up with its faces, and close on it.  (The points on
    Python floats, as in ``_carry``.)"""
    hand, (x, y, z) = view.hand_pos.tolist(), view.cube_pos[k].tolist()
    grasp = [x, y, z + p.grasp_offset]
    xy_off = xy_distance(hand, grasp)
    # at the bottom, the same xy tolerance as a descent under way: the closing fingers centre the cube
    at_grasp = (xy_off <= p.reach * p.align
                and (abs(hand[2] - grasp[2]) <= p.reach * p.stop or memory.stalled))
    if at_grasp and not memory.missed and (view.touching[k] or not open_hand):
        if missed_grasp(view, memory, p):
            return _open(f"missed cube {k + 1}: open hand")
        return _close(f"grasp cube {k + 1}")
    if not open_hand:
        return _open("open hand")
    hover_z = max(grasp[2] + p.hover, stack_top + p.carry_clearance + view.cube_size)
    # after a grasp of this cube closed on nothing, the other pair of faces: not the same pose again
    # (e.g. a cube lying against this one holds a finger off the faces toward it; across them there is room)
    avoid = memory.missed_faces[1] if memory.missed_faces is not None and memory.missed_faces[0] == k else None
    turn = yaw_error(view, k, avoid)
    yaw_tolerance = math.radians(p.yaw_deg) * (p.settled_share if memory.turning else 1.0)
    if xy_off <= p.turn_reach * p.align and abs(turn) > yaw_tolerance:
        if hand[2] < grasp[2] + p.turn_clearance * p.hover and not memory.turning:  # the fingers would hit the cube
            return _move(f"reach cube {k + 1}", Phase.RISE_TO_TURN, np.array([hand[0], hand[1], hover_z]))
        return _turn(f"turn to cube {k + 1}", np.array([0.0, 0.0, turn]))
    # what the grasp tolerates (at_grasp) bounds the error left when a push would move the hand too far to reduce it
    left = memory.pulse_step / 2
    return _approach(hand, grasp, hover_z, p, f"reach cube {k + 1}", _close(f"grasp cube {k + 1}"),
                     memory.descending, memory.stalled,
                     accepted=(min(left, p.reach * p.align), min(left, p.reach * p.stop)))


def _approach(hand: Sequence[float], goal: Sequence[float], travel_z: float, p: OperatorParams, step: str,
              on_arrival: Action, descending: bool, stalled: bool = False,
              accepted: tuple[float, float] = (0.0, 0.0), align: float | None = None) -> Action:
    """Rise to the travel height if low and far, travel over the goal, go down, then act.
    A descent already under way tolerates twice the alignment error (``align``, default the operator's);
    a stalled one has arrived.  ``accepted``: (xy, z) errors left as they are even where larger than the
    align and stop tolerances (no push could make them smaller)."""
    align = p.align if align is None else align
    xy_off = xy_distance(hand, goal)
    if xy_off > max(align * (2 if descending else 1), accepted[0]):
        if hand[2] < travel_z - p.rise_margin * p.stop and xy_off > p.reach * p.align:
            return _move(step, Phase.RISE, np.array([hand[0], hand[1], travel_z]))
        return _move(step, Phase.TRAVEL, np.array([goal[0], goal[1], hand[2]]))
    if abs(hand[2] - goal[2]) > max(p.stop, accepted[1]) and not stalled:
        over = hand if xy_off <= max(p.stop, accepted[0]) else goal
        return _move(step, Phase.DESCEND, np.array([over[0], over[1], goal[2]]))
    return on_arrival


def hand_velocity(view: View, memory: Memory) -> tuple[float, float, float]:
    """What the person sees the hand doing: the change since the previous glance (m/s, on Python
    floats: the array form's differences and divisions)."""
    if memory.last_seen is None or view.t <= memory.last_seen[0]:
        return 0.0, 0.0, 0.0
    seen_t, seen = memory.last_seen
    elapsed, (x, y, z), (x0, y0, z0) = view.t - seen_t, view.hand_pos.tolist(), seen.tolist()
    return (x - x0) / elapsed, (y - y0) / elapsed, (z - z0) / elapsed


def plan(view: View, memory: Memory, p: OperatorParams, combine_axes: bool,
         holding: Mapping[str, float] | None = None, anticipation: float | None = None,
         pace: Pace | None = None, velocity: tuple[float, float, float] | None = None) -> tuple[StickIntent, Memory]:
    """Decide the stick intent for this tick.

    ``holding`` is the deflection currently applied per function (what the person feels in the
    hand); the person lets go ``anticipation`` seconds (default: the parameter) of the hand's
    current travel before the goal; ``pace`` slows translations (``deflection_for``); ``velocity``:
    ``hand_velocity(view, memory)`` when the caller has it already.
    """
    velocity = hand_velocity(view, memory) if velocity is None else velocity
    touching = any(view.touching)
    since = view.t if memory.touch_since is None else memory.touch_since
    glance = {"touch_since": since if touching else None, "last_seen": (view.t, view.hand_pos)}
    if glance["touch_since"] != memory.touch_since:  # the plan reads it (held_cube); last_seen is the next glance's
        memory = _updated(memory, touch_since=glance["touch_since"])
    action = next_action(view, memory, p)
    descending = action.goal.descending
    finger_mode, _ = memory.controls.layout.find(Kind.FINGERS, 1.0)
    _, opening_fn = memory.controls.layout.find(Kind.FINGERS, -1.0)
    closing = action.kind is ActionKind.CLOSE and view.mode is finger_mode and not touching
    missed = missed_grasp(view, memory, p)
    freed = memory.fingers_blocked is not None and (
        view.closure <= p.open_closure or view.hand_pos[2] >= memory.fingers_blocked + p.hover - p.stop)
    learnt = dict(turning=action.kind is ActionKind.TURN, descending=descending,
                  stalled=(memory.stalled or action.kind is ActionKind.CLOSE)
                  and (descending or action.kind in (ActionKind.OPEN, ActionKind.CLOSE)) and not missed,
                  missed=(memory.missed or missed) and not touching and view.closure > p.open_closure,
                  missed_faces=missed_faces_of(view, p) if missed else None if touching else memory.missed_faces,
                  fingers_blocked=None if freed else memory.fingers_blocked,
                  backoff_z=None if memory.backoff_z is None or view.hand_pos[2] >= memory.backoff_z - p.stop
                  else memory.backoff_z,
                  closing_since=(view.t if memory.closing_since is None else memory.closing_since) if closing else None,
                  opening=action.kind is ActionKind.OPEN and view.mode is finger_mode and opening_fn in (holding or {}))
    anticipation = p.anticipation if anticipation is None else anticipation
    if action.kind is ActionKind.MOVE:
        error = (action.point - view.hand_pos).tolist()  # to the point, on Python floats (the array's differences)
        need, deflection, axis = _translation(error, velocity, anticipation, p, combine_axes,
                                              memory.axis, holding or {}, memory.controls.layout, view.mode, pace)
    else:
        (need, deflection), axis = _other_action(action, memory.controls.layout, p, anticipation), None
    if need is not None and need is not view.mode:
        # without a mode button the person rests and waits for the automatic mode switching (tasks/operators/assist.py)
        button = mode_button(view.mode, need, memory.controls) if memory.controls.buttons else None
        return StickIntent(button=button, goal=replace(action.goal, mode=need)), _updated(memory, **learnt, **glance)
    remaining = 0.0
    if action.kind is ActionKind.MOVE:
        effects = memory.controls.layout.effects[view.mode]
        dx, dy, dz = error  # np.dot with each axis, on floats (to the bit)
        remaining = max((abs(dx * ax + dy * ay + dz * az) for ax, ay, az in (effects[fn].axis for fn in deflection)),
                        default=0.0)
    return (StickIntent(deflection, goal=action.goal, remaining=remaining),
            _updated(memory, **learnt, **glance, axis=axis))


def _other_action(action: Action, layout: Layout, p: OperatorParams, anticipation: float
                  ) -> tuple[Mode | None, dict[str, float]]:
    """The mode and the stick for a turn (one rotation axis at a time, the largest first, as fast
    as lets it coast part of the way), an open or a close; no mode and no stick to rest."""
    if action.kind is ActionKind.TURN:
        axis = int(np.argmax(np.abs(action.turn)))
        direction = [0.0, 0.0, 0.0]
        direction[axis] = math.copysign(1.0, action.turn[axis])
        mode, fn = layout.find(Kind.ANGULAR, tuple(direction))
        return mode, {fn: turn_deflection_for(abs(float(action.turn[axis])), p, anticipation)}
    if action.kind in (ActionKind.OPEN, ActionKind.CLOSE):
        mode, fn = layout.find(Kind.FINGERS, 1.0 if action.kind is ActionKind.CLOSE else -1.0)
        return mode, {fn: p.coarse}
    return None, {}


def _updated(memory: Memory, **changes) -> Memory:
    """``dataclasses.replace(memory, **changes)`` at a third of its cost (``plan`` makes one or two a
    tick): the frozen fields set at once, not one ``object.__setattr__`` at a time (Memory has no
    ``__post_init__`` to run)."""
    updated = object.__new__(Memory)
    updated.__dict__.update(vars(memory), **changes)
    return updated


def _translation(error: list[float], velocity: tuple[float, float, float], anticipation: float, p: OperatorParams,
                 combine_axes: bool, axis: int | None, holding: Mapping[str, float], layout: Layout, mode: Mode,
                 pace: Pace | None = None) -> tuple[Mode, dict[str, float], int | None]:
    """The mode, and the joystick functions (and their deflections) in it, that take the hand the ``error``
    (the point minus the hand, world axes) to its point.

    An axis being moved stops when the hand would coast (``anticipation`` seconds of its ``velocity``: the
    travel expected after letting go) to within the stop tolerance of its goal; an idle axis
    starts again only when it is off by twice the stop tolerance (no dithering), unless nothing
    else would move the hand toward a goal the plan still wants.  Where the layout moves some axes
    in another mode (2-axis: z in the height mode), the axes of the current ``mode`` are finished
    first: a switch costs presses.
    """
    coast = [v * anticipation for v in velocity]
    movers = [_function_along(layout, i, error[i] >= 0) for i in range(3)]  # (mode, function) per axis
    held = {fn for fn in holding if fn in layout.axes(mode, Kind.LINEAR)}  # moving the hand now
    moving = []
    for i, (need, fn) in enumerate(movers):
        if need is mode and fn in held:
            closing_in = max(0.0, coast[i] * math.copysign(1.0, error[i]))
            keep = abs(error[i]) > p.stop + closing_in
        else:
            keep = abs(error[i]) > p.restart * p.stop
        if keep:
            moving.append(i)
    if not moving and not held:
        moving = [max(range(3), key=lambda i: abs(error[i]))]  # np.argmax's: the first of the largest
    if not moving:
        return mode, {}, None
    moving = [i for i in moving if movers[i][0] is mode] or moving
    if combine_axes:
        largest = max(moving, key=lambda i: abs(error[i]))
        moving = [i for i in moving if movers[i][0] is movers[largest][0]]
    else:
        if axis not in moving:
            axis = max(moving, key=lambda i: abs(error[i]))
        moving = [axis]
    return movers[moving[0]][0], {movers[i][1]: deflection_for(abs(error[i]), p, anticipation, pace) for i in moving}, axis


@cache  # three per tick, always the same few answers per layout
def _function_along(layout: Layout, axis: int, positive: bool) -> tuple[Mode, str]:
    """The mode and the function that move the hand along world ``axis``, in its ``positive`` direction or not."""
    direction = [0.0, 0.0, 0.0]
    direction[axis] = 1.0 if positive else -1.0
    return layout.find(Kind.LINEAR, tuple(direction))


def mode_button(current: Mode, wanted: Mode, controls: Controls = Controls()) -> str:
    """The button among ``controls`` that reaches ``wanted`` from ``current`` in fewer presses (B1 on a tie)."""
    presses = {button: controls.layout.presses(current, wanted, button)
               for button in BUTTONS if button in controls.buttons}
    return min(presses, key=presses.get)


# ---------------------------------------------------------------------------------------------
# the person in time

class Timing(Protocol):
    """When a person starts a new move and how fast they make it (``tasks.operators.human.HumanTiming``)."""

    def reaction(self, view: View, wanted: StickIntent, after: frozenset[Kind], controls: Controls) -> float:
        """Seconds from wanting ``wanted`` to starting it, drawn once per move; ``after``: what the
        move or press let go before it did (e.g. ``Kind.FINGERS``: a grasp or a release)."""

    @property
    def pause(self) -> float:
        """Least rest between letting go of a move and starting the next."""

    def pace(self, distance: float, tolerance: float) -> float:
        """Least time to cover ``distance`` to within ``tolerance`` (0: no such limit)."""

    def hold(self, wanted: StickIntent, settle: float) -> float:
        """How long to hold the move of the hand ``wanted`` (starting now) before letting go whatever
        is seen (inf: watch the hand and let go when it is about to arrive); ``settle``: how long the
        hand has been seen going on after a move is let go."""

    @property
    def pulse_step(self) -> float:
        """How far (m) the hand has been seen to go for the pulses the arm answered, a running mean (0: as little as wanted)."""

    @property
    def answered_hold(self) -> float:
        """How long (s) a push has had to be held to be seen answered (0: at once)."""


@dataclass(frozen=True)
class FixedTiming:
    """The scripted user's constants: ``reaction_time`` before every move, ``pause_between_moves``."""

    params: OperatorParams

    def reaction(self, view: View, wanted: StickIntent, after: frozenset[Kind], controls: Controls) -> float:
        return self.params.reaction_time

    @property
    def pause(self) -> float:
        return self.params.pause_between_moves

    def pace(self, distance: float, tolerance: float) -> float:
        return 0.0

    def hold(self, wanted: StickIntent, settle: float) -> float:
        return math.inf

    @property
    def pulse_step(self) -> float:
        return 0.0

    @property
    def answered_hold(self) -> float:
        return 0.0


@dataclass
class ScriptedUser:
    """``plan`` with a human's timing: reaction time, pauses between moves, and a stopping
    anticipation learnt from experience (how far the hand kept going after the last stops:
    short with a joystick, longer through a BoMI)."""

    params: OperatorParams
    combine_axes: bool
    memory: Memory = field(default_factory=Memory)
    current: StickIntent = REST
    anticipation: float | None = None
    _waiting_since: float | None = None
    _stopped_at: float = -math.inf
    _started: float = 0.0  # when the current move began
    _mode_at_start: Mode | None = None  # the arm's mode when it began
    _relax_until: float = -math.inf
    _coasting: tuple[float, np.ndarray, float] | None = None  # (t, hand, speed) when a move was let go
    settle: float = 0.0  # learnt: how long the hand keeps (or starts) moving after a move is let go
    _last_moving: float = -math.inf  # when the hand was last seen moving
    _released_move: bool = False  # the last thing let go was a stick move (not a button)
    _height_seen: tuple[float, float] = (0.0, 0.0)  # (s pushed down since the hand was last seen going lower, its height then)
    _push_down: float = 0.0  # s: how long the push down held now (or last) has been held
    _last_glance: float = -math.inf
    _closure_seen: tuple[float, float] = (-math.inf, 0.0)  # (since when, closure) while opening the fingers
    timing: Timing | None = None  # default: FixedTiming(params)
    _reaction: float = 0.0  # the reaction drawn for the move being waited for
    _let_go_of: frozenset[Kind] = frozenset()  # what the last move let go did (nothing for a press)
    _hold: float = math.inf  # how long the move held now is held whatever is seen (Timing.hold)

    def __post_init__(self) -> None:
        if self.anticipation is None:
            self.anticipation = self.params.anticipation
        if self.timing is None:
            self.timing = FixedTiming(self.params)

    @property
    def started(self) -> float:
        """When the move or press held now (or last) began."""
        return self._started

    @property
    def hold(self) -> float:
        """How long the move held now (or last) is held whatever is seen (``Timing.hold``; inf: watched)."""
        return self._hold

    def stick_intent(self, view: View) -> StickIntent:
        """What the person does with the stick at this glance."""
        velocity = hand_velocity(view, self.memory)
        speed = norm(velocity)
        if speed > self.params.still_speed:
            self._last_moving = view.t
        self._learn_coasting(view, speed)
        self._watch_descent(view)
        self._watch_opening(view)
        if (self.memory.pulse_step, self.memory.answered_hold) != (self.timing.pulse_step, self.timing.answered_hold):
            self.memory = replace(self.memory, pulse_step=self.timing.pulse_step, answered_hold=self.timing.answered_hold)
        wanted, self.memory = plan(view, self.memory, self.params, self.combine_axes, self.current.deflection,
                                   self.anticipation, self.timing.pace, velocity)
        if self.current.button is not None and view.mode is not self._mode_at_start:
            wanted = StickIntent(goal=wanted.goal)  # the press worked: let go (press again if need be)
        elif self.current.button is not None and view.t - self._started > self.params.button_patience:
            # the press did nothing: let go, relax as long again, then press anew
            wanted = StickIntent(goal=wanted.goal)
            self._relax_until = view.t + self.params.button_patience
        if self.current.deflection and view.t - self._started >= self._hold - 1e-9:
            wanted = StickIntent(goal=wanted.goal)  # the move planned without watching is over: let go, wait, look
        if wanted.is_rest or _continues(self.current, wanted):
            if wanted.is_rest and not self.current.is_rest:
                self._let_go(view, velocity)
            self.current, self._waiting_since = wanted, None
            return wanted
        if not self.current.is_rest:  # a different move: stop this one first
            self._let_go(view, velocity)
            self.current = REST
        if self._waiting_since is None:
            self._waiting_since = view.t
            self._reaction = self.timing.reaction(view, wanted, self._let_go_of, self.memory.controls)
        ready = max(self._waiting_since + self._reaction,
                    self._stopped_at + max(self.timing.pause, self.settle), self._relax_until)
        coasting = (speed > self.params.still_speed
                    and view.t - self._stopped_at < self.params.max_wait)
        if view.t + 1e-9 < ready or coasting:  # watch the hand come to rest before the next move
            return StickIntent(goal=wanted.goal)
        self._learn_settling()
        self.current, self._waiting_since, self._started, self._mode_at_start = wanted, None, view.t, view.mode
        self._hold = self.timing.hold(wanted, self.settle)
        return wanted

    def resume(self, view: View) -> None:
        """Take the task up again after a recovery (``tasks.operators.recovery``): from rest, with a new reaction."""
        self.current, self._waiting_since, self._stopped_at, self._hold = REST, None, view.t, math.inf

    def back_off(self, view: View) -> None:
        """Give up the plan under way: lift the hand ``hover`` above where it is, then plan afresh
        (what was learnt of the arm is kept; what the plan remembered of this attempt is not)."""
        self.memory = Memory(controls=self.memory.controls, pulse_step=self.memory.pulse_step,
                             answered_hold=self.memory.answered_hold, backoff_z=float(view.hand_pos[2]) + self.params.hover)
        self.resume(view)

    def _let_go(self, view: View, velocity: tuple[float, float, float]) -> None:
        self._stopped_at = view.t
        effects = self.memory.controls.layout.effects[view.mode]
        self._let_go_of = frozenset(effects[fn].kind for fn in self.current.deflection if fn in effects)
        self._released_move = bool(self.current.deflection)
        speed = norm(velocity)
        moving = self.memory.controls.layout.axes(view.mode, Kind.LINEAR)
        if any(fn in moving for fn in self.current.deflection) and speed > self.params.coasting_min_speed:
            self._coasting = (view.t, view.hand_pos, speed)

    def _watch_descent(self, view: View) -> None:
        """A descent pushed down for ``stall_time`` without the hand going lower is stalled (the cube
        or the fingers rest on something): the person takes it as arrived.  The time pushed down adds
        up over the pushes of one descent (a descent made in pulses, each shorter than ``stall_time``,
        stalls as well), and starts again when the hand goes lower or another move of the stick is made.
        A push shorter than the interface has needed to answer (``Timing.answered_hold``) and not
        answered says nothing of the hand: it does not count."""
        moves = self.memory.controls.layout.axes(view.mode, Kind.LINEAR)
        pushing_down = any(fn in moves and moves[fn][2] < 0 for fn in self.current.deflection)
        descent = self.current.goal.descending and pushing_down
        # what was held since the last glance was held this long
        held = max(0.0, view.t - self._last_glance) if math.isfinite(self._last_glance) else 0.0
        self._last_glance = view.t
        pushed, height = self._height_seen
        if (self.current.deflection and not descent) or height - view.hand_pos[2] > self.params.stop:
            self._height_seen, self._push_down = (0.0, float(view.hand_pos[2])), 0.0
            return
        if descent:
            self._push_down += held
        counted = self._push_down if self._push_down >= self.timing.answered_hold else 0.0
        if not descent and self._push_down > 0:  # a push down has ended
            self._height_seen, self._push_down = (pushed + counted, height), 0.0
        elif not descent and pushed == 0:  # no push down yet: the height to go lower than
            self._height_seen = (0.0, float(view.hand_pos[2]))
        elif pushed + counted > self.params.stall_time:
            self.memory = replace(self.memory, stalled=True)

    def _watch_opening(self, view: View) -> None:
        """Fingers pushed open for ``miss_time`` (from when the push is answered: ``answered_hold``) without
        opening further are caught (on a cube set down askew, between the cubes): the person lifts the hand
        before opening on."""
        fingers = self.memory.controls.layout.axes(view.mode, Kind.FINGERS)
        opening = any(fn in fingers and fingers[fn] < 0 for fn in self.current.deflection)
        since, closure = self._closure_seen
        if not opening or closure - view.closure > OPENING_PROGRESS:
            self._closure_seen = (view.t, view.closure)
        elif view.t - since > self.params.miss_time + self.timing.answered_hold:
            self.memory = replace(self.memory, fingers_blocked=float(view.hand_pos[2]))
            self._closure_seen = (view.t, view.closure)

    def _learn_settling(self) -> None:
        """Before a new move: update how long the hand went on moving after the last stick move was
        let go (through a BoMI the arm answers late; the person learns to watch it settle first)."""
        if self._released_move and math.isfinite(self._stopped_at):
            seen = min(max(0.0, self._last_moving - self._stopped_at), self.params.max_wait)
            rate = self.params.learning_rate
            self.settle = (1.0 - rate) * self.settle + rate * seen
        self._released_move = False

    def _learn_coasting(self, view: View, speed: float) -> None:
        """Once the hand has come to rest (or a new move began), update the anticipation."""
        if self._coasting is None or (speed > self.params.still_speed and self.current.is_rest):
            return
        t0, start, speed0 = self._coasting
        seconds = norm(view.hand_pos - start) / speed0
        rate = self.params.learning_rate
        self.anticipation = (1.0 - rate) * self.anticipation + rate * min(seconds, self.params.max_anticipation)
        self._coasting = None




def _continues(current: StickIntent, wanted: StickIntent) -> bool:
    """Same move still going on: the same button held, or the stick still pushed along at least
    one of the functions it already holds (a combined move may drop or add an axis)."""
    if current.is_rest:
        return False
    if wanted.button is not None:
        return wanted.button == current.button
    return not wanted.deflection.keys().isdisjoint(current.deflection)
