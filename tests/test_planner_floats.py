"""The planner's per-tick geometry on Python floats against its array forms (the code as it was
written on numpy 3-vectors, kept here as the reference): the same actions and goals, and points
to 4 ulps (a norm or an arctan2 may round another way in numpy's SIMD code than in libm's), over
random scenes around the cubes and B."""
import math

import numpy as np

from helpers import disagreement
from tasks.operators import planner
from tasks.operators.planner import Action, _approach, _close, _move, _open, _turn
from tasks.operators.judgement import (Memory, cube_to_take, held_cube, missed_grasp, placed_cubes, xy_distance,
                                       yaw_error)
from tasks.stacking.vocabulary import Phase, View
from tasks.operators.params import load_operator
from sim.joystick import Mode

P = load_operator()
HALF = 0.025
B = np.array([0.14, -0.45])


def placed_cubes_on_arrays(view: View, p) -> tuple:
    rest_z = view.table_z + view.cube_size / 2
    gripped = [touch and view.closure > p.open_closure for touch in view.touching]
    bottom = None
    for k, pos in enumerate(view.cube_pos):
        if np.linalg.norm(pos[:2] - view.target_xy) <= p.target_zone and abs(pos[2] - rest_z) <= p.placed \
                and not gripped[k]:
            bottom = k
    if bottom is None:
        return None, None
    for k, pos in enumerate(view.cube_pos):
        if k == bottom or gripped[k]:
            continue
        if np.linalg.norm(pos[:2] - view.cube_pos[bottom][:2]) <= p.placed \
                and abs(pos[2] - view.cube_pos[bottom][2] - view.cube_size) <= p.placed:
            return bottom, k
    return bottom, None


def carry_on_arrays(view, memory, held, bottom, stack_top, p) -> Action:
    hand, cube = view.hand_pos, view.cube_pos[held]
    grip = hand - cube
    dest_xy = view.target_xy if bottom is None else view.cube_pos[bottom][:2]
    support = view.table_z if bottom is None else view.cube_pos[bottom][2] + view.cube_size / 2
    release_xy = dest_xy + grip[:2]
    release = np.array([release_xy[0], release_xy[1], support + view.cube_size / 2 + p.release_gap + grip[2]])
    off = xy_distance(cube, dest_xy)
    if off <= p.placed and cube[2] - view.cube_size / 2 - support <= p.release_gap + p.stop:
        return _open(f"release cube {held + 1}")
    carry_z = stack_top + p.carry_clearance + view.cube_size / 2 + grip[2]
    step = f"carry cube {held + 1}"
    accepted = p.target_zone if bottom is None else p.placed
    arrival = (_open(f"release cube {held + 1}") if off <= accepted
               else _move(step, Phase.TRAVEL, np.array([release[0], release[1], hand[2]])))
    align = p.align if bottom is None else min(p.align, p.placed)
    return _approach(hand, release, carry_z, p, step, arrival, memory.descending, memory.stalled,
                     accepted=(min(memory.pulse_step / 2, accepted), 0.0), align=align)


def take_on_arrays(view, memory, k, stack_top, open_hand, p) -> Action:
    hand, cube = view.hand_pos, view.cube_pos[k]
    grasp = np.array([cube[0], cube[1], cube[2] + p.grasp_offset])
    xy_off = xy_distance(hand, grasp)
    at_grasp = (xy_off <= p.reach * p.align
                and (abs(hand[2] - grasp[2]) <= p.reach * p.stop or memory.stalled))
    if at_grasp and not memory.missed and (view.touching[k] or not open_hand):
        if missed_grasp(view, memory, p):
            return _open(f"missed cube {k + 1}: open hand")
        return _close(f"grasp cube {k + 1}")
    if not open_hand:
        return _open("open hand")
    hover_z = max(grasp[2] + p.hover, stack_top + p.carry_clearance + view.cube_size)
    avoid = memory.missed_faces[1] if memory.missed_faces is not None and memory.missed_faces[0] == k else None
    turn = yaw_error(view, k, avoid)
    yaw_tolerance = math.radians(p.yaw_deg) * (p.settled_share if memory.turning else 1.0)
    if xy_off <= p.turn_reach * p.align and abs(turn) > yaw_tolerance:
        if hand[2] < grasp[2] + p.turn_clearance * p.hover and not memory.turning:
            return _move(f"reach cube {k + 1}", Phase.RISE_TO_TURN, np.array([hand[0], hand[1], hover_z]))
        return _turn(f"turn to cube {k + 1}", np.array([0.0, 0.0, turn]))
    left = memory.pulse_step / 2
    return _approach(hand, grasp, hover_z, p, f"reach cube {k + 1}", _close(f"grasp cube {k + 1}"),
                     memory.descending, memory.stalled,
                     accepted=(min(left, p.reach * p.align), min(left, p.reach * p.stop)))


