"""The recovery a session has when the task stops progressing (docs/task.md, "Recovery").

Off unless the operator file's ``[recovery]`` table names actions (``--recovery``); then, after
``stuck_s`` without progress (``tasks.stacking.failures.ProgressWatch``: what the person sees of the task),
the person acts on what they have seen of the arm since the last progress:

- the arm did not answer the stick moves asked for (less than ``obeyed_share`` of them): the
  interface is at fault: **rezero** (the person holds still ``settle_s``, the chain takes the neutral
  posture anew over the profile's neutral samples; the arm is stopped meanwhile);
- it answered them: the plan is at fault: **backoff** (lift the hand, plan afresh:
  ``ScriptedUser.back_off``);
- the interface at fault and a rezero made since the last progress did not help (or rezero is not
  on): the classifier itself no longer reads the body (a posture drifted from what it was trained
  on): **recalibrate** (the person performs a short calibration protocol while the arm is stopped,
  the chain's classifier is retrained on it: ``BomiChannel.begin_recalibration``); once per span
  without progress: a fresh classifier that did not help is not retrained again;
- a recovery made and still no progress ``stuck_s`` later: **pause** first (the arm stopped while
  the person rests ``pause_s``), then the fitting action again.

An action that is not on is skipped (pause stands in for a missing fix).  The task's clock runs on
through every recovery: its time counts in the completion time.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from sim.joystick import JoystickState
from tasks.operators.params import RecoveryParams
from tasks.stacking import failures, metrics
from tasks.stacking.vocabulary import Goal, RecoveryAction, RecoveryEvent, StickIntent, View

# the goal each stopped action logs (no task phase: it interrupts the phase it is in, metrics.task_phase)
_GOALS = {RecoveryAction.REZERO: Goal("re-zero the neutral"), RecoveryAction.PAUSE: Goal("pause"),
          RecoveryAction.RECALIBRATE: Goal("recalibrate")}


class Person(Protocol):
    """The person the supervisor stands in for while it acts (``ScriptedUser``, ``HumanOperator``)."""

    def stick_intent(self, view: View) -> StickIntent: ...

    def back_off(self, view: View) -> None: ...

    def resume(self, view: View) -> None: ...


class Rezeroable(Protocol):
    """A channel whose neutral posture can be taken anew and whose classifier retrained (``BomiChannel``)."""

    def begin_rezero(self) -> None: ...

    @property
    def rezeroing(self) -> bool: ...

    def begin_recalibration(self, t: float) -> None: ...

    @property
    def recalibrating(self) -> bool: ...


def choose(actions: frozenset[RecoveryAction], obeyed: float | None, obeyed_share: float,
           retry: bool, made: frozenset[RecoveryAction] = frozenset()) -> tuple[RecoveryAction, ...]:
    """The actions to take, in order, after a span without progress: ``obeyed``, the share of the
    stick moves asked for that the arm answered (None: none asked); ``retry``: a recovery was made
    in this span already; ``made``: the actions made since the last progress.  See the module docstring."""
    fix = RecoveryAction.BACKOFF if obeyed is None or obeyed >= obeyed_share else _interface_fix(actions, made)
    chosen = [a for a in (RecoveryAction.PAUSE,) if retry and a in actions] + [fix] * (fix in actions)
    return tuple(chosen or [a for a in (RecoveryAction.PAUSE,) if a in actions])


def _interface_fix(actions: frozenset[RecoveryAction], made: frozenset[RecoveryAction]) -> RecoveryAction | None:
    """The interface is at fault: rezero first; recalibrate when a rezero of this span did not help
    or rezero is not on; once recalibrated in the span, nothing more to fix (None)."""
    rezero, recalibrate = RecoveryAction.REZERO, RecoveryAction.RECALIBRATE
    if rezero in actions and not (recalibrate in actions and rezero in made):
        return rezero
    return None if recalibrate in made else recalibrate


@dataclass
class StuckClock:
    """How long the task has gone without progress (since the last progress, or the end of the last
    recovery), and how many of the stick moves asked in that time the arm answered: a move (a run of
    ticks pushing the same functions) is answered when the stick gives one of its functions at any
    time while it is held (a person judges whether the arm does what they ask, late or not)."""

    stuck_s: float
    since: float = 0.0
    asked: int = 0  # stick moves asked for
    answered: int = 0  # ... that the stick gave
    retry: bool = False  # a recovery has been made since the last progress
    made: frozenset[RecoveryAction] = frozenset()  # ... which actions
    _move: frozenset[str] = frozenset()  # the functions of the move held now
    _answered: bool = False  # ... and whether the stick has given one of them yet

    def progress(self, t: float) -> None:
        self._restart(t, retry=False)
        self.made = frozenset()

    def recovered(self, t: float) -> None:
        self._restart(t, retry=True)

    def _restart(self, t: float, retry: bool) -> None:
        """A new span: the move held now counts as one asked in it."""
        self.since, self.asked, self.answered, self.retry, self._move = t, 0, 0, retry, frozenset()

    def saw(self, intent: StickIntent, state: JoystickState) -> None:
        functions = intent.functions
        if functions != self._move:
            self._move, self._answered = functions, False
            self.asked += bool(functions)
        if functions and not self._answered and not functions.isdisjoint(state.deflection):
            self._answered = True
            self.answered += 1

    def due(self, t: float) -> bool:
        return t - self.since >= self.stuck_s - 1e-9

    @property
    def obeyed(self) -> float | None:
        return self.answered / self.asked if self.asked else None


class Supervisor:
    """Between the person and the channel in ``run_episode``: watches progress, decides and runs
    the recovery actions (``intent`` replaces ``user.stick_intent``, ``state`` the stick's state)."""

    def __init__(self, params: RecoveryParams, user: Person, channel: Rezeroable, target_pos: np.ndarray | None = None,
                 progress_m: float = failures.Rules().progress_m):
        """``target_pos``: location B on the table top (None: as the first view shows it)."""
        self.params, self.user, self.channel, self.target_pos = params, user, channel, target_pos
        self.watch, self.clock = failures.ProgressWatch(progress_m), StuckClock(params.stuck_s)
        self.phase: str | None = None  # the task phase (metrics.task_phase), carried over goals that interrupt it
        self.queue: list[RecoveryAction] = []
        self.obeyed: float | None = None  # what the person saw of the arm when the actions queued were chosen
        self.acting: tuple[RecoveryAction, float, bool] | None = None  # (action, since, the channel asked)
        self.events: list[RecoveryEvent] = []
        self.last_intent: StickIntent | None = None  # what ``intent`` gave last (what ``gate`` judges the stick by)

    def intent(self, view: View) -> StickIntent:
        self.last_intent = self._intent(view)
        return self.last_intent

    def gate(self, state: JoystickState) -> JoystickState:
        """``state`` for the intent given last (the loop's hook: ``tasks.stacking.wrappers.Recovering``)."""
        return self.state(self.last_intent, state)

    def _intent(self, view: View) -> StickIntent:
        if self.acting is None and not self.queue:
            intent = self.user.stick_intent(view)
            self._watch(view, intent)
            if not self.clock.due(view.t):
                return intent
            self.obeyed = self.clock.obeyed
            self.queue = list(choose(self.params.actions, self.obeyed, self.params.obeyed_share, self.clock.retry,
                                     self.clock.made))
            if not self.queue:
                self.clock.recovered(view.t)
                return intent
        return self._act(view)

    def state(self, intent: StickIntent, state: JoystickState) -> JoystickState:
        """The arm stays at rest while an action stops it; otherwise what the arm answered is seen."""
        if self.acting is not None:
            return JoystickState()
        self.clock.saw(intent, state)
        return state

    def _watch(self, view: View, intent: StickIntent) -> None:
        self.phase = metrics.task_phase(intent.goal.step) or self.phase
        if self.phase is None:
            return
        if self.target_pos is None:
            self.target_pos = np.r_[view.target_xy, view.table_z]
        rest_z = view.table_z + view.cube_size / 2
        distance = failures.phase_distance(self.phase, view.hand_pos, np.array(view.cube_pos), self.target_pos, rest_z)
        if self.watch.update(self.phase, distance):
            self.clock.progress(view.t)

    def _act(self, view: View) -> StickIntent:
        """Go on with the action under way, or start the next one queued; the person rests meanwhile."""
        if self.acting is None:
            action = self.queue.pop(0)
            if action is RecoveryAction.BACKOFF:  # at once: the lift is the user's own next move
                self.user.back_off(view)
                self._done(action, view.t, view)
                return self._intent(view)
            self.acting = (action, view.t, False)
        action, since, asked = self.acting
        if action is RecoveryAction.PAUSE and view.t - since >= self.params.pause_s - 1e-9:
            self._done(action, since, view)
        elif action is RecoveryAction.REZERO and not asked and view.t - since >= self.params.settle_s - 1e-9:
            self.channel.begin_rezero()
            self.acting = (action, since, True)
        elif action is RecoveryAction.REZERO and asked and not self.channel.rezeroing:
            self._done(action, since, view)
        elif action is RecoveryAction.RECALIBRATE and not asked:  # at once: the protocol's first run is neutral
            self.channel.begin_recalibration(view.t)
            self.acting = (action, since, True)
        elif action is RecoveryAction.RECALIBRATE and not self.channel.recalibrating:
            self._done(action, since, view)
        if self.acting is None:
            return self._intent(view)
        return StickIntent(goal=_GOALS[action])

    def _done(self, action: RecoveryAction, start: float, view: View) -> None:
        """An action is over; after the last one queued, the person takes the task up again."""
        self.events.append(RecoveryEvent(action, start, view.t, self.obeyed))
        self.clock.made |= {action}
        self.acting = None
        if not self.queue:
            self.clock.recovered(view.t)
            if action is not RecoveryAction.BACKOFF:
                self.user.resume(view)
