"""Live back from another sitting (issue 40's bar): the numbers of the scenario that
tests/test_live_breaks.py asserts, printed.

    python benchmarks/live_another_sitting.py

The virtual P1 facing -40 deg (a model trained on its seed-1 calibration), neutral taken, then F;
the stream silent for 2 s; then back from another sitting facing +50 deg, its counters from 0,
through ``LiveLoop.tick`` on an injected clock (the loop of `bomi live` and `bomi trial`). Prints
when the new neutral holds, how many ticks moved the arm before it, the offsets' change, and
whether the second sitting's neutral and F are obeyed after it.
"""
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
from bomi.chain import OnlineChain, train
from bomi.classifier import NEUTRAL_LABEL
from bomi.frames import FrameParser
from bomi.model_io import load_model, save_model
from bomi.profiles import load_profile
from bomi.protocol import Cue
from tasks.trials.live import LiveLoop
from tasks.participants.participant import calibration_session, load_participant, session_recording
from test_live_breaks import TICK, sitting_ticks
from test_live import StickArm
params, profile = load_participant("P1"), load_profile("P1")
session = calibration_session(params, profile, 1, repetitions=1, hold_s=2.0, neutral_s=2.0)
path = Path(tempfile.mkdtemp()) / "p1.json"
save_model(path, train([session_recording(session, profile)], profile))
f_label = next(cls.label for cls in profile.classes if cls.function == "F")
cues = [Cue(NEUTRAL_LABEL, "neutral", 0.0, 15.0), Cue(f_label, "F", 15.0, 20.0)]
parser = FrameParser()
first = sitting_ticks(profile, -40.0, cues, 17.0, parser, 0.0)
second = sitting_ticks(profile, 50.0, cues, 19.0, parser, 19.0)
ticks = []
loop = LiveLoop(OnlineChain(load_model(path), profile), StickArm(), observers=[ticks.append])
for t, frames in first: loop.tick(t, frames)
for k in range(round(2.0 / TICK)): loop.tick(17.0 + k * TICK, [])
for k, (t, frames) in enumerate(second): loop.tick(t, frames, reconnected=k == 0)
neutrals = [(tick.t, tick.neutral) for tick in ticks if tick.neutral is not None]
(t1, old), (t2, new) = neutrals
back = next(k for k, tick in enumerate(ticks) if tick.reconnected)
until = next(k for k, tick in enumerate(ticks) if tick.t == t2)
moving = sum(bool(t.command.linear.any()) for t in ticks[back:until + 1])
still_after = [t for t in ticks if t2 < t.t < 19.0 + 15.9]
print(f"reconnect at {ticks[back].t:.2f} s; new neutral at {t2:.2f} s ({t2 - ticks[back].t:.2f} s later); "
      f"ticks moving between: {moving} of {until + 1 - back}; yaw offset change per node: "
      + ", ".join(f"node {n}: {new[n][2] - old[n][2]:+.1f} deg" for n in old)
      + f"; after the new neutral, moving ticks during the neutral cue: {sum(bool(t.command.linear.any()) for t in still_after)} of {len(still_after)}")
f_again = [t for t in ticks if t.t >= 19.0 + 16.2]
print(f"F cue of the second sitting: F on {sum(bool(t.state.deflection.get('F')) for t in f_again)} of {len(f_again)} ticks")
