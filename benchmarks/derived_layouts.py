"""Does every synthetic new person's derived profile reach the stacking task's functions? (issue 41)

For each population person (tasks/participants/population.py; development people by default), both
passes in one logger file as `benchmarks/two_pass_file.py` writes it, the profile `bomi train` /
`bomi twin` derive from it (bomi/derived.py), and whether the scripted stacking user can drive it
(tasks.stacking.episode.profile_controls, what `bomi benchmark` checks before any episode: every direction of
the layout, and the mode button B1 or, without a button, the automatic mode switching the user rests
and waits for). "reached" says only that; whether the person then succeeds is for episodes
(`bomi benchmark --participants TWIN.toml`). No episode is run.

    python benchmarks/derived_layouts.py --people 30 --first 0
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bomi.derived import derive_profile  # noqa: E402
from bomi.errors import BomiError  # noqa: E402
from bomi.passes import pass_bounds, split_passes  # noqa: E402
from tasks.stacking.episode import profile_controls  # noqa: E402
from tasks.participants.population import draw_person, one_file  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--people", type=int, default=30)
    parser.add_argument("--first", type=int, default=0, help="first population seed (default %(default)s)")
    args = parser.parse_args()
    reached: Counter = Counter()
    total: Counter = Counter()
    for seed in range(args.first, args.first + args.people):
        person = draw_person(seed)
        rec = one_file(person)
        passes = split_passes(rec, pass_bounds(rec))
        profile = derive_profile(passes)
        classes = len(profile.classes)
        total[classes] += 1
        try:
            controls = profile_controls(profile)
            reached[classes] += 1
            outcome = f"reached: {controls.label}"
        except BomiError as exc:
            outcome = f"NOT reached: {str(exc).split('; ')[-1]}"
        print(f"person {seed}: {classes} classes, {len(profile.nodes)} node(s), {len(passes)} passes found, layout "
              f"{profile.joystick_layout}{' + ' + ', '.join(profile.assist) if profile.assist else ''}: {outcome}")
    print("classes: reached / people: " + ", ".join(f"{c}: {reached[c]}/{total[c]}" for c in sorted(total)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
