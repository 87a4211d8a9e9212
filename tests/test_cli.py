"""The dispatcher's table of commands matches what each command module registers; every option
explains itself; `bomi --help` loads no command module."""
from __future__ import annotations

import argparse
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tasks.cli import COMMAND_MODULES, COMMANDS, _modules_for, build_parser, main


@pytest.mark.parametrize("module", COMMAND_MODULES)
def test_module_registers_exactly_the_listed_commands(module):
    parser = argparse.ArgumentParser()
    subparsers = parser.add_subparsers(dest="command")
    importlib.import_module(module).register(subparsers)
    assert tuple(subparsers.choices) == tuple(name for name, c in COMMANDS.items() if c.module == module)


def test_only_the_owning_module_is_loaded_for_a_command():
    assert _modules_for(["train", "x.csv", "--profile", "P1"]) == ["tasks.cli.chain"]
    assert _modules_for(["--help"]) == []
    assert _modules_for(["no-such-command"]) == []


def _subcommand_options():
    """(command, its parser, action) for every argument of every sub-command but -h."""
    parser = build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, sub in subparsers.choices.items():
        in_required_group = {id(a) for g in sub._mutually_exclusive_groups if g.required for a in g._group_actions}
        for action in sub._actions:
            if not isinstance(action, argparse._HelpAction):
                yield name, sub, action, id(action) in in_required_group


def test_every_option_of_every_command_has_help_that_states_its_default():
    problems = []
    for name, sub, action, in_required_group in _subcommand_options():
        label = f"bomi {name} {'/'.join(action.option_strings) or action.dest}"
        text = sub._get_formatter()._expand_help(action) if action.help else ""
        if not text.strip():
            problems.append(f"{label}: no help")
            continue
        has_default = action.nargs != 0 and action.default is not None and not action.required \
            and not in_required_group  # an option left out means something: the help says what
        if has_default and "default" not in text:
            problems.append(f"{label}: help does not say the default")
        if has_default and isinstance(action.default, (int, float, str)) and str(action.default) not in text:
            problems.append(f"{label}: help does not show the default {action.default!r}")
    assert problems == [], "\n".join(problems)


def test_the_option_walk_sees_every_command_and_catches_an_option_without_help():
    seen = {name for name, *_ in _subcommand_options()}
    assert seen == set(COMMANDS)
    parser = argparse.ArgumentParser()
    action = parser.add_argument("--x", type=int, default=3, help="an x")
    assert str(action.default) not in parser._get_formatter()._expand_help(action)


