"""Who and what drives the arm's joystick (robosuite's controllers and input devices, apart from the task).

Map (each acts on the task's vocabulary, ``tasks.stacking.vocabulary``):

- ``params``: the scripted user's parameters, ``operator.toml`` (configuration as data).
- ``judgement``: what the person judges of the task from a view (cubes placed, held, turned off)
  and the little they remember between glances.
- ``planner``: the scripted JACO user, a pure plan from what the person sees, with a person's timing.
- ``human``: the human operator model around it (perception and timing; ``human.toml``).
- ``stick``: classifier decisions -> joystick state, shared by simulated and live BoMI.
- ``assist``: assistance between the decided function and the arm (``assist.toml``).
- ``recovery``: what a session does when the task stops progressing.
- ``design``: a person's layout chosen by simulating candidate mappings with their twin.
"""
