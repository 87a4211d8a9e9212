"""A person's layout chosen by simulation (`bomi design`): candidate mappings of their motions onto the
arm's functions, each run by their twin on development seeds, ranked by success and completion time.

The candidates (kept few, so that a handful of seeds can tell them apart):

- **buttons**: in every candidate the twin's profile's own (derived from the person's recording:
  the motions farthest from the other motions' paths from neutral, ``bomi.derived.button_motions``):
  a motion passed on the way to another is decided there for a moment, and as a button it would
  change the mode.
- **mapping** of the other motions onto the directions: in label order (what `bomi train` / `bomi
  twin` derive), or *by opposites*: the two motions most nearly opposite (the cosine of their
  postures' angle) drive the first pair of opposite directions (F/B), the two most nearly opposite
  of the rest the next (R/L), then Rr/Lr in the 3-axis layout. Opposite functions on opposite
  motions put the confusions a classifier is prone to (neighbouring postures) between functions
  that are not each other's undoing.
- **assistance**: the buttons alone, or the buttons with automatic mode switching (``auto-mode``).
- **layout**: the derived one (``bomi.derived.derived_layout``: the 3-axis layout from seven motions,
  the 2-axis one from four, the 1-axis one below). The 2-axis layout for seven or eight motions is
  not a candidate: a motion left without a function would still be decided, and the episode's
  person knows a class by its function.

Ranking: success share first (Wilson 95 % interval), then the mean completion time of the successes
(Student-t 95 % interval); on a tie the earlier candidate (the derived default first) is kept.

Recommendation: the derived default, unless a candidate beats it beyond chance on the same seeds
(``Against``), each at a one-sided level ``ALPHA``: it succeeded where the default failed more
often than the reverse (an exact sign test), or, failing where the default succeeded no more often
than the reverse, its completion time minus the default's on the seeds both succeeded is below 0
(an exact Wilcoxon signed-rank test). Of the candidates that do, the best ranked. Both tests rest
on ranks and signs, not on the spread of the differences: episode times have a heavy tail (a lost
cube or a stall adds 100-300 s), which a few seeds do not show. Either needs 5 seeds at least
(all won, or all faster: p = 1/32), hence the 5 seeds of `bomi design`. A layout the person must
learn anew is not worth a difference a few seeds may show by chance: on two held-out runs the best
ranked of 3 seeds, taken as it came, had 50 successes where the default had 51 of 62 episodes, and
a Student-t interval of 3 paired times below 0 let through layouts that were then slower (run new-people-task-17330 in docs/runs.md).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from bomi.derived import AUTO_MODE, BUTTON_NAMES, ONE_AXIS, THREE_AXIS, TWO_AXIS, derived_layout
from bomi.profiles import Profile
from tasks.statistics import Alternative, mean_interval, sign_test_p, signed_rank_p, wilson_interval

_DIRECTION_PAIRS = {THREE_AXIS: (("F", "B"), ("R", "L"), ("Rr", "Lr")), TWO_AXIS: (("F", "B"), ("R", "L")),
                    ONE_AXIS: (("F", "B"),)}
LABEL_ORDER, OPPOSITES = "label order", "by opposites"
ALPHA = 0.05   # the one-sided level of both tests by which a candidate beats the default (the usual 5 %)


@dataclass(frozen=True)
class Candidate:
    """One way of driving the arm: the layout, each motion's function (by label) and the assistances."""

    layout: str
    mapping: str
    functions: tuple[tuple[int, str], ...]
    assist: tuple[str, ...]

    @property
    def name(self) -> str:
        assisted = " + auto-mode" if AUTO_MODE in self.assist else ""
        buttons = "buttons" if any(function in BUTTON_NAMES for _, function in self.functions) else "no button"
        return f"{self.layout}, {self.mapping}, {buttons}{assisted}"

    def profile(self, base: Profile) -> Profile:
        """``base`` with this candidate's layout, class functions and assistances."""
        functions = dict(self.functions)
        classes = tuple(replace(c, function=functions.get(c.label, c.function)) for c in base.classes)
        mapping = ", ".join(f"c{label} {function}" for label, function in self.functions)
        return replace(base, classes=classes, joystick_layout=self.layout, assist=self.assist,
                       description=f"{base.description.split('; design:')[0]}; design: {self.name} ({mapping})")


def opposite_order(postures: Mapping[int, np.ndarray], pairs: int) -> list[int]:
    """The motion labels as ``pairs`` pairs, each the two most nearly opposite of the motions left (the
    lowest cosine between their postures, all nodes and angles together), then the rest in label order."""
    left = sorted(postures)
    unit = {k: np.ravel(v) / max(np.linalg.norm(v), 1e-9) for k, v in postures.items()}
    order: list[int] = []
    for _ in range(pairs):
        a, b = min(((a, b) for i, a in enumerate(left) for b in left[i + 1:]), key=lambda p: unit[p[0]] @ unit[p[1]])
        order += [a, b]
        left = [k for k in left if k not in (a, b)]
    return order + left


def _functions(layout: str, order: Sequence[int], buttons: Sequence[int]) -> tuple[tuple[int, str], ...]:
    directions = [f for pair in _DIRECTION_PAIRS[layout] for f in pair]
    return tuple(sorted([*zip(order, directions), *zip(buttons, BUTTON_NAMES)]))


