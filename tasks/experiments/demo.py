"""`bomi demo`'s work: one joystick and one BoMI episode of a participant on one seed, the BoMI
episode filmed, both drawn on one timeline figure and written as JSON."""
from __future__ import annotations

from pathlib import Path

from bomi import paper
from bomi.files import atomic_output
from tasks.experiments.jobs import EpisodeJob, run_job, stage
from tasks.experiments.summary import write_json
from tasks.operators.assist import Assist
from tasks.stacking.summary import summarize
from tasks.stacking.timeline import timeline_figure

# The demo's MP4 plays this many times faster than simulated time: a long BoMI episode stays a
# short film (and quick to render).
DEMO_VIDEO_SPEEDUP = 8.0


def run_demo(participant: str, seed: int, time_limit: float, assist: frozenset[Assist] | None, figure: Path,
             video: Path, record: Path, replace: bool) -> list[dict]:
    """Both episodes (progress bars on stderr), the BoMI's filmed to ``video``, the timeline to
    ``figure`` and both records with the paper's figures to ``record`` (each written whole, replacing
    an existing file only if ``replace``); returns the two records."""
    joystick = run_job(EpisodeJob("joystick", participant, seed, time_limit, assist=assist), progress=True)
    with atomic_output(video, overwrite=replace) as temp:
        bomi = run_job(EpisodeJob("bomi", participant, seed, time_limit, assist=assist), video=temp,
                       video_speedup=DEMO_VIDEO_SPEEDUP, progress=True)
    summaries = [summarize(joystick), summarize(bomi)]
    with stage("timeline figure", progress=True), atomic_output(figure, overwrite=replace) as temp:
        timeline_figure([joystick, bomi], temp)
    write_json(record, {"paper": paper.TASK, "episodes": summaries}, overwrite=replace)
    return summaries
