"""A synthetic new person's calibration as the original logger writes it: both passes of the protocol in
one .mat file, the clock pausing 6.2 s between them (issue 41's real file). Development people only.

    python benchmarks/two_pass_file.py --person 5 --out me.mat   # six head motions + neutral
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bomi.recording import write_logger_mat  # noqa: E402
from tasks.participants.population import draw_person, one_file  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--person", type=int, default=5, help="population seed (default %(default)s: six motions and the neutral posture, one head node)")
    parser.add_argument("--out", type=Path, required=True, help=".mat file to write")
    args = parser.parse_args()
    person = draw_person(args.person)
    rec = one_file(person)
    write_logger_mat(args.out, rec)
    print(f"person {args.person}: {person.n_classes} classes, node(s) {list(rec.node_indices)}, {len(rec)} rows: "
          f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
