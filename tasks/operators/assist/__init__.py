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

Modules: ``options`` (the assistances' names: ``Assist``, ``parse_assist``, ``profile_assist``),
``params`` (``assist.toml`` -> ``AssistParams``), ``goals`` (the scene's candidate goals),
``path`` (the careful path's steps, their modes, the presses to them), ``belief`` (``GoalBelief``
over the goals from the commanded motion), ``learning`` (this user's tolerances, press response
and what a switch was made for) and ``assistance`` (the layer, ``Assistance``). The public names are
re-exported here.
"""
from tasks.operators.assist.assistance import Assistance, AutomaticSwitch, Switchable
from tasks.operators.assist.belief import GoalBelief, motion_scores
from tasks.operators.assist.goals import Goal, candidate_goals, held_cube
from tasks.operators.assist.learning import LearntTolerance, PressResponse, SwitchContext
from tasks.operators.assist.options import (ASSIST_HELP, NONE, Assist, assist_label, assist_option, parse_assist,
                                            profile_assist)
from tasks.operators.assist.params import (DEFAULT_ASSIST_FILE, AssistParams, AutoModeParams, GraspHelpParams,
                                           PathParams, load_assist)
from tasks.operators.assist.path import (EITHER_ORDER, PATH_ORDER, PathStep, Step, next_step_modes, next_step_shares,
                                         path_order, path_steps, presses, revisit_scale, rise_error, step_errors,
                                         step_of_move, time_to_goal, user_order, yaw_offset)

__all__ = [
    "ASSIST_HELP", "DEFAULT_ASSIST_FILE", "EITHER_ORDER", "NONE", "PATH_ORDER", "Assist", "AssistParams", "Assistance",
    "AutoModeParams", "AutomaticSwitch", "Goal", "GoalBelief", "GraspHelpParams", "LearntTolerance", "PathParams",
    "PathStep", "PressResponse", "Step", "SwitchContext", "Switchable", "assist_label", "assist_option",
    "candidate_goals", "held_cube", "load_assist", "motion_scores", "next_step_modes", "next_step_shares",
    "parse_assist", "path_order", "path_steps", "presses", "profile_assist", "revisit_scale", "rise_error",
    "step_errors", "step_of_move", "time_to_goal", "user_order", "yaw_offset",
]
