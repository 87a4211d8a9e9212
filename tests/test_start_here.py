"""docs/start_here.md's path, run as a user would: every `bomi ...` line of its code blocks, in order,
in a temporary directory, so that the page cannot drift from the code.

Two kinds of line are not run as written, each by a rule stated here:

- ``REDUCTIONS``: the long ones run on fewer seeds and shorter episodes (their options replaced, or
  added when the page leaves them to the default). The page shows the same command with its own
  values; nothing else of the line changes.
- ``NEEDS_A_PERSON``: a line reading a person's stream (``--port``) cannot run here; it is parsed by
  the command line (every option and value it shows must exist) but not run.

The lines run in one process (``tasks.cli.main``), each checked to exit 0 and to write what it names
(--out)."""
from __future__ import annotations

import re
import shlex
import time
from pathlib import Path

import pytest

from tasks.cli import _modules_for, build_parser, main

DOC = Path(__file__).resolve().parents[1] / "docs" / "start_here.md"

# command -> options set to these values (added when absent): the same path on 1 seed and 5-s episodes
REDUCTIONS = {
    "design": {"--seeds": "1", "--time-limit": "5", "--jobs": "1"},
    "benchmark": {"--seeds": "1", "--time-limit": "5", "--jobs": "1"},
    "trial": {"--trials": "1", "--time-limit": "5", "--countdown": "0", "--headless": None},
}
NEEDS_A_PERSON = "--port"   # a line with this option reads a live base-station stream: parsed, not run


def doc_commands(text: str) -> list[list[str]]:
    """The `bomi` lines of the page's code blocks, in order, as argument lists (a trailing `# ...` dropped)."""
    blocks = re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.S | re.M)
    return [shlex.split(line, comments=True)[1:] for block in blocks for line in block.splitlines()
            if line.startswith("bomi ")]


def reduced(argv: list[str]) -> list[str]:
    """``argv`` with its command's REDUCTIONS applied."""
    out = list(argv)
    for option, value in REDUCTIONS.get(argv[0], {}).items():
        if option in out:
            if value is not None:
                out[out.index(option) + 1] = value
        else:
            out += [option] if value is None else [option, value]
    return out


def test_doc_commands_are_read_as_a_shell_would():
    text = "x\n```\nbomi train a.csv --out m.json   # a comment\nnot bomi\n```\n`bomi inline` is prose\n"
    assert doc_commands(text) == [["train", "a.csv", "--out", "m.json"]]
    assert reduced(["design", "t.toml", "--seeds", "5"]) == ["design", "t.toml", "--seeds", "1", "--time-limit", "5",
                                                             "--jobs", "1"]


@pytest.mark.xdist_group("start-here")
@pytest.mark.long
def test_the_documented_path_runs_end_to_end(tmp_path, monkeypatch, capsys):
    commands = doc_commands(DOC.read_text(encoding="utf-8"))
    assert [c[0] for c in commands if NEEDS_A_PERSON not in c][:3] == ["synth", "train", "twin"]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    start = time.monotonic()
    ran = []
    for argv in commands:
        if NEEDS_A_PERSON in argv:   # every option it shows exists, with a value the parser takes
            build_parser(_modules_for(argv)).parse_args(argv)
            continue
        argv = reduced(argv)
        code = main(argv)
        out = capsys.readouterr()
        assert code == 0, f"bomi {shlex.join(argv)} exited {code}:\n{out.out[-2000:]}\n{out.err[-2000:]}"
        if "--out" in argv:
            assert Path(argv[argv.index("--out") + 1]).exists(), f"bomi {shlex.join(argv)} wrote no --out"
        ran.append((argv[0], out.out))
    assert [name for name, _ in ran] == ["synth", "train", "twin", "design", "twin", "benchmark", "train", "synth",
                                         "evaluate", "trial"]
    # what the page says each step gives
    evaluate_out = dict(ran)["evaluate"]
    assert "on the holds:" in evaluate_out and "IN-SAMPLE" not in evaluate_out
    assert 'profile = "best.toml"' in (tmp_path / "me_twin.toml").read_text()   # relative to the twin's file
    assert (tmp_path / "me_twin.profile.toml").is_file() and (tmp_path / "session" / "trials.jsonl").is_file()
    print(f"start_here's path: {len(ran)} commands in {time.monotonic() - start:.0f} s")
