"""The assistance layer itself: ``Assistance.step`` once per control tick, between the decided stick and
the arm; every switch it makes an ``AutomaticSwitch``."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from sim.joystick import BUTTONS, JoystickState, Kind, Layout, Mode
from tasks.operators.assist.belief import GoalBelief, motion_scores
from tasks.operators.assist.goals import Goal, candidate_goals, held_cube
from tasks.operators.assist.learning import LearntTolerance, PressResponse, SwitchContext
from tasks.operators.assist.options import Assist, assist_label
from tasks.operators.assist.params import AssistParams, load_assist
from tasks.operators.assist.path import (EITHER_ORDER, PATH_ORDER, PathStep, next_step_modes, next_step_shares,
                                        path_steps, revisit_scale, rise_error, step_errors, step_of_move,
                                        time_to_goal, user_order, yaw_offset)
from tasks.stacking.vocabulary import View


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


class Switchable(Protocol):
    """What the assistance needs of the arm (``sim.env.ArmSim``)."""

    dt: float

    @property
    def mode(self) -> Mode: ...

    def switch_mode(self, mode: Mode) -> None: ...


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
