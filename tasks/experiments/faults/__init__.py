"""Faults made and run through the command line, the corpora `python benchmarks/faults.py` runs (the README's
rows "damaged files and option values", "session faults" and "`bomi live`"): every command runs as
``python -m tasks.cli`` in a process of its own (``runs``), on files made in a temporary directory.

- ``runs``: the command line run with a timeout, a file-size limit or a signal at a given line.
- ``bad_input``: damaged files and bad option values through every command.
- ``sessions``: the human-in-the-loop session's faults (kills, signals, a full disk, damaged files).
- ``live``: the live loop's safety bars end to end (a virtual participant's frames on a pty).
"""
