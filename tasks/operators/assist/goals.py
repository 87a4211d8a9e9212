"""The goals the scene offers the assistance (grasp a cube, set the held one down), as it sees them."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tasks.operators.assist.params import AssistParams
from tasks.stacking.vocabulary import View


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
