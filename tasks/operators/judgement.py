"""What the person judges of the task from what they see (``View``): which cubes are placed,
held or to take, how far the hand is turned off a cube, how fast to push for a distance; and the
little they remember between glances (``Memory``).  Pure functions, shared by the scripted
user's plan (``planner``), the human model and the assistance."""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sim.kernels import clip
from tasks.operators.params import OperatorParams
from tasks.stacking.vocabulary import Controls, View

CUBE_SYMMETRY = math.pi / 2  # a cube looks the same every quarter turn
PINCH_SYMMETRY = math.pi  # the fingers close on the same pair of faces with the hand turned half a turn


@dataclass(frozen=True)
class Memory:
    """The little the person remembers between glances (and the controls they have, which do not change)."""

    axis: int | None = None  # single-axis channel: the axis being worked on
    touch_since: float | None = None  # when the fingers started touching the cube being grasped
    turning: bool = False  # a wrist turn goes on until the hand is well lined up
    descending: bool = False  # a descent goes on while the hand stays roughly over the goal
    last_seen: tuple[float, np.ndarray] | None = None  # (t, hand position) at the previous glance
    # arrived at the bottom of a descent, until the grasp is made or missed: a descent pushed on for a while
    # without the hand going lower (it is as low as it goes), or a hand once judged at the grasp (a late arm
    # coasting past it while the fingers mode is pressed does not undo that; over a cube lying on another
    # cube nothing stops the hand, and a new correction would coast past as far again)
    stalled: bool = False
    closing_since: float | None = None  # when the fingers (in the finger mode) began closing on a cube they do not touch yet
    opening: bool = False  # the person is opening the fingers: that goes on until the hand is open
    missed: bool = False  # the last grasp closed on nothing: open the hand fully before trying again
    missed_faces: tuple[int, float] | None = None  # (cube, pair of its faces: hand yaw off the cube's, rad) a grasp missed on
    fingers_blocked: float | None = None  # hand height where the fingers stopped opening (caught on a cube): rise first
    controls: Controls = Controls()  # the same all episode
    # m: how far the hand has been seen to go for the pulses the arm answered (Timing.pulse_step): an error of less
    # than half of it cannot be made smaller by a push, and is left where the grasp or the place tolerates it
    pulse_step: float = 0.0
    # s: how long a push has had to be held to be seen answered (Timing.answered_hold): a grasp is judged from then
    answered_hold: float = 0.0
    backoff_z: float | None = None  # backing off after a while without progress: lift the hand to this height first


def norm(v: Sequence[float]) -> float:
    """Euclidean length of a small vector (2 or 3 elements, an array or Python floats): what
    ``np.linalg.norm`` computes for one (the square root of ``v.dot(v)``, whose BLAS sum of so few
    starts at 0 and adds the squares in order: the same bits), without its generic checks."""
    squares = 0.0
    for c in v:
        squares += c * c
    return math.sqrt(squares)


def xy_distance(a: Sequence[float], b: Sequence[float]) -> float:
    """``norm(a[:2] - b[:2])`` to the bit (the same differences, products and sum), without the
    arrays it makes."""
    dx, dy = a[0] - b[0], a[1] - b[1]
    return math.sqrt(dx * dx + dy * dy)

def placed_cubes(view: View, p: OperatorParams) -> tuple[int | None, int | None]:
    """(cube resting on the table at B, cube resting on top of it), None where there is none.  A cube
    the fingers touch is placed only if the hand is open (it rests there; the hand is not holding it)."""
    rest_z = view.table_z + view.cube_size / 2
    gripped = [touch and view.closure > p.open_closure for touch in view.touching]
    cubes, target = [pos.tolist() for pos in view.cube_pos], view.target_xy.tolist()  # read as Python floats
    bottom = None
    for k, pos in enumerate(cubes):
        at_b = xy_distance(pos, target) <= p.target_zone
        if at_b and abs(pos[2] - rest_z) <= p.placed and not gripped[k]:
            bottom = k
    if bottom is None:
        return None, None
    for k, pos in enumerate(cubes):
        if k == bottom or gripped[k]:
            continue
        on_top = xy_distance(pos, cubes[bottom]) <= p.placed
        if on_top and abs(pos[2] - cubes[bottom][2] - view.cube_size) <= p.placed:
            return bottom, k
    return bottom, None


