"""The composing side: the stacking task, who drives the arm, the participants, trials and the CLI.

Map (data flows down; each subpackage's docstring maps its modules):

- ``participants``: virtual people (a twin of a person's calibration) whose IMU frames go
  through the real chain (``bomi/``).
- ``operators``: who and what drives the arm's joystick: the scripted user's plan (``planner``),
  its human model, decisions -> joystick (``stick``), assistance, recovery, and the layout
  design that picks a person's mapping by simulation.
- ``stacking``: the paper's task and its vocabulary, the task as a Gymnasium environment
  (``env``: the one loop every surface steps), the sources of actions (``sources``: scripted
  user, human model, BoMI participant, devices) and the wrappers between them and the arm, one
  episode (``episode``) and what it is measured by (``record``, ``summary``, ``metrics``,
  ``failures``, ``timeline``).
- ``trials``: a person in the loop: the live loop from a serial stream (``live``), sessions of
  trials, their files, replays and reports.
- ``cli``: the ``bomi`` command line, the one place that wires ``bomi/``, ``sim/`` and ``tasks/``.
"""
