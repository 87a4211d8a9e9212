"""The trial session: N trials of the stacking task per controller, scored like simulated episodes.

One session per controller is one continuous control loop: for the BoMI the live loop itself
(``tasks.trials.live.run_live``: source -> parser -> chain -> safety -> stick), for the joystick a loop
paced the same way (``tasks.trials.live.paced_ticks``) that reads an input device. The loop drives a
``TrialArm``, which runs the trials one after the other on the simulated arm:

    WAIT (BoMI: until the live loop has taken the neutral posture) -> COUNTDOWN (the task at its
    start, cubes at A and hand at home, the arm held) -> RUN (the task reset once more, the stick
    reaches the arm; timed from the first command) -> the next trial's COUNTDOWN ... -> DONE

A trial ends at success, a cube off the table, or the time limit (counted from the go). Every
control tick is recorded (``TickRecorder``): what the source delivered (bytes and frames), the
decisions, the stick, the command and the arm's and cubes' state; each trial's ticks become an
``EpisodeLog`` scored by ``tasks.stacking.episode.summarize``, the benchmark's own record builder.

Clocks: with a person the loop runs on the wall clock; with a stand-in (``tasks.trials.standin``)
on a ``SimulatedClock`` whose sleep advances time at once, so a session runs as fast as the
simulation allows, tick times exact multiples of the control period.
"""
from __future__ import annotations

import enum
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from bomi.chain import Decision
from bomi.frames import SAMPLE_PERIOD_S, FrameParser, ImuFrame, SampleIndex, imu_node_id
from sim.env import ArmSim
from sim.joystick import BUTTONS, FUNCTIONS, ArmCommand, JoystickState, Mode
from tasks.stacking.record import DecisionTrace, EpisodeLog
from tasks.stacking.summary import summarize
from tasks.operators.recovery import RecoveryAction, RecoveryEvent
from tasks.stacking.env import Command, StackingEnv
from tasks.stacking.task import TaskConfig
from tasks.stacking.vocabulary import View

DEFAULT_TRIALS = 3
DEFAULT_COUNTDOWN_S = 3.0
DEFAULT_TIME_LIMIT_S = 600.0
READY_WITHIN_S = 120.0
UNKNOWN = -1  # an intended class nobody knows (a person, not a stand-in)


class Controller(str, enum.Enum):
    BOMI = "bomi"
    JOYSTICK = "joystick"


class Phase(enum.IntEnum):
    WAIT = 0       # the controller is not ready yet (BoMI: warm-up, neutral calibration)
    COUNTDOWN = 1  # the task at its start, the arm held
    RUN = 2        # the trial: the stick reaches the arm
    DONE = 3       # every trial is over


@dataclass(frozen=True)
class TrialPlan:
    """How many trials (numbered from ``first``), how long the countdown, the time limit (from the
    go), how long the controller may take to get ready, and the seed of the cube placement (the k-th
    trial of a controller uses ``seed + k - 1``: every controller meets the same placements)."""

    trials: int = DEFAULT_TRIALS
    countdown_s: float = DEFAULT_COUNTDOWN_S
    time_limit_s: float = DEFAULT_TIME_LIMIT_S
    seed: int = 0
    first: int = 1
    ready_within_s: float = READY_WITHIN_S  # a controller not ready by then (a signal that never settles) ends it

    @property
    def last(self) -> int:
        return self.first + self.trials - 1

    def task_seed(self, trial: int) -> int:
        return self.seed + trial - self.first


@dataclass
class TrialResult:
    """One trial's bounds (tick indices into the session) and outcome."""

    number: int
    task_seed: int
    go_tick: int
    end_tick: int = -1
    first_command_tick: int = -1
    first_command_s: float | None = None  # task time of the first command
    success: bool = False
    completion_time: float | None = None  # s from the first command to the stack standing still
    failure: str | None = None
    wall_time: float = 0.0
    cpu_time: float = 0.0


