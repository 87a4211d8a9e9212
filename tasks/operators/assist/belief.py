"""The belief over the goals the user heads for, from the motion they command."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sim.joystick import JoystickState, Kind, Layout, combine
from tasks.operators.assist.goals import Goal
from tasks.operators.assist.params import AutoModeParams, PathParams
from tasks.operators.assist.path import yaw_offset
from tasks.stacking.vocabulary import View


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
