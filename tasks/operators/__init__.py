"""Who and what drives the arm's joystick (robosuite's controllers and input devices, apart from the task).

Map:

- ``planner``: the scripted JACO user, a pure plan from what the person sees; ``operator.toml``
  its parameters (configuration as data).
- ``human``: the human operator model around it (perception and timing; ``human.toml``).
- ``stick``: classifier decisions -> joystick state, shared by simulated and live BoMI.
- ``assist``: assistance between the decided function and the arm (``assist.toml``).
- ``recovery``: what a session does when the task stops progressing.
- ``design``: a person's layout chosen by simulating candidate mappings with their twin.
"""