class TrialArm:
    """The simulated arm as the control loop sees it (``tasks.trials.live.Arm``), running the trials
    on the one loop (``tasks.stacking.env.StackingEnv``), reset at each trial's countdown and go.

    Only ticks in the RUN phase pass the stick to the arm; the countdown steps the task with a
    centred stick, and before the first countdown (WAIT: no task yet) the env in free mode (no
    task, no outcome: ``StackingEnv.reset(options={"task": False})``) holds the arm still.
    The countdown is counted in control ticks, so a replay of the same ticks runs the same trials.
    """

    def __init__(self, sim: ArmSim, plan: TrialPlan, ready: bool = False, last_trial: int | None = None):
        self.sim, self.plan = sim, plan
        self.env = StackingEnv(sim, config=TaskConfig(time_limit=plan.time_limit_s))
        self.task = self.env.task
        self._view: View = self.env.reset(options={"task": False})[1]["view"]  # what the last reset or step showed
        self.dt = sim.dt
        self.ticks = 0
        self.phase = Phase.WAIT
        self.trial = plan.first - 1  # the current trial's number
        self.results: list[TrialResult] = []
        self.rows: list[dict] = []  # per tick: the arm and the task before the step
        self._last = plan.last if last_trial is None else last_trial
        self._countdown_end = 0
        self._started = (0.0, 0.0)
        self.not_ready: str | None = None  # why the session ended before its first trial
        if ready:
            self.ready()

    @property
    def mode(self) -> Mode:
        return self.sim.mode

    @property
    def finished(self) -> bool:
        return self.phase is Phase.DONE

    def ready(self, *_) -> None:
        """The controller is ready (the neutral posture taken): the first countdown starts."""
        if self.phase is Phase.WAIT:
            self._count_down()

    def countdown_left(self) -> float:
        return max(0, self._countdown_end - self.ticks) * self.dt

    def _count_down(self) -> None:
        if self.trial >= self._last:
            self.phase = Phase.DONE
            return
        self.trial += 1
        self.phase = Phase.COUNTDOWN
        self._countdown_end = self.ticks + round(self.plan.countdown_s / self.dt)
        self._reset()

    def _go(self) -> None:
        self.phase = Phase.RUN
        self._reset()
        self.results.append(TrialResult(self.trial, self.plan.task_seed(self.trial), self.ticks))
        self._started = (time.perf_counter(), time.process_time())

    def _reset(self) -> None:
        self._view = self.env.reset(seed=self.plan.task_seed(self.trial))[1]["view"]

    def step(self, state: JoystickState) -> ArmCommand | Command:
        view = self._view
        self.rows.append({"trial": self.trial if self.phase in (Phase.COUNTDOWN, Phase.RUN) else 0,
                          "phase": int(self.phase), "task_t": view.t, "hand_pos": view.hand_pos,
                          "arm_qpos": self.sim.arm_qpos, "closure": view.closure, "mode": view.mode.value,
                          "cube_pos": np.array(view.cube_pos), "touching": np.array(view.touching, dtype=bool)})
        self.ticks += 1
        if self.phase is Phase.WAIT and self.ticks * self.dt > self.plan.ready_within_s:
            self.phase = Phase.DONE
            self.not_ready = (f"the controller was not ready within {self.plan.ready_within_s:g} s (the live loop "
                              f"never took the neutral posture: a node's signal did not settle)")
        if self.phase is Phase.WAIT or self.phase is Phase.DONE:  # no task under way: the arm holds still
            info = self.env.step(JoystickState())[-1]
            self._view = info["view"]
            return info["command"]
        if self.phase is Phase.COUNTDOWN:
            info = self.env.step(JoystickState())[-1]
            self._view = info["view"]
            if self.ticks >= self._countdown_end:
                self._go()  # the next tick starts the trial, the task at its start (as a person sees it)
            return info["command"]
        result = self.results[-1]
        if result.first_command_s is None and (any(state.deflection.values()) or state.pressed):
            result.first_command_s, result.first_command_tick = view.t, self.ticks - 1
        info = self.env.step(state)[-1]
        self._view, command, outcome = info["view"], info["command"], info["outcome"]
        if outcome.done:
            result.end_tick = self.ticks
            result.success, result.failure = outcome.success, outcome.failure
            if outcome.success:
                result.completion_time = outcome.completion_time - (result.first_command_s or 0.0)
            self.clock_out(result)
            self._count_down()
        return command

    def clock_out(self, result: TrialResult) -> None:
        """The trial's wall and CPU time, from its go to now (its end, or the tick a lost input cut it short)."""
        result.wall_time = time.perf_counter() - self._started[0]
        result.cpu_time = time.process_time() - self._started[1]

    def status(self) -> str:
        """The trial's part of the status line."""
        if self.phase is Phase.WAIT:
            return "waiting for the controller (hold still)"
        if self.phase is Phase.DONE:
            return "session over"
        head = f"trial {self.trial}/{self._last}"
        if self.phase is Phase.COUNTDOWN:
            return f"{head}: starts in {int(np.ceil(self.countdown_left()))}"
        result = self.results[-1]
        if result.first_command_s is None:
            return f"{head}: GO"
        return f"{head}: {self.task.view().t - result.first_command_s:5.1f} s"


