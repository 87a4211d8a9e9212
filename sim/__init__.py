"""The simulated Kinova JACO arm: MuJoCo scene, Pinocchio differential IK, joystick modes, rendering."""
