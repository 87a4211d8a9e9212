"""The BoMI chain, batch (training, evaluation) and streaming (live and simulated runs).

Both forms share every stage: node states -> ``component_index`` -> windows -> ``features`` ->
``posteriors`` -> post-processing -> class, joystick function, proportional output nu.

Modules, in the order of the stages:

- ``windows``: node states of a recording (neutral-subtracted angles + gyroscope), cut into windows
  for a feature spec (``prepare``), and the training windows' container and class priors.
- ``holds``: cues and movement told apart where a recording keeps its moves (``bomi.onsets``): the
  posture held before each measured onset (``as_held``, for training) and each cue's transition
  (``MoveAllowances``, left out of the holds accuracy).
- ``copies``: the synthesised training copies (smaller, turned, measured from other rests:
  ``MotionCopies``) and ``training_windows``, the single-label windows plus the copies.
- ``selection``: cross-validation holding out whole holds and the rule that chooses a new person's
  settings (shrinkage, copies, rejection: ``select_settings``).
- ``training``: the checks on the recordings (``check_training_data``) and ``train``.
- ``evaluation``: a model scored on a labelled recording (``evaluate``), leave-one-pass-out, and the
  choice of the rest-offset copies across passes (``choose_rest_offsets``).
- ``online``: the streaming chain (``OnlineChain``) and its ``Decision``.

Every public name is re-exported here: ``from bomi.chain import train, OnlineChain``.
"""
from bomi.chain.copies import MotionCopies, rest_offsets, rotated_about, training_windows
from bomi.chain.evaluation import (Evaluation, PassOut, choose_rest_offsets, each_pass_by_the_others, evaluate,
                                   evaluate_each, leave_one_pass_out, rest_offset_scores)
from bomi.chain.holds import MAX_MOVE_END_S, MoveAllowances, as_held, held_labels, recording_moves
from bomi.chain.online import Decision, OnlineChain
from bomi.chain.selection import (CONSISTENCY, N_FOLDS, PLAIN, REQUIRED_GAIN, SHRINKAGE_GRID, THRESHOLD_GRID, Candidate,
                                  CrossValidation, HoldScores, Selection, choose_candidate, choose_option,
                                  choose_settings, choose_threshold, cross_validate, hold_folds, select_settings,
                                  select_settings_each, settings_candidates)
from bomi.chain.training import MIN_CLASS_WINDOWS, check_training_data, train
from bomi.chain.windows import (PreparedRecording, TrainingWindows, node_states, prepare, recorded_priors,
                                recording_neutral, require_for, spec_signals, window_features)

__all__ = [
    "CONSISTENCY", "MAX_MOVE_END_S", "MIN_CLASS_WINDOWS", "MoveAllowances", "as_held", "held_labels",
    "recording_moves", "N_FOLDS", "PLAIN", "REQUIRED_GAIN", "SHRINKAGE_GRID", "THRESHOLD_GRID", "Candidate",
    "CrossValidation", "Decision", "Evaluation", "HoldScores", "MotionCopies", "OnlineChain", "PassOut",
    "PreparedRecording", "Selection", "TrainingWindows", "check_training_data", "choose_candidate", "choose_option",
    "choose_rest_offsets", "choose_settings", "choose_threshold", "cross_validate", "each_pass_by_the_others",
    "evaluate", "evaluate_each", "hold_folds", "leave_one_pass_out", "node_states", "prepare", "recorded_priors",
    "recording_neutral", "require_for", "rest_offset_scores", "rest_offsets", "rotated_about", "select_settings",
    "select_settings_each", "settings_candidates", "spec_signals", "train", "training_windows", "window_features",
]
