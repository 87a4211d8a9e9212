"""The dispatcher's table of commands matches what each command module registers."""
from __future__ import annotations

import argparse
import importlib

import pytest

from tasks.cli import COMMAND_MODULES, _modules_for, main


@pytest.mark.parametrize("module", sorted(COMMAND_MODULES))
def test_module_registers_exactly_the_listed_commands(module):
    parser = argparse.ArgumentParser()
    subparsers = parser.add_subparsers(dest="command")
    importlib.import_module(module).register(subparsers)
    assert tuple(subparsers.choices) == COMMAND_MODULES[module]


def test_only_the_owning_module_is_loaded_for_a_command():
    assert _modules_for(["train", "x.csv", "--profile", "P1"]) == ["tasks.cli.chain"]
    assert _modules_for(["--help"]) == list(COMMAND_MODULES)
    assert _modules_for(["no-such-command"]) == list(COMMAND_MODULES)


def test_unknown_command_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["no-such-command"])
    assert exit_info.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
