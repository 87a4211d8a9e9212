"""Episode jobs: everything an episode depends on, run one at a time or many on an engine."""
from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tqdm import tqdm

from tasks.operators.assist import Assist, assist_label, profile_assist
from tasks.operators.params import DEFAULT_OPERATOR_FILE, load_operator
from tasks.operators.stick import arm_profile
from tasks.participants.participant import load_participant
from tasks.stacking.channels import JoystickChannel, calibrated_channel, participant_controls, profile_controls
from tasks.stacking.episode import run_episode
from tasks.stacking.summary import summarize
from tasks.stacking.task import TaskConfig

if TYPE_CHECKING:
    from tasks.experiments.engine import Engine

# Majority vote over this many decisions on the simulated BoMI (the profiles ship with it off):
# it removes the one- and two-decision blips that would otherwise press B1/B2 by mistake.
DEFAULT_VOTE = 5

RECOVERY_KEY = "operator.recovery.actions"  # the override --recovery sets (a grid may vary it too)
HUMAN_MODEL_KEY = "operator.human.model"     # the override that puts a human model around the scripted user
HUMAN_ON = ((HUMAN_MODEL_KEY, "human"),)     # ... the shipped one (tasks/operators/human.toml)


def with_recovery(job: EpisodeJob, recovery: str | None) -> EpisodeJob:
    """``job`` with the recovery actions ``recovery`` (None: as the operator file says)."""
    return job if recovery is None else replace(job, overrides=(*job.overrides, (RECOVERY_KEY, recovery)))


# The configuration files an episode reads, each of which a job may edit (``EpisodeJob.overrides``).
EDITABLE_FILES = ("profile", "participant", "operator")
JOYSTICK_ANYONE = "any"  # the participant column of a joystick row: the stick needs no body


@dataclass(frozen=True)
class EpisodeJob:
    """Everything an episode depends on.  ``overrides``: ``(file.dotted.key, value)`` pairs that
    edit the profile, participant or operator file before it is read (``("profile.post_processing.
    rejection_threshold", 0.99)``); the majority vote is ``vote_length``, never a profile override."""

    operator: str
    participant: str
    seed: int
    time_limit: float = 600.0
    operator_file: str = str(DEFAULT_OPERATOR_FILE)
    vote_length: int = DEFAULT_VOTE
    overrides: tuple[tuple[str, Any], ...] = ()
    assist: frozenset[Assist] | None = None  # None: as the profile says (BoMI), none (joystick)

    def __str__(self) -> str:
        edits = "".join(f", {key}={value!r}" for key, value in self.overrides)
        vote = f", vote {self.vote_length}" if self.operator != "joystick" else ""
        assist = f", assist {assist_label(self.assist)}" if self.assist is not None else ""
        return f"episode {self.participant} {self.operator} seed {self.seed}{vote}{assist}{edits}"

    def edits(self, file: str) -> dict[str, Any]:
        """The overrides of one of EDITABLE_FILES, keyed relative to that file."""
        prefix = file + "."
        return {key[len(prefix):]: value for key, value in self.overrides if key.startswith(prefix)}


def run_job(job: EpisodeJob, video: Path | None = None, video_speedup: float = 4.0, progress: bool = False):
    """One episode (calibration first for the BoMI); returns its log (and films it if ``video``).
    With ``progress``, a bar on stderr for each stage: the calibration, then the episode."""
    what = f"{job.participant} {job.operator} seed {job.seed}"
    params = load_participant(job.participant, job.edits("participant"))
    profile = arm_profile(params.profile, job.edits("profile"))
    assist = job_assist(job, profile)
    if job.operator == "joystick":  # on the controls the participant's profile gives (like for like)
        channel = JoystickChannel(profile_controls(profile))
    else:
        with stage(f"{what}: calibration (the participant performs the protocol, the LDA is trained)", progress):
            channel = calibrated_channel(params, job.seed, replace(profile.post, vote_length=job.vote_length),
                                         profile)
    filming = f", filming at {video_speedup:g}x" if video is not None else ""
    with simulated_time(f"{what}: episode{filming}", progress) as on_tick:
        return run_episode(channel, operator=job.operator, participant=job.participant, seed=job.seed,
                           operator_file=load_operator(job.operator_file, job.edits("operator")),
                           task_config=TaskConfig(time_limit=job.time_limit), video=video,
                           video_speedup=video_speedup, on_tick=on_tick, assist=assist)


def job_assist(job: EpisodeJob, profile) -> frozenset[Assist]:
    """The assistances of a job: as the run says, else as the participant's profile says (the
    joystick operator: none, unless the profile's controls have no mode button to press)."""
    if job.assist is not None:
        return job.assist
    return frozenset() if job.operator == "joystick" and profile_controls(profile).buttons else profile_assist(profile)


@contextmanager
def stage(what: str, progress: bool) -> Iterator[None]:
    """A one-step bar: shown when the stage starts, complete (with its duration) when it ends."""
    with tqdm(total=1, desc=what, file=sys.stderr, disable=not progress, bar_format="{desc}: {elapsed}") as bar:
        yield
        bar.update(1)


@contextmanager
def simulated_time(what: str, progress: bool) -> Iterator:
    """A bar counting simulated seconds (an episode's length is not known in advance)."""
    with tqdm(desc=what, file=sys.stderr, disable=not progress, unit="s", mininterval=0.5,
              bar_format="{desc}: {n:.0f} s simulated in {elapsed} ({rate_noinv_fmt})") as bar:
        yield (lambda t: bar.update(t - bar.n)) if progress else None  # no bar: no call a tick


def episode_record(job: EpisodeJob) -> dict:
    """The per-episode metrics of one job (what the engines run)."""
    return summarize(run_job(job))


def run_many(jobs: list[EpisodeJob], engine: Engine) -> list[dict]:
    """Episodes on ``engine``, with a progress bar; results in job order."""
    results = dict(tqdm(engine.run(episode_record, jobs), total=len(jobs), desc="episodes", unit="ep"))
    return [results[i] for i in range(len(jobs))]


def benchmark_jobs(participants: list[str], operators: list[str], seeds: int, time_limit: float,
                   operator_file: str, vote_length: int = DEFAULT_VOTE, first_seed: int = 0,
                   assist: frozenset[Assist] | None = None) -> list[EpisodeJob]:
    """Every (participant, operator, seed) for ``seeds`` seeds from ``first_seed``.  The joystick
    needs no body: it is run once per distinct set of controls (layout and buttons) among the
    participants' profiles, so each BoMI row has a joystick row with the same controls and no
    joystick row is repeated under several names."""
    seen: set[str] = set()
    jobs = []
    for p in participants:
        for op in operators:
            if op == "joystick":
                label = participant_controls(p).label
                if label in seen:
                    continue
                seen.add(label)
            jobs += [EpisodeJob(op, p, s, time_limit, operator_file, vote_length, assist=assist)
                     for s in range(first_seed, first_seed + seeds)]
    return jobs


