"""The paper's "reliability over days" table beside ours (same code as `bomi reproduce`).

Writes benchmarks/results/reproduce.md and reproduce.json. Every setting is chosen on day 1
alone (bomi.chain.select_settings); days 2..5 are only tested.
"""
from __future__ import annotations

import json
from pathlib import Path

from bomi.chain_commands import reproduce, reproduction_markdown, reproduction_record
from bomi.dataset import data_dir
from bomi.profiles import load_profile

RESULTS = Path(__file__).resolve().parent / "results"


def main() -> None:
    record = reproduction_record(reproduce(data_dir(), load_profile("P1")))
    table = reproduction_markdown(record)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "reproduce.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / "reproduce.md").write_text("Command: `python benchmarks/reproduce_table.py` (or `bomi reproduce`).\n\n"
                                          + table)
    print(table)


if __name__ == "__main__":
    main()
