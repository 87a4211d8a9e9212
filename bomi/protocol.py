"""The paper's calibration protocol: which motion to hold when, shared by `bomi record`,
`bomi emulate --participant` and the virtual participant's calibration session."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from bomi.profiles import NEUTRAL_FUNCTION, ClassConfig, Profile


def protocol_order(labels: Sequence[int], repetitions: int, amplitudes: Sequence[float]) -> list[tuple[int, float]]:
    """Every class at every amplitude, class after class, the whole sequence ``repetitions`` times."""
    return [(label, amp) for _ in range(repetitions) for label in labels for amp in amplitudes]


@dataclass(frozen=True)
class Cue:
    """One cue of the calibration protocol: hold ``label`` (or neutral) from start_s to end_s."""

    label: int
    prompt: str
    start_s: float
    end_s: float


def calibration_schedule(profile: Profile, *, repetitions: int = 3, sequences: int = 1,
                         amplitudes: Sequence[float] = (1.0,), hold_s: float = 5.0,
                         neutral_s: float = 5.0) -> list[Cue]:
    """Neutral, then every motion class (at every amplitude) in label order, each held ``hold_s``
    and followed by ``neutral_s`` of neutral; the class sequence ``repetitions`` times per sequence."""
    neutral = next(cls for cls in profile.classes if cls.function == NEUTRAL_FUNCTION)
    by_label = {cls.label: cls for cls in profile.classes if cls.function != NEUTRAL_FUNCTION}
    motions = [(by_label[label], amp)
               for label, amp in protocol_order(sorted(by_label), sequences * repetitions, amplitudes)]
    schedule, t = [Cue(neutral.label, _prompt(neutral, None), 0.0, neutral_s)], neutral_s
    for cls, amp in motions:
        schedule.append(Cue(cls.label, _prompt(cls, amp if len(amplitudes) > 1 else None), t, t + hold_s))
        schedule.append(Cue(neutral.label, _prompt(neutral, None), t + hold_s, t + hold_s + neutral_s))
        t += hold_s + neutral_s
    return schedule


def _prompt(cls: ClassConfig, amplitude: float | None) -> str:
    if cls.function == NEUTRAL_FUNCTION:
        return f"relax: {cls.name}"
    extent = "" if amplitude is None else f" at {100 * amplitude:.0f} % of your range"
    return f"HOLD c{cls.label} {cls.function}: {cls.name}{extent}"
