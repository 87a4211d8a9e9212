"""A stand-in twin driven by a model trained on its own source recording is the person of that
recording's day (issue 53.4): the twin file names its recordings' runs, the model its training runs."""
import dataclasses
from types import SimpleNamespace

import numpy as np

from tasks.participants.params import Protocol, load_participant, parse_participant_text
from tasks.trials.standin import trained_on_its_recording


def _chain(*runs: str) -> SimpleNamespace:
    return SimpleNamespace(model=SimpleNamespace(training_runs=tuple(runs)))


def test_only_a_model_trained_on_the_twins_own_runs_puts_it_on_its_recorded_day():
    twin = dataclasses.replace(load_participant("P1"), protocol=Protocol((0, 1), (5.0, 5.0), True, "day1.mat",
                                                                         ("aa11", "bb22")))
    assert trained_on_its_recording(twin, _chain("bb22", "cc33"))
    assert not trained_on_its_recording(twin, _chain("cc33"))
    assert not trained_on_its_recording(dataclasses.replace(twin, protocol=None), _chain("aa11"))


def test_the_twin_file_keeps_its_run_digests():
    text = open(load_participant("P1").source).read()   # a twin file written before the digests
    assert parse_participant_text(text, "old.toml").protocol.run_digests == ()
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("durations_s"))
    with_runs = "\n".join(lines[:at + 1] + ['run_digests = ["aa11", "bb22"]'] + lines[at + 1:])
    params = parse_participant_text(with_runs, "twin.toml")
    assert params.protocol.run_digests == ("aa11", "bb22") and np.isclose(params.feel.give_up_s, 10.0)
