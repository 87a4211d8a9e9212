"""The simulated Kinova JACO arm: MuJoCo scene, Pinocchio differential IK, joystick modes, rendering."""
import os

# Headless rendering: choose EGL before mujoco or dm_control is first imported (they read it then).
os.environ.setdefault("MUJOCO_GL", "egl")
