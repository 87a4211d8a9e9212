"""A person in the loop: `bomi live` drives the arm from a stream, `bomi trial` runs the paper's
session, `bomi replay` re-runs a logged trial.

Map (data flows down):

- ``live``: the live loop: a base-station stream through the live person (``person``) to the task's
  environment at its control rate, with the safety path (any input it cannot trust leaves the arm at rest).
- ``person``: the live person as an action source (stream -> gate -> chain -> sanitizer -> stick:
  ``LivePerson``) and the safety hold around it (``SafetyHold``).
- ``recalibration``: the calibration protocol performed during a live session at the person's long
  press, and the classifier retrained on it.
- ``displays``: where a live run is shown and logged (viewer, film process, status line, tick log).
- ``session``: the runner. ``TrialArm`` runs N trials on the task's environment
  (``tasks.stacking.env``: wait, countdown, the timed trial, next; reset per trial); ``run_bomi`` drives it from the live loop (``tasks.trials.live.run_live``),
  ``run_joystick`` from an input device; ``TickRecorder`` keeps every tick; ``episode_log`` and
  ``trial_record`` score each trial with ``tasks.stacking.episode.summarize`` (the benchmark's records).
- ``assisted``: the assistance (automatic mode switching, grasp help) on a session's trials, as the
  benchmark applies it to an episode; logged per trial, applied again by a replay.
- ``standin``: a virtual participant at the controls (BoMI: base-station bytes through the live
  path; joystick: the scripted user's stick), on a simulated clock.
- ``devices``: a person's joystick: a gamepad (pygame) or the viewer's keys.
- ``dataset``: the HDF5 file of a session (format ``bomi-trials``, versioned; docs/trials.md).
- ``replay``: a logged trial re-run through the loop and the arm; its decisions re-scored with another model.
- ``report``: report.md (the trial table beside the paper's) and the timeline figures.
"""
