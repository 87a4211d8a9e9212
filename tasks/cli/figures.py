"""Until tasks/cli/sweep.py moves to tasks/experiments/ (helper "infra"), which should then import
these from tasks.experiments.figures: delete this file at that merge."""
from tasks.experiments.figures import completion_time_figure, metric_figure  # noqa: F401
