"""Evaluation: a model scored on a labelled recording, each pass by the model of the others, and
whether the rest-offset copies earn their place (judged across passes)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from bomi.chain.holds import MoveAllowances
from bomi.chain.selection import CONSISTENCY, HoldScores, choose_option
from bomi.chain.training import train
from bomi.chain.windows import prepare
from bomi.classifier import Model, PostProcessing, classify_windows
from bomi.errors import BomiError
from bomi.features import FeatureSpec, run_edges
from bomi.profiles import Profile
from bomi.recording import Recording


@dataclass
class Evaluation:
    """Scores of a model on the single-label windows of a labelled recording."""

    source: str
    truth: np.ndarray
    predicted: np.ndarray    # after post-processing (a rejected window is predicted neutral)
    rejected: np.ndarray
    on_hold: np.ndarray | None = None          # the scored windows on the holds, where the recording keeps
    allowances: MoveAllowances | None = None   # its moves (and the transitions left out); None: all are holds

    @property
    def holds(self) -> np.ndarray:
        """(m,) the scored windows on the holds: all of them in a recording that keeps only its holds."""
        return np.ones(len(self.truth), dtype=bool) if self.on_hold is None else self.on_hold

    @property
    def holds_accuracy(self) -> float:
        """Accuracy over the windows on the holds (the transitions left out): the classifier's own errors,
        not the person's reaction to the cue."""
        holds = self.holds
        return float(np.mean(self.predicted[holds] == self.truth[holds])) if holds.any() else float("nan")

    @property
    def accuracy(self) -> float:
        return float(np.mean(self.predicted == self.truth))

    @property
    def rejected_share(self) -> float:
        return float(np.mean(self.rejected))

    @property
    def accepted_accuracy(self) -> float:
        """Accuracy over the windows the rejection let through."""
        accepted = ~self.rejected
        return float(np.mean(self.predicted[accepted] == self.truth[accepted])) if accepted.any() else float("nan")


def evaluate(model: Model, rec: Recording, neutral_samples: int, post: PostProcessing | None = None) -> Evaluation:
    """Decide every window in time order (as the stream does), then score the single-label ones against
    the cue; where the recording keeps its moves, also tell which lie on the holds (``holds``)."""
    (evaluation,) = evaluate_each([model], rec, neutral_samples, post)
    return evaluation


def evaluate_each(models: Sequence[Model], rec: Recording, neutral_samples: int,
                  post: PostProcessing | None = None) -> list[Evaluation]:
    """``evaluate`` of each of ``models`` (of one feature spec) on ``rec``: its windows prepared and its
    moves found once for all of them."""
    if not models:
        return []
    spec = models[0].spec
    if any(model.spec != spec for model in models):
        raise ValueError("evaluate_each: the models' feature specs differ")
    for model in models:
        unknown = sorted(set(rec.require_labels().tolist()) - set(model.classes.tolist()))
        if unknown:
            raise BomiError(f"{rec.source}: label(s) {unknown} are not classes of the model {model.classes.tolist()}")
    prepared = prepare(rec, spec, neutral_samples)
    pure = prepared.pure
    if not pure.any():
        raise BomiError(f"{rec.source}: no {spec.window}-sample window lies within one label; nothing to score")
    allowances = MoveAllowances.of(rec, spec.nodes)
    evaluations = []
    for model in models:
        decisions = classify_windows(model, prepared.features, post)
        on_hold = None
        if allowances is not None:   # a hold's part after its transition is a suffix of its run: its first row decides
            on_hold = allowances.on_hold(len(rec))[prepared.ends[pure] - (spec.window - 1)]
        evaluations.append(Evaluation(rec.source, prepared.labels[pure], decisions.labels[pure],
                                      decisions.rejected[pure], on_hold, allowances))
    return evaluations


