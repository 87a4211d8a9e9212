"""The paper's "reliability over days" table beside ours (same code as `bomi reproduce`).

Writes benchmarks/results/reproduce.md, reproduce.json and reproduce.png. Every setting is chosen on day 1
alone (bomi.chain.select_settings); days 2..5 are only tested.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bomi.dataset import data_dir
from bomi.profiles import load_profile
from bomi.reproduce import reproduce, reproduction_markdown, reproduction_record

RESULTS = Path(__file__).resolve().parent / "results"


def save_figure(record: dict, path: Path) -> None:
    """Per-day accuracy of the day-1 model: the paper's FV3 beside ours for FV1, FV2, FV3."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    days = sorted(int(d) for d in record["paper_day1_model_fv3"])
    series = {"paper FV3": [record["paper_day1_model_fv3"][d] for d in days]}
    for kind, result in record["features"].items():
        series[kind] = [100 * result["within_day1_cv_accuracy"]] + [100 * result["days"][d]["accuracy"] for d in days[1:]]
    fig, ax = plt.subplots(figsize=(7, 3.8))
    width = 0.8 / len(series)
    for k, (name, values) in enumerate(series.items()):
        ax.bar(np.arange(len(days)) + (k - (len(series) - 1) / 2) * width, values, width, label=name)
    ax.set_xticks(range(len(days)), ["day 1\n(CV within)"] + [f"day {d}" for d in days[1:]])
    ax.set_ylim(96, 100.2)
    ax.set_ylabel("accuracy (%)")
    ax.set_title("P1, model trained on day 1", fontsize=10)
    ax.legend(ncol=4, fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    record = reproduction_record(reproduce(data_dir(), load_profile("P1")))
    table = reproduction_markdown(record)
    RESULTS.mkdir(exist_ok=True)
    save_figure(record, RESULTS / "reproduce.png")
    (RESULTS / "reproduce.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / "reproduce.md").write_text("Command: `python benchmarks/reproduce_table.py` (or `bomi reproduce`).\n\n"
                                          + table)
    print(table)


if __name__ == "__main__":
    main()
