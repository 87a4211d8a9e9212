"""What one user's presses teach the assistance: their tolerances per path step, how soon they press,
and what was judged when they had a mode."""
from __future__ import annotations

from dataclasses import dataclass, field

from tasks.operators.assist.path import PathStep


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
