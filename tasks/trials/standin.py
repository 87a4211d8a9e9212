"""The stand-in: a virtual participant at the controls of a trial, where a person would sit.

It watches the simulated arm as a person does (the scripted user of ``tasks.operators.planner``, or the
human operator model the operator file names: a ``tasks.stacking.sources.Operator``): holds
still while the controller gets ready and through the countdown, then does the task.

- BoMI: its body moves as ``tasks.stacking.channels.BomiChannel`` moves a virtual participant's, and the
  base-station bytes it sends go through the same live path a person's stream does
  (``StandInSource``: bytes -> parser -> chain -> safety -> stick -> arm, in ``tasks.trials.live.run_live``);
  it sees the arm answer the decisions the live loop acted on (``heard``).
- Joystick: the person's intent straight to the stick (``tasks.stacking.channels.JoystickChannel``).

``seed`` draws the BoMI stand-in's body and noise (one body for the session); the scripted user of
trial k is that of a simulated episode with the trial's cube-placement seed (its human model's
draws too, when the operator file names one), so a joystick stand-in's trial is that episode.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from bomi.chain import Decision, OnlineChain
from bomi.frames import ImuFrame
from bomi.profiles import Profile
from sim.joystick import JoystickState
from tasks.stacking.channels import BomiChannel, JoystickChannel, OperatorChannel
from tasks.stacking.episode import intended_direction
from tasks.stacking.sources import Operator, operator_user
from tasks.participants.params import recorded_day
from tasks.participants.participant import ParticipantParams, VirtualParticipant
from tasks.operators.params import OperatorParams
from tasks.stacking.vocabulary import REST, StickIntent
from tasks.trials.session import Phase, TappedParser, TrialArm

IDLE = {"intended_dir": (0.0, 0.0, 0.0), "pushing": False, "goal": "", "stage": ""}


class StandIn:
    """What both stand-ins share: the person looking at the arm at the start of each tick."""

    def __init__(self, arm: TrialArm, channel: OperatorChannel, operator: OperatorParams):
        self.arm, self.channel, self.operator = arm, channel, operator
        self._person: Operator | None = None
        self._trial = 0
        self._truth = dict(IDLE)

    def look(self) -> tuple[StickIntent, float, np.ndarray | None, object] | None:
        """(intent, task time, hand velocity seen as a fraction of full speed, arm mode) while a
        trial runs; None otherwise (the person rests)."""
        arm = self.arm
        if arm.phase is not Phase.RUN:
            self._person, self._truth = None, dict(IDLE)
            return None
        if self._person is None or self._trial != arm.trial:  # a new trial: the person starts afresh, with
            # the human model's draws (if any) of a simulated episode of the trial's seed
            self._person = Operator(operator_user(self.operator, self.channel, arm.plan.task_seed(arm.trial)),
                                    self.channel)
            self._trial = arm.trial
        view = arm.task.view()
        intent, seen = self._person.look({"view": view, **arm.env.scales})  # what the loop's info gives a person
        self._truth = {"intended_dir": intended_direction(view.mode, intent, arm.sim.layout),
                       "pushing": bool(intent.deflection), "goal": intent.goal.step,
                       "stage": "" if intent.goal.phase is None else intent.goal.phase.value}
        return intent, view.t, seen, view.mode

    def tick_truth(self) -> dict:
        return self._truth


def trained_on_its_recording(params: ParticipantParams, chain: OnlineChain) -> bool:
    """The chain's model was trained on runs of the twin's own source recordings (their digests meet):
    the twin is then the person of that recording's day, moving within the amplitudes the model learnt
    (issue 53.4), not a person of another day drawn from its drift."""
    protocol = params.protocol
    return protocol is not None and not set(protocol.run_digests).isdisjoint(chain.model.training_runs)


class BomiStandIn(StandIn):
    """A virtual participant sending base-station frames; the live loop's chain decides."""

    def __init__(self, arm: TrialArm, params: ParticipantParams, profile: Profile, chain: OnlineChain,
                 operator: OperatorParams, seed: int):
        if trained_on_its_recording(params, chain):
            params = recorded_day(params)
        participant = VirtualParticipant(params, profile, seed)
        super().__init__(arm, BomiChannel(participant, chain, profile, calibrate=False), operator)
        self.participant = participant

    def bytes_until(self, now: float) -> bytes:
        """Look at the arm, take up the posture for what is wanted, and send what arrives by ``now``
        (stream time: the participant's clock starts with the stream)."""
        seen = self.look()
        if seen is None:
            self.channel.perform(REST, now)
        else:
            intent, _, velocity, mode = seen
            self.channel.perform(intent, now, velocity, mode)
        return self.channel.arrived(now, now)

    def heard(self, decisions: Sequence[Decision]) -> None:
        """The decisions the live loop acted on this tick: what the person sees the arm answer."""
        self.channel.answered(list(decisions))

    def intents(self, samples: np.ndarray) -> np.ndarray:
        intent = self.participant.truth().intent
        return intent[np.clip(samples, 0, len(intent) - 1)].astype(int)

    @property
    def allowance(self) -> int:
        return self.channel.transition_samples


class JoystickStandIn(StandIn):
    """The scripted user's intent straight to the stick (a ``session.StickDevice``)."""

    def __init__(self, arm: TrialArm, operator: OperatorParams):
        super().__init__(arm, JoystickChannel(), operator)

    def read(self, now: float) -> JoystickState:
        seen = self.look()
        if seen is None:
            return JoystickState()
        intent, t, velocity, mode = seen
        return self.channel.command(intent, t, t + self.arm.dt, velocity, mode)

    def intents(self, samples: np.ndarray) -> np.ndarray:
        return np.zeros(len(samples), dtype=int)

    def close(self) -> None:
        """Nothing to release."""


class StandInSource:
    """The stand-in's bytes as a live source gives them (a ``tasks.trials.live.Source``), on the session's
    clock: each poll, the stand-in looks at the arm and sends what has arrived by now."""

    error = None  # a stand-in never goes away
    reconnections = 0

    def __init__(self, standin: BomiStandIn, clock: Callable[[], float]):
        self.standin, self.clock, self.parser = standin, clock, TappedParser()
        self._seen_events = 0

    def poll(self) -> tuple[list[ImuFrame], list]:
        now = self.clock()
        frames = self.parser.feed(self.standin.bytes_until(now), now)
        events = self.parser.safety_events[self._seen_events:]
        self._seen_events += len(events)
        return frames, events
