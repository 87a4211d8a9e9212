"""`bomi design`'s candidates and ranking (tasks/operators/design.py), without running episodes."""
from __future__ import annotations

import numpy as np
import pytest

from bomi.derived import derive_profile
from tasks.operators.design import (LABEL_ORDER, OPPOSITES, Against, Candidate, Score, candidates, opposite_order, ranked,
                                    recommend)
from tasks.stacking.channels import profile_controls
from tests.test_derived_layout import motions


def posture(pitch: float, roll: float) -> np.ndarray:
    return np.array([[pitch, roll, 0.0]])


# six head motions: c1 pitch +, c2 roll +, c3 pitch -, c4 roll -, c5 / c6 diagonal, c6 almost opposite c5
POSTURES = {1: posture(20, 0), 2: posture(0, 20), 3: posture(-25, 2), 4: posture(1, -18), 5: posture(15, 15),
            6: posture(-14, -16)}


def test_by_opposites_pairs_the_most_nearly_opposite_motions_first():
    # cosines by hand: c2/c4 -360 / (20 * 18.03) = -0.9984, c5/c6 -450 / (21.21 * 21.26) = -0.9978,
    # c1/c3 -500 / (20 * 25.08) = -0.9968: c2/c4 first, then c5/c6 of the rest, then c1, c3 in label order
    assert opposite_order(POSTURES, 2) == [2, 4, 5, 6, 1, 3]
    assert opposite_order(POSTURES, 3) == [2, 4, 5, 6, 1, 3]


def test_six_motions_give_four_candidates_the_derived_default_first():
    options = candidates(POSTURES, [3, 5])   # the profile's B1 and B2 motions
    assert [(c.layout, c.mapping, c.assist) for c in options] == [
        ("2-axis", LABEL_ORDER, ()), ("2-axis", LABEL_ORDER, ("auto-mode",)),
        ("2-axis", OPPOSITES, ()), ("2-axis", OPPOSITES, ("auto-mode",))]
    assert dict(options[0].functions) == {1: "F", 2: "B", 4: "R", 6: "L", 3: "B1", 5: "B2"}
    # of the others c2/c4 most nearly opposite (-0.9984), then c1, c6
    assert dict(options[2].functions) == {2: "F", 4: "B", 1: "R", 6: "L", 3: "B1", 5: "B2"}
    # a profile without its buttons named: the motions after the directions press them; c2/c4, then c1/c3
    assert dict(candidates(POSTURES)[2].functions) == {2: "F", 4: "B", 1: "R", 3: "L", 5: "B1", 6: "B2"}
    # each is a profile the stacking user can drive
    base = derive_profile([motions(6)])
    for option in options:
        profile = option.profile(base)
        assert profile_controls(profile).buttons == ("B1", "B2")
        assert profile.assist == option.assist and option.name in profile.description


def test_where_both_mappings_coincide_the_candidate_is_run_once():
    # label order already pairs opposites: c1/c2 and c3/c4 opposite, c5 the button
    same = {1: posture(20, 0), 2: posture(-20, 0), 3: posture(0, 20), 4: posture(0, -20), 5: posture(10, 10)}
    assert [(c.mapping, c.assist) for c in candidates(same, [5])] == [(LABEL_ORDER, ()), (LABEL_ORDER, ("auto-mode",))]


def test_three_motions_take_the_one_axis_layout_and_b1_four_no_button_and_auto_mode_alone():
    # c2 the button: the two left are F/B in label order and by opposites alike (one candidate mapping)
    three = candidates({1: posture(20, 0), 2: posture(0, 20), 3: posture(-20, 1)}, [2])
    assert [(c.layout, c.mapping, c.assist) for c in three] == [
        ("1-axis", LABEL_ORDER, ()), ("1-axis", LABEL_ORDER, ("auto-mode",))]
    assert dict(three[0].functions) == {1: "F", 3: "B", 2: "B1"} and three[0].name == "1-axis, label order, buttons"
    base = derive_profile([motions(3)])
    assert all(profile_controls(c.profile(base)).buttons == ("B1",) for c in three)
    (four,) = candidates({k: POSTURES[k] for k in (1, 2, 3, 4)})
    assert four.name == "2-axis, label order, no button + auto-mode"
    assert profile_controls(four.profile(derive_profile([motions(4)]))).buttons == ()


def record(success: bool, time: float) -> dict:
    return {"success": success, "completion_time": time if success else None}


