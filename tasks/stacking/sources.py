"""Who holds the stick: one small interface (``ActionSource``, robosuite's Device idea) for every
source of a tick's ``JoystickState``, so that the one loop (``env.StackingEnv``) does not care.

- ``Operator``: a person at the controls of a channel: the scripted user (``planner.ScriptedUser``)
  or the human model around it (``human.HumanOperator``), its intent reaching the stick straight
  (``channels.JoystickChannel``) or through a virtual participant's body and the BoMI chain
  (``channels.BomiChannel``), optionally with the recovery supervisor standing in for the person;
  ``joystick_user`` and ``bomi_user`` build one by name.
- elsewhere: a gamepad, the viewer's keys and a logged stick (``tasks.trials.devices``,
  ``tasks.trials.replay.LoggedStick``: ``DeviceSource``), and the live person (stream -> gate ->
  chain -> stick: ``tasks.trials.person.LivePerson``, held at rest by ``SafetyHold``).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from sim.joystick import JoystickState, Layout
from tasks.operators.human import HumanOperator, load_human
from tasks.operators.params import DEFAULT_OPERATOR_FILE, NO_HUMAN_MODEL, OperatorParams, load_operator
from tasks.operators.judgement import Memory, wrapped_angle
from tasks.operators.planner import ScriptedUser
from tasks.operators.recovery import Supervisor
from tasks.stacking.channels import JoystickChannel, OperatorChannel, calibrated_channel, participant_controls
from tasks.stacking.vocabulary import StickIntent, View


class ActionSource(Protocol):
    """A source of the stick: given what the loop's last reset or step told (its ``info``: the
    ``View`` the person sees, the control period ``dt``, the hand's ``full_speed``), the stick for
    the next control tick."""

    def act(self, info: Mapping[str, Any]) -> JoystickState: ...


def operator_user(params: OperatorParams, channel: OperatorChannel, seed: int) -> ScriptedUser | HumanOperator:
    """The person at the controls: the scripted user, inside the human operator model when the
    operator file names one (``[human] model``)."""
    if params.human_model == NO_HUMAN_MODEL:
        return ScriptedUser(params, combine_axes=channel.combine_axes, memory=Memory(controls=channel.controls))
    return HumanOperator(load_human(params.human_model), params, channel.combine_axes, channel.controls, seed,
                         channel.body_reaction)


class Operator:
    """A person (``user``) at the controls of ``channel``: each tick they look (the info's view),
    want a stick (``intent``, kept for the record) and the channel makes it the stick.  With a
    ``supervisor`` (``tasks.operators.recovery``) the person's intent comes through it (its stick
    gate is a wrapper of the loop: ``wrappers.Recovering``)."""

    def __init__(self, user: ScriptedUser | HumanOperator, channel: OperatorChannel,
                 supervisor: Supervisor | None = None):
        self.user, self.channel, self.supervisor = user, channel, supervisor
        self.intent: StickIntent | None = None  # the intent of the last tick acted on
        self._previous: View | None = None  # what was seen at the last look

    @property
    def layout(self) -> Layout:
        """The joystick layout the person's controls have (the env's arm must have it too)."""
        return self.channel.controls.layout

    def look(self, info: Mapping[str, Any]) -> tuple[StickIntent, np.ndarray | None]:
        """What the person wants now and what they saw the hand do since their last look (None at the
        first look): ``seen_velocity``."""
        view = info["view"]
        intent = self.user.stick_intent(view) if self.supervisor is None else self.supervisor.intent(view)
        seen = None if self._previous is None else seen_velocity(self._previous, view, info)
        self._previous = view
        self.intent = intent
        return intent, seen

    def act(self, info: Mapping[str, Any]) -> JoystickState:
        intent, seen = self.look(info)
        view = info["view"]
        return self.channel.command(intent, view.t, view.t + info["dt"], seen, view.mode)


def seen_velocity(before: View, now: View, info: Mapping[str, Any]) -> np.ndarray:
    """(6,): the hand's velocity between two looks a control tick (``info["dt"]``) apart, as a fraction
    of the arm's top speeds: its move (3, of ``full_speed``), then its turn (3, of ``wrist_speed``; about
    the vertical only: the hand's heading is what the person sees of its turns)."""
    move = (now.hand_pos - before.hand_pos) / (info["dt"] * info["full_speed"])
    turn = wrapped_angle(now.hand_yaw - before.hand_yaw, 2 * math.pi) / (info["dt"] * info["wrist_speed"])
    return np.concatenate([move, [0.0, 0.0, turn]])


def operator_at(channel: OperatorChannel, seed: int, operator_file: Path | str | OperatorParams = DEFAULT_OPERATOR_FILE
             ) -> Operator:
    """The person of ``operator_file`` (the scripted user's parameters, or the file they are read
    from) at ``channel``; with the file's recovery on, supervised."""
    params = operator_file if isinstance(operator_file, OperatorParams) else load_operator(operator_file)
    user = operator_user(params, channel, seed)
    supervisor = Supervisor(params.recovery, user, channel) if params.recovery.actions else None
    return Operator(user, channel, supervisor)


def joystick_user(participant: str | None = None, seed: int = 0,
                  operator_file: Path | str | OperatorParams = DEFAULT_OPERATOR_FILE) -> Operator:
    """The scripted user on a JACO stick: a 3-axis stick with both buttons, or (``participant``) the
    layout and buttons that participant's BoMI profile gives (the like-for-like baseline)."""
    channel = JoystickChannel() if participant is None else JoystickChannel(participant_controls(participant))
    return operator_at(channel, seed, operator_file)


def bomi_user(participant: str, seed: int = 0,
              operator_file: Path | str | OperatorParams = DEFAULT_OPERATOR_FILE) -> Operator:
    """A virtual participant (``P1`` ...) through the BoMI chain: their twin performs the calibration
    protocol, the LDA is trained with the ``bomi train`` code, and the scripted user drives the arm
    through their body (``channels.calibrated_channel``; ``seed`` draws body, noise and the human
    model's timing)."""
    return operator_at(calibrated_channel(participant, seed), seed, operator_file)


class Device(Protocol):
    """An input device (``tasks.trials.session.StickDevice``): its stick at time ``now``."""

    def read(self, now: float) -> JoystickState: ...


class DeviceSource:
    """A device as an ``ActionSource``: read at the task time of the view (a logged stick ignores it)."""

    def __init__(self, device: Device):
        self.device = device

    def act(self, info: Mapping[str, Any]) -> JoystickState:
        return self.device.read(info["view"].t)