@dataclass
class SimulatedClock:
    """Time that a sleep advances at once: a session runs as fast as the simulation allows."""

    now: float = 0.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += max(0.0, seconds)


class TappedParser(FrameParser):
    """A frame parser that keeps every byte it is fed and every IMU frame it gives, for the record
    (``take`` empties it)."""

    def __init__(self) -> None:
        super().__init__()
        self._fed: list[bytes] = []
        self._frames: list[ImuFrame] = []

    def feed(self, data: bytes, now: float | None = None) -> list[ImuFrame]:
        self._fed.append(bytes(data))
        frames = super().feed(data, now)
        self._frames += frames
        return frames

    def take(self) -> tuple[bytes, list[ImuFrame]]:
        data, frames = b"".join(self._fed), self._frames
        self._fed, self._frames = [], []
        return data, frames


class Watcher(Protocol):
    """Someone at the controls whose intent is known (a stand-in)."""

    def tick_truth(self) -> dict:
        """What they wanted at this tick (intended_dir, pushing, goal, stage)."""

    def intents(self, samples: np.ndarray) -> np.ndarray:
        """The class they performed at each sample index (from the packet counters)."""


@dataclass
class TickRecorder:
    """Every control tick of a session, as rows (``tasks.trials.dataset`` writes them as columns)."""

    arm: TrialArm
    parser: TappedParser | None = None  # the BoMI's stream (None: the joystick)
    watcher: Watcher | None = None
    node1: int | None = None  # the node id whose frames make the chain's decisions
    ticks: list[dict] = field(default_factory=list)
    frames: list[tuple] = field(default_factory=list)  # (tick, node id, period, counter, *mag, *gyro, *acc, sample)
    decisions: list[tuple] = field(default_factory=list)  # (tick, frame row, sample_index, label, confidence,
    #                                                        rejected, gamma, nu)
    chunks: list[bytes] = field(default_factory=list)
    neutral: dict[int, tuple[float, float, float]] | None = None
    _samples: SampleIndex = field(default_factory=SampleIndex)

    def record(self, t: float, state: JoystickState, command: ArmCommand, decisions: Sequence[Decision] = (),
               flags: dict | None = None) -> None:
        k = len(self.ticks)
        data, frames = self.parser.take() if self.parser is not None else (b"", [])
        node1_rows = []
        for frame in frames:
            if frame.node_id == self.node1:
                node1_rows.append(len(self.frames))
            self.frames.append((k, frame.node_id, frame.period_ms, frame.counter, *frame.mag, *frame.gyro,
                                *frame.acc, self._samples(frame)))
        # a decision is made by a node-1 frame: the tick's decisions are its last node-1 frames'
        made_by = node1_rows[len(node1_rows) - len(decisions):] if len(decisions) <= len(node1_rows) \
            else [-1] * len(decisions)
        for decision, row in zip(decisions, made_by):
            self.decisions.append((k, row, decision.sample_index, decision.label, decision.confidence,
                                   decision.rejected, decision.gamma, decision.nu))
        self.chunks.append(data)
        row = {"t": t, "stick": [state.deflection.get(f, 0.0) for f in FUNCTIONS],
               "pressed": [b in state.pressed for b in BUTTONS], "linear": command.linear.tolist(),
               "angular": command.angular.tolist(), "finger": float(command.finger),
               "frames": len(frames), **(flags or {})}
        row.update(self.watcher.tick_truth() if self.watcher is not None else {})
        self.ticks.append(row)

    def observe(self, tick) -> None:
        """``tasks.trials.live.run_live``'s observer: one live tick."""
        self.record(tick.t, tick.state, tick.command, tick.decisions,
                    {"stale": tick.stale, "standby": tick.standby, "calibrating": tick.calibrating,
                     "reconnected": tick.reconnected, "recalibrating": tick.recalibrating,
                     "recalibrated": tick.recalibrated or "",
                     "lost": tick.lost, "dropped": len(tick.dropped), "skipped": tick.skipped,
                     "hold": tick.hold or "", "loop_hz": tick.loop_hz, "overruns": tick.overruns})
        if tick.neutral is not None:
            self.neutral = dict(tick.neutral)

    def frame_intents(self) -> np.ndarray:
        """The class the stand-in performed at each recorded frame (UNKNOWN for a person)."""
        samples = np.array([f[-1] for f in self.frames], dtype=int)
        if self.watcher is None or not len(samples):
            return np.full(len(samples), UNKNOWN)
        return self.watcher.intents(samples)

    def decision_intents(self) -> np.ndarray:
        frames = self.frame_intents()
        rows = np.array([d[1] for d in self.decisions], dtype=int)
        return np.where(rows >= 0, frames[np.maximum(rows, 0)] if len(frames) else UNKNOWN, UNKNOWN)


