"""What Fall et al. report: the figures our results are set beside (the one copy of them)."""
from __future__ import annotations

# Table "reliability over days": the day-1 model (FV3) tested on each day, percent correct
# (day 1: 5-fold cross-validation within day 1's recording).
DAY1_MODEL_PCT = {1: 99.58, 2: 99.93, 3: 98.14, 4: 97.50, 5: 98.31}

# The joystick functions of P1's classes c1..c8, in label order (also what a derived profile gives).
CLASS_FUNCTIONS = ("F", "B", "R", "L", "Rr", "Lr", "B1", "B2")

# The assembly task: mean completion times, the BoMI's real-time accuracy (the share of relevant
# outputs) and its longest run of irrelevant outputs (18 outputs).
TASK = {"bomi_time_s": 138.0, "joystick_time_s": 58.0, "realtime_accuracy": 0.992, "longest_irrelevant_run_ms": 290.0}
# P1's three trials per controller behind those means: completion times (s), in trial order.
TRIALS_S = {"bomi": (156.58, 121.08, 135.37), "joystick": (59.36, 64.64, 49.84)}
