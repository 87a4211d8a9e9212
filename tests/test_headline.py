"""Guards of the headline: a whole BoMI episode of P1 succeeds (the paper's table, `bomi reproduce`,
on the real recordings: tests/test_reproduce_command.py; `bomi demo`: tests/test_cli.py).  The fixed
seed is a development seed (0-999); the reported figures come from held-out seeds (README)."""

import pytest

from tasks.experiments.jobs import DEFAULT_VOTE, EpisodeJob, run_job
from tasks.stacking.summary import summarize

DEV_SEED = 0


@pytest.mark.long
def test_a_p1_bomi_episode_stacks_the_cubes_within_a_generous_time():
    """Calibration, then the task, through frames, fusion, LDA and vote: both cubes stacked at B."""
    summary = summarize(run_job(EpisodeJob("bomi", "P1", DEV_SEED, time_limit=300.0, vote_length=DEFAULT_VOTE)))
    assert summary["success"], summary["failure"]
    assert summary["completion_time"] < 300.0 and summary["cube_drops"] == 0
    # the decisions follow the intent far above chance (9 classes), the excused figure above the all-decision one
    assert 0.3 < summary["accuracy_all_decisions"] < summary["accuracy_excused_transitions"] <= 1.0
    assert summary["excused_share"] == pytest.approx(summary["accuracy_excused_transitions"]
                                                     - summary["accuracy_all_decisions"])
