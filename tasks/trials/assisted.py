"""The assistance of a trial session (``tasks.operators.assist``: automatic mode switching, grasp help)
between the controller's stick and the arm, as `bomi benchmark` applies it to an episode.

``TrialAssistance`` is the live loop's ``assist`` (``tasks.trials.live.LiveLoop``: not consulted
while the arm is held) and the joystick loop's: a fresh ``Assistance`` at each trial's go (each
benchmark episode starts one), consulted only while a trial runs, seeing what the person sees (the
task's view) and switching the arm's mode itself. Each trial's automatic switches are kept with
their tick counted from the trial's go, so that the trial's record scores them as an episode's.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from sim.joystick import JoystickState, Layout
from tasks.operators.assist import Assist, Assistance, AutomaticSwitch, assist_label
from tasks.trials.session import Phase, TrialArm


@dataclass(frozen=True)
class TrialAssisted:
    """What the assistance did in one trial (the episode log's ``assist``, ``automatic``, ``grasp_helps``)."""

    assist: str
    automatic: tuple[AutomaticSwitch, ...] = ()
    grasp_helps: int = 0


@dataclass
class TrialAssistance:
    """The chosen assistances on ``arm``'s trials (see the module docstring)."""

    options: frozenset[Assist]
    arm: TrialArm
    layout: Layout
    buttons: tuple[str, ...]
    _trials: dict[int, tuple[Assistance, list[int]]] = field(default_factory=dict, repr=False)

    @property
    def label(self) -> str:
        return assist_label(self.options)

    def __call__(self, state: JoystickState) -> JoystickState:
        arm = self.arm
        if not self.options or arm.phase is not Phase.RUN:
            return state  # no trial under way: the arm holds still or counts down
        if arm.trial not in self._trials:
            self._trials[arm.trial] = (Assistance(self.options, self.layout, self.buttons), [])
        assistance, ticks = self._trials[arm.trial]
        ticks.append(arm.ticks - arm.results[-1].go_tick)  # the trial's tick this step of the assistance is
        return assistance.step(arm.task.view(), state, arm.sim)

    def of_trial(self, number: int) -> TrialAssisted:
        """What the assistance did in trial ``number`` (nothing, when it was never consulted)."""
        if number not in self._trials:
            return TrialAssisted(self.label)
        assistance, ticks = self._trials[number]
        return TrialAssisted(self.label, tuple(replace(s, tick=ticks[s.tick]) for s in assistance.switches),
                             assistance.grasp_helps)
