"""The stacking task and how an episode of it is run and measured.

Map (data flows down):

- ``task``: the paper's assembly task (two 5 cm cubes from A stacked at B): the scene, the
  person's view of it, success and termination.
- ``episode``: one episode, the one loop at the 60 Hz control rate where the operator (joystick
  or BoMI participant), the arm and the task meet; its record (``EpisodeLog``) and summary.
- ``metrics``: pure functions over a record's arrays (completion, accuracy, drops, phases).
- ``failures``: why an episode failed or was slow (its stuck span and mechanism).
- ``timeline``: the paper-style timeline figure of an episode.
"""
