"""Errors the command line reports as one line (no traceback) with a non-zero exit."""


class SimError(Exception):
    """Bad user input to the simulation: a malformed model file, scene or task configuration.

    The message names the file and what is wrong with it.
    """