@dataclass(frozen=True)
class PassOut:
    """A leave-one-pass-out cross-validation: each pass decided by a model trained on the others."""

    evaluations: tuple[Evaluation, ...]

    @property
    def accuracy(self) -> float:
        """Over every held-out window of every pass (pooled)."""
        return float(np.mean(np.concatenate([ev.predicted == ev.truth for ev in self.evaluations])))

    @property
    def holds_accuracy(self) -> float:
        """Over the held-out windows on the holds (``Evaluation.holds``), pooled."""
        return float(np.mean(np.concatenate([(ev.predicted == ev.truth)[ev.holds] for ev in self.evaluations])))

    def text(self) -> str:
        each = ", ".join(f"{100 * ev.accuracy:.2f} %" for ev in self.evaluations)
        holds = ("" if all(ev.allowances is None for ev in self.evaluations) else
                 f"; on the holds {100 * self.holds_accuracy:.2f} %, each transition from its cue to the end of its "
                 "move found in the signals left out")
        return (f"leave-one-pass-out accuracy {100 * self.accuracy:.2f} % (each of {len(self.evaluations)} passes "
                f"decided by a model trained on the others: {each}){holds}")


def leave_one_pass_out(passes: Sequence[Recording], profile: Profile, model: Model) -> PassOut | None:
    """``model``'s settings (shrinkage, copies, post-processing) trained on all passes but one and tested
    on it, for every pass: how the classifier does on a pass it has not seen. None for one pass; a
    BomiError when the passes but one cannot train every class."""
    if len(passes) < 2:
        return None
    return PassOut(tuple(each_pass_by_the_others(passes, replace(profile, amplitude_scales=model.amplitude_scales),
                                                 model.spec, model.shrinkage, model.post)))


def each_pass_by_the_others(passes: Sequence[Recording], profile: Profile, spec: FeatureSpec,
                            shrinkage: float | str | None, post: PostProcessing) -> list[Evaluation]:
    """Each pass decided by the model of these settings trained on all the other passes."""
    evaluations = []
    for k, held_out in enumerate(passes):
        others = [p for j, p in enumerate(passes) if j != k]
        fold = train(others, profile, spec, shrinkage=shrinkage, post=post)
        evaluations.append(evaluate(fold, held_out, profile.neutral_samples, post))
    return evaluations


def rest_offset_scores(passes: Sequence[Recording], profile: Profile) -> tuple[HoldScores, HoldScores]:
    """Each pass read by the model of the others, without and with the rest-offset copies (the
    profile's plain LDA and smaller copies: the copies' own effect), scored per hold."""
    scores = []
    for on in (False, True):
        correct, windows = [], []
        for result in each_pass_by_the_others(passes, replace(profile, rest_offsets=on), profile.spec, None,
                                              PostProcessing()):
            holds = run_edges(result.truth)   # the scored windows, in time order: a run of one label is a hold
            correct.append(np.add.reduceat(result.predicted == result.truth, holds[:-1]))
            windows.append(np.diff(holds))
        scores.append(HoldScores(np.concatenate(correct), np.concatenate(windows)))
    return scores[0], scores[1]


def choose_rest_offsets(passes: Sequence[Recording], profile: Profile) -> tuple[bool, str]:
    """Whether the rest-offset copies (``MotionCopies.rest_offsets``) earn their place for this person,
    and why in one line. A cross-validation within one recording cannot tell (its folds share one
    reference); passes calibrated each on its own rest can (``rest_offset_scores``), judged by
    ``choose_option``'s rule, its standard errors without its margin: REQUIRED_GAIN stands for the
    drift to the next recording that a cross-validation within one cannot see, and the other pass
    shows it. One pass: no evidence, no copies."""
    if len(passes) < 2:
        return False, "no rest-offset copies: one pass, nothing to judge them on"
    without, with_copies = rest_offset_scores(passes, profile)
    chosen = choose_option([without, with_copies], required_gain=0.0) == 1
    gain, se = with_copies.gain_over(without)
    return chosen, (f"{'' if chosen else 'no '}rest-offset copies: each pass read by the others' model "
                    f"{100 * without.accuracy:.2f} % without, {100 * with_copies.accuracy:.2f} % with "
                    f"({100 * gain:+.2f} +- {100 * se:.2f} points over {len(without.windows)} holds: they come in "
                    f"for a gain of {CONSISTENCY:g} standard errors)")
