"""What a new user reads: the comparison with the paper like beside like, the failure table's short
settings, readable completion-time ticks."""
from __future__ import annotations

import pytest

from tasks.experiments.tables import markdown_comparison, terminal_comparison
from tasks.operators.assist import NONE
from tasks.operators.planner import NO_RECOVERY


def _row(operator: str, time: float, **decisions) -> dict:
    return {"participant": "P1", "operator": operator, "layout": "3-axis", "assist": NONE, "recovery": NO_RECOVERY,
            "completion_time_mean": time, **dict.fromkeys(("relevant_share", "accuracy_all_decisions",
                                                           "accuracy_excused_transitions", "irrelevant_longest_run_ms",
                                                           "longest_error_run_ms")), **decisions}


ROWS = [_row("bomi", 120.0, relevant_share=0.981, accuracy_all_decisions=0.53, accuracy_excused_transitions=0.71,
             irrelevant_longest_run_ms=400.0, longest_error_run_ms=2000.0), _row("joystick", 60.0)]


def test_the_paper_real_time_accuracy_stands_beside_our_share_of_relevant_outputs():
    header, _, line = terminal_comparison(ROWS).splitlines()
    cells = line.split()
    columns = header.split()
    # participant assist BoMI/joy time paper relevant paper err. run ms paper acc. all acc. exc.
    assert cells == ["P1", "none", "2.00", "2.38", "98.1", "%", "99.2", "%", "2000", "290", "53.0", "%", "71.0", "%"]
    assert columns[columns.index("relevant") + 1] == "paper"
    head, _, row = (line.split("|")[1:-1] for line in markdown_comparison(ROWS).splitlines())
    assert head[5].strip() == "relevant outputs" and head[6].strip().startswith("paper real-time accuracy")
    assert (row[5].strip(), row[6].strip()) == ("98.1 %", "99.2 %")
