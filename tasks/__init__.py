"""The stacking task, its operators (scripted joystick, BoMI virtual participant) and metrics."""
