"""`bomi trial`'s bookkeeping: the session directory's lock, the trials still to run, every finished
trial written as it finishes (``Committer``), the trials scored, and a virtual participant's
prediction of them. What the session says goes to stderr as ``trial: ...``."""
from __future__ import annotations

import fcntl
import json
import os
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from bomi.errors import BomiError
from bomi.model_io import save_model
from bomi.profiles import save_profile
from sim.joystick import BUTTONS
from tasks.experiments.jobs import EpisodeJob, run_job
from tasks.operators.assist import Assist, profile_assist
from tasks.stacking.vocabulary import Controls
from tasks.operators.stick import profile_layout
from tasks.stacking.summary import summarize
from tasks.trials.dataset import file_sha256, replace_atomically, sync_directory, write_session
from tasks.trials.session import Controller, Session, TrialPlan, episode_log, trial_record

LOCK_FILE = ".lock"               # held (flock) by the one bomi trial writing to the directory


def say(line: str) -> None:
    print(f"trial: {line}", file=sys.stderr, flush=True)



def lock_session(out: Path) -> int:
    """The directory's lock (flock on DIR/.lock), held until the process ends; refused if another holds it."""
    out.mkdir(exist_ok=True)
    fd = os.open(out / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise BomiError(f"{out}: another bomi trial is writing to this directory (it holds {out / LOCK_FILE})") from None
    return fd



def remaining_plans(controllers: list[Controller], trials: int, countdown: float, time_limit: float, seed: int,
                    done: int) -> list[tuple[Controller, TrialPlan]]:
    """Each controller's trials still to run after the first ``done`` trials of the session (numbered from 1
    in session order; the k-th trial of a controller keeps the cube placement of seed + k - 1)."""
    out = []
    for k, controller in enumerate(controllers):
        first = 1 + k * trials
        start = max(first, done + 1)
        if start <= first + trials - 1:
            out.append((controller, TrialPlan(first + trials - start, countdown, time_limit, seed + start - first,
                                              start)))
    return out


@dataclass
class Committer:
    """Every trial written as it finishes: the session files (HDF5), the model and profile (once: their
    SHA-256 goes into each BoMI trial's record), then the records (trials.jsonl) last, each replaced atomically (``tasks.trials.dataset.replace_atomically``),
    so a kill at any instant leaves every finished trial whole. Under --force the session is written
    to a staging directory inside DIR until its first trial has finished; the earlier session is then
    moved aside (DIR.old-TIME) and the new one into DIR."""

    final: Path                      # --out
    target: Path                     # where the files go now (a staging directory, or --out)
    sessions: list
    profile: object
    model: object
    intent_known: bool
    previous: list[dict] = field(default_factory=list)   # the records of a resumed session
    committed: int = 0
    failed: bool = False
    aside: Path | None = None
    digests: dict[str, str] = field(default_factory=dict)  # model_sha256, profile_sha256 of the files written

    def finished(self) -> int:
        return sum(len(session.finished) for session, _ in self.sessions)

    def after_tick(self, *_) -> None:
        if self.finished() > self.committed:
            self.commit()

    def commit(self) -> tuple[list[dict], dict]:
        """Write what has finished; the records and episode logs of this run's trials."""
        records, logs = score(self.sessions, self.intent_known)
        if self.failed or self.finished() == self.committed:
            return self._stamped(records), logs
        try:
            if self.model is not None and any(s.controller is Controller.BOMI for s, _ in self.sessions):
                for name, save in (("model.json", save_model), ("profile.toml", save_profile)):
                    what, path = self.model if name == "model.json" else self.profile, self.target / name
                    if not path.exists():  # written once: a resumed session keeps its own files byte for byte
                        replace_atomically(path, lambda partial: save(partial, what))
                    self.digests[f"{name.split('.')[0]}_sha256"] = file_sha256(path)
            records = self._stamped(records)
            for session, meta in self.sessions:
                if session.finished:
                    write_session(self.target / meta["file"], session, meta["attrs"])
            lines = "".join(json.dumps(record) + "\n" for record in self.previous + records)
            replace_atomically(self.target / "trials.jsonl", lambda partial: partial.write_text(lines, "utf-8"))
        except (BomiError, OSError) as exc:
            self.failed = True
            why = str(exc) if isinstance(exc, BomiError) else f"{exc.filename}: {exc.strerror}"
            kept = f"trials up to {self.committed} kept" if self.committed else "no trial had finished"
            raise BomiError(f"{why}; the session stops, {kept}") from None
        self.committed = self.finished()
        if self.target != self.final:
            self._swap()
        return records, logs

    def _stamped(self, records: list[dict]) -> list[dict]:
        """The BoMI trials' records with the SHA-256 of the model and profile files they ran with
        (`bomi replay` refuses other files)."""
        return [{**record, **self.digests} if record["operator"] == Controller.BOMI.value else record
                for record in records]

    def _swap(self) -> None:
        self.aside = self.final.with_name(f"{self.final.name}.old-{time.strftime('%Y%m%d-%H%M%S')}")
        self.aside.mkdir()
        for entry in list(self.final.iterdir()):
            if entry.name != LOCK_FILE and entry != self.target:
                entry.rename(self.aside / entry.name)
        for entry in list(self.target.iterdir()):
            entry.rename(self.final / entry.name)
        self.target.rmdir()
        self.target = self.final
        sync_directory(self.final)
        sync_directory(self.final.parent)
        say(f"the earlier session in {self.final} is now in {self.aside}")



def score(sessions: list[tuple[Session, dict]], intent_known: bool) -> tuple[list[dict], dict]:
    """Every finished trial's record (trials.jsonl) and episode log (the figures), with what the
    session's assistance (``meta["assistance"]``, a ``tasks.trials.assisted.TrialAssistance``) did in it."""
    records, logs = [], {}
    for session, meta in sessions:
        assistance = meta.get("assistance")
        for result in session.finished:
            log = episode_log(session.recorder, result, **meta["log"])
            if assistance is not None:
                log = replace(log, **vars(assistance.of_trial(result.number)))
            logs[result.number] = log
            records.append(trial_record(log, result.number, intent_known))
    return records, logs



def session_assist(controller: Controller, chosen: frozenset[Assist] | None, profile) -> frozenset[Assist]:
    """A controller's assistances, as `bomi benchmark` chooses an episode's (``jobs.job_assist``): the
    ``--assist`` given, else the profile's ``[assist] options`` for the BoMI and none for the joystick
    (the JACO's joystick has its mode buttons)."""
    if chosen is not None:
        return chosen
    return profile_assist(profile) if controller is Controller.BOMI else frozenset()


def controls_label(profile) -> str:
    """The layout and buttons a profile's classes give (``tasks.operators.planner.Controls.label``)."""
    functions = {cls.function for cls in profile.classes}
    buttons = tuple(b for b in BUTTONS if b in functions)
    return Controls(profile_layout(profile), buttons).label if buttons else profile_layout(profile).name



def predictions(controllers: list[Controller], trials: int, participant: str, seed: int,
                time_limit: float) -> list[tuple[dict, object]]:
    """The named virtual participant's simulated episodes (``bomi benchmark``'s), one per trial, on
    the trials' cube placements: (record, episode log) each."""
    out = []
    for controller in controllers:
        for k in range(trials):
            log = run_job(EpisodeJob(controller.value, participant, seed + k, time_limit), progress=True)
            out.append((summarize(log), log))
    return out
