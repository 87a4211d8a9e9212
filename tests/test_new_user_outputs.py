"""What a new user reads: the comparison with the paper like beside like, the failure table's short
settings, readable completion-time ticks."""
from __future__ import annotations

import pytest

from tasks.experiments.tables import markdown_comparison, terminal_comparison
from tasks.operators.assist import NONE
from tasks.stacking.vocabulary import NO_RECOVERY


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
    # participant assist BoMI/joy time paper relevant paper irr. run ms paper acc. all acc. exc.
    assert cells == ["P1", "none", "2.00", "2.38", "98.1", "%", "99.2", "%", "400", "290", "53.0", "%", "71.0", "%"]
    assert columns[columns.index("relevant") + 1] == "paper" and columns[columns.index("run") + 2] == "paper"
    head, _, row = (line.split("|")[1:-1] for line in markdown_comparison(ROWS).splitlines())
    assert head[5].strip() == "relevant outputs" and head[6].strip().startswith("paper real-time accuracy")
    assert (row[5].strip(), row[6].strip()) == ("98.1 %", "99.2 %")
    assert head[7].strip() == "longest irrelevant run (ms)" and (row[7].strip(), row[8].strip()) == ("400", "290")


@pytest.mark.parametrize("low, high, expected", [(70.0, 106.0, ["70", "80", "90", "100"]),
                                                 (40.0, 300.0, ["50", "70", "100", "200", "300"])])
def test_a_log_time_axis_labels_a_narrow_range_at_readable_ticks(low, high, expected):
    import matplotlib.pyplot as plt

    from tasks.experiments.figures import label_log_axis
    fig, ax = plt.subplots()
    ax.set_yscale("log")
    ax.scatter([0, 1], [low, high])
    label_log_axis(ax.yaxis, low, high)
    fig.canvas.draw()
    shown = [t.get_text() for t in ax.get_yticklabels() if low * 0.9 <= t.get_position()[1] <= high * 1.1]
    plt.close(fig)
    assert shown == expected


def test_the_failure_table_shows_only_the_settings_a_sweep_varied():
    from tasks.experiments.tables import terminal_mechanisms

    common = {"participant": "P1", "operator": "bomi", "time_limit": 300.0, "operator_file": "operator",
              "participant.spasm.rate_per_min": 0.5, "profile.some_long_setting_name": [1, 2, 3]}
    records = [{"participant": "P1", "operator": "bomi", "seed": seed, "success": seed != 2, "completion_time": 90.0,
                "sim_time": 300.0 if seed == 2 else 90.0, "recovery": NO_RECOVERY,
                "stuck": {"mechanism": "cube lost"} if seed == 2 else None,
                "settings": common | {"seed": seed, "profile.vote_length": vote}}
               for vote in (1, 3) for seed in (1, 2, 3)]
    header, _, *rows = terminal_mechanisms(records).splitlines()[1:]
    assert len(rows) == 2   # one per cell, its seeds pooled
    assert [row.split()[:3] for row in rows] == [["P1", "bomi", "vote_length=1"], ["P1", "bomi", "vote_length=3"]]
    assert all(row.split()[3:5] == ["1/3", "0/3"] for row in rows)
    assert header.index("failed") - header.index("settings") == len("vote_length=1") + 2   # the column's width


def test_files_are_shown_by_name_in_tables_and_figures(tmp_path):
    import matplotlib.pyplot as plt

    from tasks.experiments import figures
    from tasks.experiments.summary import shown_name
    twin = str(tmp_path / "people" / "me_twin.toml")   # a sweep resolves a grid's files to absolute paths
    assert shown_name(twin) == "me_twin.toml" and shown_name("P1") == "P1"
    rows = [{**row, "participant": twin} for row in ROWS]
    assert terminal_comparison(rows).splitlines()[2].startswith("me_twin.toml ")
    seen = {}
    original = plt.Axes.set_xticks

    def spy(self, ticks, labels=None, **kwargs):
        seen["labels"] = labels
        return original(self, ticks, labels, **kwargs)

    record = {"operator": "bomi", "success": True, "completion_time": 80.0, "sim_time": 80.0}
    plt.Axes.set_xticks = spy
    try:
        figures.completion_time_figure([(f"{twin}\nbomi", [record])], tmp_path / "t.png", "t")
    finally:
        plt.Axes.set_xticks = original
    assert seen["labels"] == ["me_twin.toml\nbomi"]


def test_a_twin_names_its_profile_relative_to_its_own_file(tmp_path):
    import argparse

    from tasks.cli.twin import _profile_for
    (tmp_path / "layouts").mkdir()
    profile = tmp_path / "layouts" / "best.toml"
    from bomi.profiles import load_profile, save_profile
    save_profile(profile, load_profile("P1"))
    args = argparse.Namespace(profile=str(profile), out=tmp_path / "twins" / "me_twin.toml")
    _, reference = _profile_for(args, [], None)
    assert reference == "../layouts/best.toml"


def test_evaluate_names_the_class_another_day_reads_as_another(shared_data, tmp_path, capsys):
    """P1's day 1 with a derived profile, tested on day 3: 91.72 % overall (above the 85 % of the overall
    warning) while c8 (B1) is read as c5 (L) in all its 294 windows."""
    from tasks.cli import main
    model, profile = tmp_path / "me.json", tmp_path / "me.toml"
    assert main(["train", str(shared_data / "day1_testp.mat"), "--out", str(model), "--save-profile", str(profile)]) == 0
    capsys.readouterr()
    assert main(["evaluate", "--train", str(model), "--profile", str(profile), "--test",
                 str(shared_data / "day3_testp.mat"), "--png", str(tmp_path / "c.png")]) == 0
    out = capsys.readouterr().out
    assert "accuracy 91.72 % over 16170 windows" in out
    assert "on the holds: 91.72 %, the same windows (the recording keeps only its holds" in out
    warning, = [line for line in out.splitlines() if line.startswith("warning:")]
    assert ": 2 class(es) below 85 % of their windows: c8 (B1) read as itself in 0 % of its 294 windows, as c5 (L) " \
           "in 100 %; c4 (R) read as itself in 43 % of its 1470 windows, as c0 (neutral) in 56 %" in warning
