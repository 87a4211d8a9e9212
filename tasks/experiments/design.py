"""`bomi design`'s work: each candidate layout of a person (tasks/operators/design.py) written as a
profile and run by their twin on the same seeds, then scored and ranked."""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from bomi.profiles import Profile, save_profile
from tasks.experiments.jobs import EpisodeJob
from tasks.operators.design import Against, Candidate, Score
from tasks.operators.stick import arm_profile
from tasks.stacking.channels import profile_controls


def candidate_jobs(twin: str | Path, base: Profile, options: list[Candidate], seeds: range, time_limit: float,
                   directory: Path) -> Iterator[tuple[Candidate, list[EpisodeJob]]]:
    """Per candidate, in order: its profile written in ``directory`` and checked (one the stacking
    user cannot drive fails here, unrun), and its episodes on ``seeds`` with the twin."""
    for k, option in enumerate(options, start=1):
        path = directory / f"candidate{k}.toml"
        save_profile(path, option.profile(base))
        profile_controls(arm_profile(path))
        yield option, [EpisodeJob("bomi", str(Path(twin).resolve()), seed, time_limit,
                                  overrides=(("participant.profile", str(path)),)) for seed in seeds]


def design_payload(twin: str, seeds: range, best: Candidate, reason: str, scores: list[Score],
                   records: list[dict]) -> dict:
    """What `bomi design --json` writes: every candidate's scores, its comparison with the derived
    default (the first) and its episodes' records (``records`` in candidate order)."""
    n = len(seeds)
    return {"twin": twin, "seeds": list(seeds), "recommended": best.name, "reason": reason,
            "candidates": [{"name": s.candidate.name, "functions": dict(s.candidate.functions),
                            "episodes": s.episodes, "successes": s.successes, "success_ci95": s.success_ci95,
                            "completion_time_mean": s.time_mean, "completion_time_ci95": s.time_ci95,
                            "against_default": vars(Against.of(scores[0], s)),
                            "records": records[k * n:(k + 1) * n]}
                           for k, s in enumerate(scores)]}