def episode_log(recorder: TickRecorder, result: TrialResult, *, operator: str, participant: str, controls: str,
                class_names: tuple[str, ...] = (), neutral: int = 0, allowance: int = 0, amplitude: str = "gamma",
                sample_period: float = SAMPLE_PERIOD_S) -> EpisodeLog:
    """One trial of a recorded session as the episode log a simulated episode gives."""
    arm = recorder.arm
    span = range(result.go_tick, result.end_tick if result.end_tick >= 0 else len(arm.rows))
    rows = [arm.rows[k] for k in span]
    ticks = [recorder.ticks[k] for k in span]
    known = recorder.watcher is not None
    decisions = None
    if class_names:
        intents = recorder.decision_intents()
        picked = [k for k, d in enumerate(recorder.decisions) if d[0] in span]
        rows_d = [recorder.decisions[k] for k in picked]
        decisions = DecisionTrace(t=np.array([arm.rows[d[0]]["task_t"] for d in rows_d]),
                                  intended=intents[picked].astype(int) if picked else np.zeros(0, int),
                                  decided=np.array([d[3] for d in rows_d], dtype=int),
                                  gamma=np.array([d[6] for d in rows_d]), nu=np.array([d[7] for d in rows_d]))
    return EpisodeLog(
        operator=operator, participant=participant, seed=result.task_seed, controls=controls,
        t=np.array([r["task_t"] for r in rows]), hand_pos=np.array([r["hand_pos"] for r in rows]).reshape(-1, 3),
        intended_dir=np.array([t.get("intended_dir", (0.0, 0.0, 0.0)) for t in ticks]).reshape(-1, 3),
        mode=[r["mode"] for r in rows], presses=sum(sum(t["pressed"]) for t in ticks),
        cube_pos=np.array([r["cube_pos"] for r in rows]), touching=np.array([r["touching"] for r in rows], dtype=bool),
        target_pos=arm.task.target_pos.copy(), success=result.success, completion_time=result.completion_time,
        failure=result.failure, wall_time=result.wall_time, cpu_time=result.cpu_time,
        pushing=np.array([t.get("pushing", any(v > 0 for v in t["stick"])) for t in ticks], dtype=bool),
        decisions=decisions, class_names=class_names, neutral=neutral, allowance=allowance,
        sample_period=sample_period, amplitude=amplitude,
        goals=tuple(t.get("goal", "") for t in ticks) if known else (),
        stages=tuple(t.get("stage", "") for t in ticks) if known else (),
        recoveries=person_recoveries(ticks, [r["task_t"] for r in rows]))