def same_action(a: Action, b: Action) -> bool:
    def same(x, y):
        return (x is None) == (y is None) and (x is None or (x.shape == y.shape and disagreement(x, y) is None))
    return a.kind is b.kind and a.goal == b.goal and same(a.point, b.point) and same(a.turn, b.turn)


def random_scene(rng: np.random.Generator) -> tuple[View, Memory]:
    """Cubes at A, at B, stacked or in the hand, the hand near one of them or anywhere, at millimetre scales."""
    near = rng.choice([1e-4, 1e-3, 1e-2, 1e-1])
    bottom = np.r_[B + rng.normal(size=2) * near, HALF + rng.normal() * near * 0.1]
    other = np.r_[rng.uniform(-0.2, 0.2), rng.uniform(-0.6, -0.35), HALF]
    cubes = [bottom, other] if rng.integers(2) else [other, bottom]
    if rng.integers(3) == 0:  # one on top of the other
        cubes[1] = cubes[0] + np.r_[rng.normal(size=2) * near, 2 * HALF + rng.normal() * near * 0.1]
    held = int(rng.integers(2))
    hand = cubes[held] + rng.normal(size=3) * rng.choice([1e-3, 1e-2, 1e-1])
    touching = tuple(bool(rng.integers(2)) and k == held for k in range(2))
    view = View(t=float(rng.uniform(1, 50)), hand_pos=hand, hand_yaw=float(rng.uniform(-math.pi, math.pi)),
                hand_tilt=np.zeros(2), closure=float(rng.choice([0.0, 0.3, 0.8])), mode=Mode.TRANSLATION,
                cube_pos=tuple(cubes), cube_yaw=tuple(rng.uniform(-0.5, 0.5, size=2).tolist()), touching=touching,
                target_xy=B.copy(), table_z=0.0, cube_size=2 * HALF)
    memory = Memory(touch_since=0.0 if any(touching) else None, descending=bool(rng.integers(2)),
                    stalled=bool(rng.integers(2)), turning=bool(rng.integers(2)), missed=bool(rng.integers(4) == 0),
                    pulse_step=float(rng.choice([0.0, 0.004, 0.02])))
    return view, memory


def test_carry_take_and_placed_cubes_on_floats_equal_their_array_forms():
    rng = np.random.default_rng(8)
    kinds = set()
    for _ in range(4000):
        view, memory = random_scene(rng)
        bottom, top = placed_cubes(view, P)
        assert (bottom, top) == placed_cubes_on_arrays(view, P)
        stack_top = view.table_z + view.cube_size * ((bottom is not None) + (top is not None))
        held = held_cube(view, memory, P)
        if held is not None:
            got, expected = planner._carry(view, memory, held, bottom, stack_top, P), \
                carry_on_arrays(view, memory, held, bottom, stack_top, P)
        else:
            k, open_hand = cube_to_take(view, bottom), view.closure <= P.open_closure
            got, expected = planner._take(view, memory, k, stack_top, open_hand, P), \
                take_on_arrays(view, memory, k, stack_top, open_hand, P)
        assert same_action(got, expected), (got, expected)
        kinds.add((held is not None, got.kind, got.goal.phase))
    assert len(kinds) >= 8  # carries and takes, moves of every phase, opens and closes were compared