def candidates(postures: Mapping[int, np.ndarray], buttons: Sequence[int] = ()) -> list[Candidate]:
    """The candidates for a person whose motions have these postures (label -> posture), the derived
    default first: ``buttons`` (the motions of B1, B2 in the person's profile; absent: the first motions
    after the directions in label order) press the buttons, the other motions drive the directions in
    label order or by opposites. No motion left for a button (two or four motions): the derived
    layout with automatic mode switching only."""
    labels = sorted(postures)
    derived = derived_layout(len(labels))
    if AUTO_MODE in derived.assist:
        return [Candidate(derived.layout, LABEL_ORDER, tuple(zip(labels, derived.functions)), derived.assist)]
    layout = derived.layout
    count = sum(f in BUTTON_NAMES for f in derived.functions)
    buttons = list(buttons) if len(buttons) == count else labels[len(labels) - count:]
    moving = {label: p for label, p in postures.items() if label not in buttons}
    orders = {LABEL_ORDER: sorted(moving), OPPOSITES: opposite_order(moving, len(_DIRECTION_PAIRS[layout]))}
    out = [Candidate(layout, mapping, _functions(layout, order, buttons), assist)
           for mapping, order in orders.items() for assist in ((), (AUTO_MODE,))]
    unique: dict[tuple, Candidate] = {}
    for candidate in out:   # label order and opposites may give the same functions: the first is kept
        unique.setdefault((candidate.functions, candidate.assist), candidate)
    return list(unique.values())


@dataclass(frozen=True)
class Score:
    """A candidate's episodes: successes (Wilson 95 % interval) and the successes' mean completion time
    (Student-t 95 % interval; None below two successes)."""

    candidate: Candidate
    episodes: int
    successes: int
    success_ci95: tuple[float, float]
    time_mean: float | None
    time_ci95: tuple[float, float] | None
    times: tuple[float | None, ...]   # per seed, in the seeds' order: the completion time, None on a failure

    @classmethod
    def of(cls, candidate: Candidate, records: Sequence[dict]) -> Score:
        per_seed = tuple(r["completion_time"] if r["success"] else None for r in records)
        times = [t for t in per_seed if t is not None]
        return cls(candidate, len(records), len(times), wilson_interval(len(times), len(records)),
                   float(np.mean(times)) if times else None, mean_interval(times), per_seed)

    def text(self) -> str:
        low, high = self.success_ci95
        time = "-" if self.time_mean is None else f"{self.time_mean:.1f} s"
        if self.time_ci95 is not None:
            time += f" [{max(0.0, self.time_ci95[0]):.1f}, {self.time_ci95[1]:.1f}]"
        return f"{self.successes}/{self.episodes} [{100 * low:.0f}, {100 * high:.0f} %], time {time}"


def ranked(scores: Sequence[Score]) -> list[Score]:
    """Best first: the success share, then the mean time of the successes (none: last); stable."""
    return sorted(scores, key=lambda s: (-s.successes / s.episodes, s.time_mean if s.time_mean is not None else np.inf))


@dataclass(frozen=True)
class Against:
    """A candidate against the derived default on the same seeds: the seeds only it succeeded on
    (``won``), only the default did (``lost``), and its time minus the default's where both did."""

    won: int
    lost: int
    time_differences: tuple[float, ...]

    @classmethod
    def of(cls, default: Score, candidate: Score) -> Against:
        if default.episodes != candidate.episodes:
            raise ValueError(f"{candidate.candidate.name} ran {candidate.episodes} seeds, the default {default.episodes}")
        pairs = list(zip(default.times, candidate.times))
        return cls(sum(d is None and c is not None for d, c in pairs), sum(d is not None and c is None for d, c in pairs),
                   tuple(c - d for d, c in pairs if d is not None and c is not None))

    @property
    def success_p(self) -> float:
        """One-sided exact sign test of the seeds one of the two failed: P(won or more | a fair coin)."""
        return sign_test_p(self.won, self.lost, Alternative.GREATER)

    @property
    def time_p(self) -> float:
        """One-sided exact Wilcoxon signed-rank test of the paired times: the candidate faster."""
        return signed_rank_p(self.time_differences, Alternative.LESS)

    def better(self) -> str | None:
        """Why the candidate beats the default beyond chance, or None."""
        if self.success_p < ALPHA:
            return (f"it succeeded on {self.won} seed(s) the default failed, failed on {self.lost} the default "
                    f"succeeded (sign test p = {self.success_p:.3f} < {ALPHA})")
        if self.won >= self.lost and self.time_p < ALPHA:
            return (f"faster on the {len(self.time_differences)} seeds both succeeded, by {-np.median(self.time_differences):.1f} s "
                    f"in the median (signed-rank test p = {self.time_p:.3f} < {ALPHA}), and no more failures")
        return None


def recommend(scores: Sequence[Score]) -> tuple[Score, str]:
    """The recommended of ``scores`` (the derived default first) and why: the best ranked of the
    candidates that beat the default beyond chance (``Against``), else the default."""
    default = scores[0]
    for score in ranked(scores[1:]):
        if (reason := Against.of(default, score).better()) is not None:
            return score, reason
    return default, (f"no candidate beat the derived default beyond chance on {default.episodes} seed(s) (more "
                     "seeds, --seeds, tell smaller differences apart)")