def test_ranking_is_successes_then_time_with_intervals():
    a, b, c = (Candidate("2-axis", name, ((1, "F"),), ()) for name in "abc")
    scores = [Score.of(a, [record(True, 200.0), record(False, 0), record(True, 220.0)]),
              Score.of(b, [record(True, 250.0), record(True, 230.0), record(True, 240.0)]),
              Score.of(c, [record(True, 190.0), record(True, 210.0), record(True, 200.0)])]
    assert [s.candidate.mapping for s in ranked(scores)] == ["c", "b", "a"]
    assert scores[2].time_mean == pytest.approx(200.0)
    # Student-t: mean 200, sd 10, n 3: 200 +- 4.303 * 10 / sqrt(3) = [175.2, 224.8]
    assert scores[2].time_ci95 == pytest.approx((200 - 4.3027 * 10 / 3 ** 0.5, 200 + 4.3027 * 10 / 3 ** 0.5), abs=1e-3)
    # Wilson 2/3: [20.8 %, 93.9 %]
    assert scores[0].success_ci95 == pytest.approx((0.2077, 0.9385), abs=1e-3)
    assert scores[2].text() == "3/3 [44, 100 %], time 200.0 s [175.2, 224.8]"


def scored(name: str, *times: float | None) -> Score:
    """A candidate's score from its completion time per seed (None: failed)."""
    return Score.of(Candidate("2-axis", name, ((1, "F"),), ()), [record(t is not None, t or 0.0) for t in times])


def test_a_candidate_beats_the_default_only_beyond_chance_on_the_same_seeds():
    default = scored("default", 200.0, None, 210.0, None, None)
    # 3 seeds won, none lost: sign test p = 0.5 ** 3 = 0.125, not below 0.05; faster on the two seeds
    # both succeeded: signed ranks all negative, p = 0.5 ** 2 = 0.25
    some = Against.of(default, scored("some", 190.0, 220.0, 205.0, 230.0, 240.0))
    assert (some.won, some.lost, some.time_differences) == (3, 0, (-10.0, -5.0))
    assert some.success_p == pytest.approx(0.125) and some.time_p == pytest.approx(0.25) and some.better() is None
    # every seed the default failed won, on 5 seeds: p = 0.5 ** 5 = 0.03125
    all_won = Against.of(scored("default", None, None, None, None, None), scored("all", *[300.0] * 5))
    assert all_won.success_p == pytest.approx(0.03125) and "p = 0.031" in all_won.better()
    # the same 5 seeds succeeded, faster on each (by 10, 12, 11, 1, 2 s): the 2^5 sign patterns of the ranks
    # equally likely, none as low as all negative: p = 1/32; the median gain 10 s
    base = (200.0, 210.0, 220.0, 230.0, 240.0)
    faster = Against.of(scored("default", *base), scored("faster", 190.0, 198.0, 209.0, 229.0, 238.0))
    assert faster.time_p == pytest.approx(1 / 32)
    assert "faster on the 5 seeds both succeeded, by 10.0 s in the median (signed-rank test p = 0.031" in faster.better()
    # faster by much on 4, slower by 1 s on the fifth (the smallest rank, 1): sums of negative-free ranks
    # <= 1 are 2 patterns of 32: p = 0.0625; a heavy tail cannot buy it (ranks, not sizes)
    lucky = Against.of(scored("default", *base), scored("lucky", 100.0, 110.0, 120.0, 130.0, 241.0))
    assert lucky.time_p == pytest.approx(2 / 32) and lucky.better() is None
    # 3 seeds can never be enough: all faster, p = 1/8
    assert Against.of(scored("default", 200.0, 210.0, 220.0), scored("three", 100.0, 110.0, 120.0)).better() is None
    # as fast, but one more failure: not better
    assert Against.of(scored("default", *base), scored("fails", 190.0, 198.0, 209.0, 229.0, None)).better() is None
    with pytest.raises(ValueError, match="ran 2 seeds, the default 3"):
        Against.of(scored("default", 200.0, 210.0, 220.0), scored("short", 190.0, 198.0))


def test_the_recommendation_is_the_best_ranked_of_those_beating_the_default_else_the_default():
    base = (200.0, 210.0, 220.0, 230.0, 240.0)
    default = scored("default", *base)
    lucky = scored("lucky", 100.0, 110.0, 120.0, 130.0, 241.0)   # faster on average, not beyond chance: ranked first
    steady = scored("steady", 190.0, 198.0, 209.0, 229.0, 238.0)  # beats the default (above)
    steadier = scored("steadier", 195.0, 205.0, 215.0, 225.0, 235.0)  # 5 s faster on each seed: ties, p 1/32
    assert [s.candidate.mapping for s in ranked([default, lucky, steady, steadier])][0] == "lucky"
    chosen, reason = recommend([default, lucky, steadier, steady])
    assert chosen is steady and "faster" in reason
    chosen, reason = recommend([default, lucky])
    assert chosen is default and "no candidate beat the derived default beyond chance on 5 seed(s)" in reason