def test_top_level_help_lists_every_command_without_loading_any():
    code = ("import json, sys\n"
            "from tasks.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = ('sklearn', 'scipy', 'mujoco', 'pinocchio', 'matplotlib', 'dm_control')\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in heavy "
            "or m.startswith('tasks.cli.'))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    *help_lines, loaded = done.stdout.strip().splitlines()
    assert json.loads(loaded) == []
    listing = "\n".join(help_lines)
    for name, command in COMMANDS.items():
        assert name in listing and command.summary.split()[0] in listing


def test_unknown_command_is_a_usage_error(capsys):
    assert main(["no-such-command"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bomi: error: ") and err.count("\n") == 1 and "invalid choice" in err


def test_a_reader_that_goes_away_ends_the_command_quietly():
    """`bomi evaluate ... | head`: the pipe closes while the command writes; no traceback, exit 141 like `cat`."""
    writes_a_lot = ("import sys; from tasks import cli; "
                    "cli._run = lambda argv: print('row\\n' * 100000) or 0; sys.exit(cli.main([]))")
    process = subprocess.Popen([sys.executable, "-c", writes_a_lot], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()
    err = process.stderr.read().decode()
    assert process.wait(timeout=60) == 141
    assert err == ""


HEAVY = ("numpy", "sklearn", "scipy", "mujoco", "pinocchio", "matplotlib", "dm_control", "numba")


def _helps(commands, preload: bool) -> dict[str, tuple[str, list[str]]]:
    """`bomi COMMAND --help` for each command in one fresh interpreter: its text, and the heavy
    libraries loaded by then. ``preload``: every command module imported for real first (the help
    the placeholders must match)."""
    code = ("import contextlib, importlib, io, json, sys\n"
            "from tasks.cli import COMMAND_MODULES, main\n"
            f"if {preload}:\n    [importlib.import_module(m) for m in COMMAND_MODULES]\n"
            "helps = {}\n"
            f"for command in {list(commands)!r}:\n"
            "    out = io.StringIO()\n"
            "    with contextlib.redirect_stdout(out):\n"
            "        assert main([command, '--help']) == 0\n"
            "    heavy = sorted({m.split('.')[0] for m in sys.modules} & set(%r))\n" % (HEAVY,)
            + "    helps[command] = (out.getvalue(), heavy)\n"
            "print(json.dumps(helps))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          env=os.environ | {"COLUMNS": "100"})
    return {command: tuple(value) for command, value in json.loads(done.stdout.strip().splitlines()[-1]).items()}


@pytest.fixture(scope="module")
def real_helps():
    """Every command's real help (every command module imported: ~3 s of CPU), made once: its tests
    share an xdist group, so that one worker makes it rather than each that draws one of them."""
    return _helps(COMMANDS, preload=True)


@pytest.mark.xdist_group("cli-helps")
@pytest.mark.parametrize("command", COMMANDS)
def test_a_commands_help_loads_no_heavy_library_and_says_what_the_real_one_says(command, real_helps):
    (fast, heavy), = _helps([command], preload=False).values()
    assert heavy == [], f"bomi {command} --help loaded {heavy}"
    assert fast == real_helps[command][0]
    assert "_Placeholder" not in fast and "placeholder" not in fast.lower()


def test_every_command_has_a_description(capsys):
    for command in COMMANDS:
        assert main([command, "--help"]) == 0
        text = capsys.readouterr().out
        description = text.split("\n\n")[1]
        assert not description.lstrip().startswith(("positional arguments", "options")), command
        assert len(description.split()) >= 6, (command, description)


def test_a_help_in_this_process_leaves_the_real_libraries_importable(capsys):
    assert main(["train", "--help"]) == 0
    import sklearn.discriminant_analysis
    assert hasattr(sklearn.discriminant_analysis.LinearDiscriminantAnalysis, "fit")
    assert not any(type(m).__name__ == "_Placeholder" for m in list(sys.modules.values()))


def test_sweep_help_shows_the_grid_format_and_how_resuming_works(capsys):
    assert main(["sweep", "--help"]) == 0
    text = capsys.readouterr().out
    for needed in ("participants = [", "seeds = {first = 0, count = 20}", "[vary]", "vote_length = [1, 5, 9]",
                   "Resuming and extending", "only the episodes", "Ctrl-C"):
        assert needed in text, needed


# ------------------------------------------------------------------------------- reruns
def test_evaluate_twice_in_one_directory_replaces_its_own_confusion_png_but_not_a_named_one(
        tmp_path, monkeypatch, capsys, shared_data):
    """The default output is the command's own (replaced, atomically); a file the user names keeps
    the --force rule."""
    from bomi.recording import NodeData, Recording, read_recording, write_recording
    day1, rows = read_recording(shared_data / "day1_testp.mat"), 4000
    write_recording(tmp_path / "r.csv", Recording(
        {i: NodeData(*(getattr(n, s)[:rows] for s in ("acc", "gyro", "mag", "angles"))) for i, n in day1.nodes.items()},
        day1.labels[:rows], source="r.csv"))
    monkeypatch.chdir(tmp_path)
    argv = ["evaluate", "--train", "r.csv", "--test", "r.csv"]
    assert main(argv) == 0
    first = (tmp_path / "confusion.png").stat()
    (tmp_path / "confusion.png").write_bytes(b"\x89PNG stale")
    assert main(argv) == 0
    assert (tmp_path / "confusion.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "confusion.png").stat().st_size > 1000 and first.st_size > 1000
    capsys.readouterr()
    assert main(argv + ["--png", "confusion.png"]) == 2  # named: not replaced without --force
    assert "file exists" in capsys.readouterr().err
    assert main(argv + ["--png", "confusion.png", "--force"]) == 0
    (tmp_path / "link.png").symlink_to(tmp_path / "r.csv")
    assert main(argv + ["--png", "link.png", "--force"]) == 2  # never written through a link
    assert sorted(p.name for p in tmp_path.iterdir()) == ["confusion.png", "link.png", "r.csv"]


@pytest.mark.long
def test_demo_writes_its_figure_film_and_record_and_replaces_only_its_own_directory(tmp_path, monkeypatch, capsys):
    """`bomi demo` as a newcomer runs it (its default directory; a short time limit keeps it quick: the
    episodes stop unfinished, everything is still written); run again it replaces demo_out (the second
    run's episodes are the first run's logs: what is tested is the replacing, not the simulation);
    demo_out named with --out is refused without --force."""
    import tasks.experiments.demo as demo

    monkeypatch.chdir(tmp_path)
    logs, simulate = {}, demo.run_job

    def kept(job, **options):
        logs[job.operator] = simulate(job, **options)
        return logs[job.operator]
    monkeypatch.setattr(demo, "run_job", kept)
    assert main(["demo", "--time-limit", "3"]) == 0
    out = tmp_path / "demo_out"
    assert (out / "timeline.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    film = (out / "bomi_episode.mp4").read_bytes()
    assert len(film) > 1000
    joystick, bomi = json.loads((out / "demo.json").read_text())["episodes"]
    assert (joystick["operator"], bomi["operator"]) == ("joystick", "bomi")
    assert bomi["failure"].startswith("time limit 3") and bomi["decisions"] > 100
    assert any(line.split()[:3] == ["P1", "bomi", "0/1"] for line in capsys.readouterr().out.splitlines() if line.strip())

    def replayed(job, video=None, **options):
        if video is not None:
            Path(video).write_bytes(film)
        return logs[job.operator]
    monkeypatch.setattr(demo, "run_job", replayed)
    (out / "demo.json").write_text("stale")
    assert main(["demo", "--time-limit", "3"]) == 0
    assert json.loads((out / "demo.json").read_text())["episodes"]
    assert sorted(p.name for p in out.iterdir()) == ["bomi_episode.mp4", "demo.json", "timeline.png"]
    capsys.readouterr()
    assert main(["demo", "--time-limit", "1", "--out", "demo_out"]) == 2  # a directory the user names: --force
    assert "file exists" in capsys.readouterr().err


# ------------------------------------------------------------------------------- figures
def _drawn(monkeypatch, draw):
    """The figure ``draw`` saves (its axes kept for inspection)."""
    import matplotlib.pyplot as plt
    kept = {}
    real = plt.Figure.savefig
    monkeypatch.setattr(plt.Figure, "savefig", lambda fig, path, **kw: (kept.setdefault("fig", fig), real(fig, path, **kw)))
    draw()
    return kept["fig"]


def test_a_confusion_matrix_is_coloured_by_the_share_of_its_row_and_names_the_classes(tmp_path, monkeypatch):
    """Neutral's thousands of windows must not hide a rare class's errors: 271 of 294 c8 windows
    called neutral read 92 %, as dark as a perfect neutral row's 100 % nearly."""
    import numpy as np
    from tasks.experiments.figures import confusion_figure
    counts = np.array([[8232, 0, 0], [7, 1753, 4], [271, 0, 23]])
    names = ["c0 neutral posture", "c7 B1: right shoulder", "c8 B2: left shoulder"]
    fig = _drawn(monkeypatch, lambda: confusion_figure(tmp_path / "c.png", [("day3", counts)], names))
    ax = fig.axes[0]
    shown = ax.images[0].get_array()
    np.testing.assert_allclose(shown, 100 * counts / counts.sum(axis=1, keepdims=True))
    assert [t.get_text() for t in ax.get_xticklabels()] == names
    assert [t.get_text() for t in ax.get_yticklabels()] == [f"{n} ({c:,})" for n, c in zip(names, counts.sum(axis=1))]
    texts = [t.get_text() for t in ax.texts]
    assert "92%" in texts and "271" in texts and "8,232" in texts


def test_the_timeline_explains_every_joystick_function_a_shipped_profile_uses():
    from bomi.profiles import load_profile
    from tasks.stacking.timeline import FUNCTION_WORDS
    functions = {cls.function for name in ("P1", "P4", "P5") for cls in load_profile(name).classes} - {"neutral"}
    assert functions <= set(FUNCTION_WORDS)
