"""The BoMI signal chain: frames -> fusion -> windows/features -> classifier -> joystick commands."""
