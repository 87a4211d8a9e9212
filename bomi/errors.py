"""Errors the command line reports as one line (no traceback) with a non-zero exit."""


class BomiError(Exception):
    """Bad user input: a malformed recording, profile, model file or serial stream.

    The message names the file (or port) and what is wrong with it.
    """
