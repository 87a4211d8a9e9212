"""The largest values any run accepts: seeds, seed counts, durations (the command line's options
and the trial files are checked against the same numbers)."""

# Longest time any option may ask for: a day, longer than any session, capture or episode; it keeps
# arithmetic on times (sample counts, schedules) finite.
MAX_SECONDS = 86_400.0
# The shortest episode worth simulating: a second (the scripted user's reaction alone takes 0.3 s);
# shorter ones (1e-300 s) are typing mistakes, not experiments.
MIN_TIME_LIMIT_S = 1.0
# Seeds: numpy's and MuJoCo's are 32-bit; no run of this project needs more than ten thousand of them
# (far beyond what this machine, or a cluster in a week, runs), and more would exhaust memory listing them.
MAX_SEED = 2**32 - 1
MAX_SEEDS = 10_000
