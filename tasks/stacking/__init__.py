"""The stacking task, the one loop that steps it, and how an episode is recorded and measured.

Map (data flows down):

- ``vocabulary``: the task's words: what the person sees (``View``), wants (``Goal``, ``Phase``,
  ``StickIntent``) and has (``Controls``), the recovery actions a record names.  Imports nothing
  of the operators, participants or the loop: they all speak it.
- ``task``: the paper's assembly task (two 5 cm cubes from A stacked at B): the scene, the
  person's view of it, success and termination.
- ``env``: the task as a Gymnasium environment (``BomiJaco/Stacking-v0``): the one loop every
  surface steps (episodes, trials, replays, stand-ins), one control tick per ``step``.
- ``channels``: how the person's intent reaches the stick: straight (joystick) or through a
  virtual participant's body and the BoMI chain.
- ``sources``: who holds the stick (``ActionSource``): the scripted user or the human model at a
  channel (``Operator``; ``joystick_user``, ``bomi_user``), or an input device.
- ``wrappers``: what sits between the stick and the arm, or watches: assistance, the recovery
  supervisor's gate, the film.
- ``episode``: one episode (``run_episode``): a source steps the wrapped env until done; its record.
- ``record``: what an episode records (``EpisodeLog``); ``summary``: its per-episode metrics.
- ``metrics``: pure functions over a record's arrays (completion, accuracy, drops, phases).
- ``failures``: why an episode failed or was slow (its stuck span and mechanism).
- ``timeline``: the paper-style timeline figure of an episode.
- ``budget``: where an episode's time and its irrelevant outputs go (time budget by part,
  irrelevant decisions by context, the vote's effect).
"""
