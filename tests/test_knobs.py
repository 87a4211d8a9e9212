"""The knobs that shaped the results are data: every one benchmarks/sensitivity.py varies is read
from its TOML file (an edited value reaches the code), and the sensitivity scales them as it says."""
import pytest

from helpers import benchmark_script
from tasks.participants.participant import load_participant
from tasks.operators.params import load_operator

sensitivity = benchmark_script("sensitivity")


def test_every_knob_of_the_sensitivity_reaches_the_code():
    knobs = sensitivity.knob_values()
    assert len(knobs) >= 15 and sensitivity.VOTE in knobs
    for knob, value in knobs.items():
        if knob == sensitivity.VOTE:
            continue
        file, key = knob.split(".", 1)
        # half, or one and a half where half is out of the knob's range (most_lean: at least 1)
        edited = next(v for v in (sensitivity.scaled(value, f) for f in (0.5, 1.5)) if sensitivity.invalid(knob, v) is None)
        if file == "operator":
            assert getattr(load_operator(overrides={key: edited}), key.rsplit(".", 1)[1]) == pytest.approx(edited)
        else:
            params = load_participant(sensitivity.PARTICIPANT, {key: edited})
            assert getattr(params.feel, key.rsplit(".", 1)[1]) == pytest.approx(edited), knob


def test_an_edit_outside_a_knobs_range_is_left_out_with_its_reason():
    assert sensitivity.invalid("participant.feel.max_zero", 1.35).endswith("got 1.35")
    assert sensitivity.invalid("participant.feel.max_zero", 0.45) is None
    assert sensitivity.invalid(sensitivity.VOTE, 2) is None


def test_integer_knobs_stay_integers_of_at_least_one():
    assert sensitivity.scaled(5, 0.5) == 2 and sensitivity.scaled(5, 1.5) == 8 and sensitivity.scaled(1, 0.5) == 1
    assert sensitivity.scaled(0.15, 1.5) == pytest.approx(0.225)
