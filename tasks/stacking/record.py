"""What an episode records (``EpisodeLog``, with the BoMI's ``DecisionTrace``): every tick's hand,
cubes, mode and the person's intent, and the outcome.  Metrics and figures are computed from it
(``summary``, ``failures``, ``timeline``); a trial of a session is recorded the same way."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bomi.frames import SAMPLE_PERIOD_S
from tasks.operators.assist import NONE, AutomaticSwitch
from tasks.stacking.vocabulary import NO_RECOVERY, RecoveryEvent


@dataclass
class DecisionTrace:
    """One entry per classifier decision."""

    t: np.ndarray
    intended: np.ndarray  # class label the participant was performing
    decided: np.ndarray  # class label the chain output
    gamma: np.ndarray
    nu: np.ndarray
    lean: np.ndarray | None = None  # the participant's intended lean (0-1 of their range; 0 at neutral)
    body_deg: np.ndarray | None = None  # the body's true angle from the neutral the chain calibrated (deg)


@dataclass
class EpisodeLog:
    """Everything an episode records; metrics and figures are computed from it."""

    operator: str
    participant: str
    seed: int
    controls: str  # the layout and buttons the operator had (Controls.label)
    t: np.ndarray  # (N,) control ticks
    hand_pos: np.ndarray  # (N, 3)
    intended_dir: np.ndarray  # (N, 3) unit direction the person wanted, zero when resting
    mode: list[str]
    presses: int
    cube_pos: np.ndarray  # (N, K, 3)
    touching: np.ndarray  # (N, K)
    target_pos: np.ndarray  # (3,) B on the table top
    success: bool
    completion_time: float | None
    failure: str | None
    wall_time: float
    cpu_time: float  # this process's CPU seconds: the speed on one core, whatever else runs
    pushing: np.ndarray | None = None  # (N,) the person held a stick function (not a button, not at rest)
    decisions: DecisionTrace | None = None
    class_names: tuple[str, ...] = ()
    neutral: int = 0
    allowance: int = 0  # decisions after an intent change that belong to the transition
    sample_period: float = SAMPLE_PERIOD_S
    amplitude: str = "gamma"  # what the decisions' amplitude is: the profile's [proportional] amplitude
    goals: tuple[str, ...] = ()  # per control tick: the scripted user's step (planner Goal.step, plain words)
    stages: tuple[str, ...] = ()  # per control tick: the stage of the step's approach (planner Phase value, or "")
    assist: str = NONE  # the assistances on (tasks.operators.assist.assist_label)
    automatic: tuple[AutomaticSwitch, ...] = ()  # the mode switches the assistance made
    grasp_helps: int = 0  # closes the grasp help started
    commanded: np.ndarray | None = None  # (N, 3) hand velocity the stick commanded the arm (m/s, world)
    recovery: str = NO_RECOVERY  # the recovery actions on (RecoveryParams.label)
    recoveries: tuple[RecoveryEvent, ...] = ()  # the recovery actions taken (tasks.operators.recovery)