def held_cube(view: View, memory: Memory, p: OperatorParams) -> int | None:
    """The cube the hand has been squeezing for the squeeze time, if any (the one nearest the pinch
    point when the fingers touch more than one, e.g. a cube lying against the other)."""
    if memory.touch_since is None or view.t - memory.touch_since < p.squeeze_time:
        return None
    touching = [k for k, touch in enumerate(view.touching) if touch]
    if not touching or view.closure <= p.open_closure:
        return None
    if len(touching) == 1:  # (min's answer, without the distance it would work out for nothing)
        return touching[0]
    return min(touching, key=lambda k: norm(view.cube_pos[k] - view.hand_pos))


def missed_grasp(view: View, memory: Memory, p: OperatorParams) -> bool:
    """The fingers have been closing for ``miss_time`` without touching a cube: they closed on
    nothing, or beside the cube against something else. Counted from when the interface answers the
    closing push (``answered_hold`` after it, as the person has learnt): through a lagging BoMI a clock
    started at the push would call a grasp missed before the fingers had reached the cube."""
    return (memory.closing_since is not None and view.t - memory.closing_since > p.miss_time + memory.answered_hold
            and not any(view.touching))


def missed_faces_of(view: View, p: OperatorParams) -> tuple[int, float]:
    """The cube a grasp has just missed (only the cube to take is grasped) and the pair of its faces
    the fingers closed on."""
    k = cube_to_take(view, placed_cubes(view, p)[0])
    return k, faces_lined_up(view, k)


def cube_to_take(view: View, bottom: int | None) -> int:
    """The next cube to pick up: the first not placed at B, unless another lies on top of it."""
    candidates = [k for k in range(len(view.cube_pos)) if k != bottom]
    k = candidates[0]
    for other in candidates[1:]:
        if view.cube_pos[other][2] > view.cube_pos[k][2] + view.cube_size / 2:
            k = other
    return k


def wrapped_angle(angle: float, period: float) -> float:
    """``angle`` (rad) brought into [-period/2, period/2) by whole periods."""
    return (angle + period / 2) % period - period / 2


def yaw_error(view: View, k: int, avoid: float | None = None) -> float:
    """Wrist turn (rad) that lines the hand up with the nearest face of cube k, in [-pi/4, pi/4); or,
    with ``avoid`` (a pair of faces, ``faces_lined_up``), with the other pair, in [-pi/2, pi/2)."""
    err = view.cube_yaw[k] - view.hand_yaw
    if avoid is None:
        return wrapped_angle(err, CUBE_SYMMETRY)
    return wrapped_angle(err - avoid - CUBE_SYMMETRY, PINCH_SYMMETRY)


def faces_lined_up(view: View, k: int) -> float:
    """The pair of faces of cube k the fingers close on now: the hand's yaw off the cube's, to the
    nearest quarter turn, modulo half a turn (0 or pi/2)."""
    return round((view.cube_yaw[k] - view.hand_yaw) / CUBE_SYMMETRY) % 2 * CUBE_SYMMETRY


Pace = Callable[[float, float], float]  # (distance, tolerance) -> the least time a person takes to cover it


def deflection_for(distance: float, p: OperatorParams, anticipation: float, pace: Pace | None = None) -> float:
    """As fast as lets the hand coast (``anticipation`` seconds of the speed) no further than
    ``coast_share`` of the distance, between fine and coarse: a person who has learnt that the arm
    goes on for a while after letting go does not go full speed into a short move, and makes small
    corrections slowly enough not to overshoot them.  ``pace`` (a human model's movement time, e.g.
    Fitts' law) may slow a move further: no faster than covers the distance in that time."""
    coast = p.coast_share * distance / (p.full_speed * max(anticipation, 1e-9))
    least_time = 0.0 if pace is None else pace(distance, 2 * p.stop)
    if least_time > 0:
        coast = min(coast, distance / (p.full_speed * least_time))
    return clip(coast, p.fine, p.coarse)  # np.clip's result, without its overhead


def turn_deflection_for(angle: float, p: OperatorParams, anticipation: float) -> float:
    """The same rule for a wrist turn of ``angle`` rad, between fine and ``turn``."""
    return clip(p.coast_share * angle / (p.full_turn_speed * max(anticipation, 1e-9)), p.fine, p.turn)