def person_recoveries(ticks: Sequence[dict], task_t: Sequence[float]) -> tuple[RecoveryEvent, ...]:
    """The trial's recoveries the person asked for, as recovery events (task time from the first tick to
    the last, in order of their start): re-zeros, each run of ticks in which the live loop took the
    neutral posture anew while the arm was otherwise free (the person's gesture or the safety key's
    calibration event; a retake after a break in the stream, whose ticks are held, is the loop's
    safety, not a recovery), and recalibrations, each run of ticks its protocol held the arm."""
    runs = {RecoveryAction.REZERO: [bool(t.get("calibrating")) and not t.get("hold") for t in ticks],
            RecoveryAction.RECALIBRATE: [bool(t.get("recalibrating")) for t in ticks]}
    events = [RecoveryEvent(action, task_t[start], task_t[end - 1])
              for action, flags in runs.items() for start, end in _runs(flags)]
    return tuple(sorted(events, key=lambda event: event.start_s))


def _runs(flags: Sequence[bool]) -> list[tuple[int, int]]:
    """[start, end) of each run of True in ``flags``."""
    edges = np.diff(np.r_[0, np.asarray(flags, dtype=np.int8), 0])
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


# what a trial record cannot know when nobody knows what the person intended
INTENT_KEYS = ("unintended_displacement_mm", "accuracy_all_decisions", "accuracy_excused_transitions",
               "excused_share", "accuracy_vs_allowance", "misclassified", "longest_error_run_ms",
               "errors_to_neutral", "errors_to_other_class", "irrelevant_decisions", "irrelevant_runs",
               "irrelevant_per_min", "irrelevant_longest_run_ms", "latency_onsets_ms", "latency_ms_median",
               "latency_ms_p90", "latency_ms_max", "decisions_intended_active")


def trial_record(log: EpisodeLog, number: int, intent_known: bool) -> dict:
    """The benchmark's episode record (``summarize``) of one trial, with its number; the metrics that
    need the person's intent are null when it is not known (a person, not a stand-in)."""
    record = {"trial": number, **summarize(log)}
    if not intent_known:
        record.update({key: None for key in INTENT_KEYS if key in record})
    return record


def node1_id(chain) -> int:
    """The node id whose frames make the chain's decisions (its first node)."""
    return imu_node_id(chain.nodes[0])



# ---------------------------------------------------------------------------------- running
class StickDevice(Protocol):
    """Where the joystick condition's stick comes from (a gamepad, the viewer's keys, a stand-in)."""

    def read(self, now: float) -> JoystickState: ...

    def close(self) -> None: ...


