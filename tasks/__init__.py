"""The composing side: the stacking task, who drives the arm, the participants, trials and the CLI.

Map (data flows down; each subpackage's docstring maps its modules):

- ``participants``: virtual people (a twin of a person's calibration) whose IMU frames go
  through the real chain (``bomi/``).
- ``operators``: who and what drives the arm's joystick: the scripted user's plan (``planner``),
  its human model, decisions -> joystick (``stick``), assistance, recovery, and the layout
  design that picks a person's mapping by simulation.
- ``stacking``: the paper's task (``task``), the episode loop where participant, operator, arm
  and task meet (``episode``), and what an episode is measured by (``metrics``, ``failures``,
  ``timeline``).
- ``trials``: a person in the loop: the live loop from a serial stream (``live``), sessions of
  trials, their files, replays and reports.
- ``cli``: the ``bomi`` command line, the one place that wires ``bomi/``, ``sim/`` and ``tasks/``.
"""
