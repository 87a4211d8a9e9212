"""The paper's "reliability over days" table beside ours (same code as `bomi reproduce`): the README's
rows "day-1 model on real P1 days 2, 3, 4, 5" and "every ordered pair of the five real days".

    python benchmarks/reproduce_table.py [--data DIR]

Writes benchmarks/results/reproduce.md, reproduce.json, reproduce.png (the day-1 model) and
reproduce_day_pairs.png (the 5 x 5 day-pair matrices). Every setting is chosen on the training day alone
(bomi.chain.select_settings); the other days are only tested.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bomi.dataset import data_dir
from bomi.profiles import load_profile
from bomi.reproduce import DAYS, day_pairs, read_days, reproduce, reproduction_markdown, reproduction_record

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


def save_day_pairs_figure(record: dict, path: Path) -> None:
    """One heat map per variant: accuracy of the row day's model on the column day."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pairs = record["day_pairs"]
    fig, axes = plt.subplots(1, len(pairs), figsize=(3.6 * len(pairs), 3.9), squeeze=False)
    for ax, (name, p) in zip(axes[0], pairs.items()):
        matrix = np.full((len(DAYS), len(DAYS)), np.nan)
        for i, a in enumerate(DAYS):
            for j, b in enumerate(DAYS):
                if a != b:
                    matrix[i, j] = 100 * p["accuracy"][f"{a}->{b}"]
        image = ax.imshow(matrix, vmin=89, vmax=100, cmap="viridis")
        for i in range(len(DAYS)):
            for j in range(len(DAYS)):
                if i != j:
                    ax.text(j, i, f"{matrix[i, j]:.1f}", ha="center", va="center", fontsize=7,
                            color="white" if matrix[i, j] < 96 else "black")
        ax.set_xticks(range(len(DAYS)), [str(d) for d in DAYS])
        ax.set_yticks(range(len(DAYS)), [str(d) for d in DAYS])
        ax.set_xlabel("test day")
        if ax is axes[0][0]:
            ax.set_ylabel("training day")
        ax.set_title(f"{name}\nmean {100 * p['mean']:.2f}, worst {100 * p['worst']:.2f}", fontsize=9)
    fig.colorbar(image, ax=axes[0].tolist(), shrink=0.8, label="accuracy (%)")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, help="dataset directory (default: BOMI_DATA_DIR or ../shared/data/...)")
    args = parser.parse_args()
    profile, recordings = load_profile("P1"), read_days(args.data or data_dir())
    record = reproduction_record(reproduce(recordings, profile), day_pairs(recordings, profile))
    table = reproduction_markdown(record)
    RESULTS.mkdir(exist_ok=True)
    save_figure(record, RESULTS / "reproduce.png")
    save_day_pairs_figure(record, RESULTS / "reproduce_day_pairs.png")
    (RESULTS / "reproduce.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / "reproduce.md").write_text("Command: `python benchmarks/reproduce_table.py` (or `bomi reproduce`).\n\n"
                                          + table)
    print(table)


if __name__ == "__main__":
    main()