@dataclass
class TrialDisplay:
    """The session's display: the trial's status before the loop's, each trial's go and end on one
    line, and running until the last trial is over."""

    inner: object  # tasks.trials.live.Display
    arm: TrialArm
    say: Callable[[str], None] = lambda line: None
    _seen: tuple[int, Phase] = (0, Phase.WAIT)

    def running(self) -> bool:
        return not self.arm.finished and self.inner.running()

    def sync(self, status: Callable[[], str]) -> None:
        now = (self.arm.trial, self.arm.phase)
        if now != self._seen:
            done = [r for r in self.arm.results if r.end_tick >= 0]
            if done and (self._seen[1] is Phase.RUN):
                last = done[-1]
                verdict = f"done in {last.completion_time:.2f} s" if last.success else f"failed: {last.failure}"
                self.say(f"trial {last.number}: {verdict}")
            if now[1] is Phase.RUN:
                self.say(f"trial {now[0]}: go")
            self._seen = now
        self.inner.sync(lambda: f"{self.arm.status()} | {status()}")

    def close(self) -> None:
        self.inner.close()


class TrialStatusLine:
    """The live loop's status line on the terminal, the trial's status before it."""

    def __init__(self, arm: TrialArm, line):
        self.arm, self.line = arm, line  # line: a tasks.trials.live.StatusLine

    def show(self, t: float, text: Callable[[], str]) -> None:
        self.line.show(t, lambda: f"{self.arm.status()} | {text()}")

    def close(self) -> None:
        self.line.close()


@dataclass
class Session:
    """One controller's trials: the loop, the arm running the trials and the record of every tick."""

    controller: Controller
    arm: TrialArm
    recorder: TickRecorder
    clock_kind: str  # "simulated" or "wall"
    stopped: str | None = None  # why the session stopped before its last trial ended

    @property
    def finished(self) -> list[TrialResult]:
        """The trials that ended (a trial cut short by a lost input is marked failed)."""
        return [r for r in self.arm.results if r.end_tick >= 0]

    def cut_short(self, why: str) -> None:
        """The input went away: the running trial ends here as a failure, timed to here."""
        if self.arm.phase is Phase.RUN and self.arm.results and self.arm.results[-1].end_tick < 0:
            result = self.arm.results[-1]
            result.end_tick, result.failure = len(self.recorder.ticks), why
            self.arm.clock_out(result)
        self.arm.phase, self.stopped = Phase.DONE, why


def run_bomi(session: Session, source, chain, *, display, on_tick: Callable[[object], None] | None = None,
             status=None, clock: Callable[[], float] = time.monotonic,
             sleep: Callable[[float], None] = time.sleep,
             assist: Callable[[JoystickState], JoystickState] | None = None) -> None:
    """The BoMI's trials through the live loop (``tasks.trials.live.run_live``: gate, chain, safety):
    ``source`` is a ``tasks.trials.live.Source`` whose parser is a ``TappedParser``; ``on_tick`` is told
    every tick after it is recorded (a stand-in watching the arm answer the tick's decisions); ``assist``:
    the live loop's (``tasks.trials.assisted.TrialAssistance``)."""
    from tasks.trials.live import run_live  # the live loop (imports the viewer's machinery)

    observers = [session.recorder.observe] + ([on_tick] if on_tick is not None else [])
    run_live(source, chain, session.arm, status=status, display=display, on_neutral=session.arm.ready,
             clock=clock, sleep=sleep, observers=observers, assist=assist)


def run_joystick(session: Session, device: StickDevice, *, display, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, on_tick: Callable[[float], None] | None = None,
                 assist: Callable[[JoystickState], JoystickState] | None = None) -> None:
    """The joystick's trials: every tick, the device's stick (through ``assist``, when given) to the arm,
    paced as the live loop is; ``on_tick`` is told the session's time after every tick (a progress bar)."""
    from tasks.trials.live import paced_ticks

    arm, start = session.arm, clock()
    for now, _ in paced_ticks(arm.dt, display, clock, sleep, start, None):
        state = device.read(now)  # logged as read: a replay gives it to the assistance again
        command = arm.step(assist(state) if assist is not None else state)
        session.recorder.record(now - start, state, command)
        if on_tick is not None:
            on_tick(now - start)
        speed = f"{100 * np.linalg.norm(command.linear):.1f} cm/s"
        display.sync(lambda: f"{now - start:6.1f} s | {arm.mode.value} | {speed}")
