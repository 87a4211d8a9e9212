"""Small helpers shared by test modules."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from bomi.errors import BomiError


def edited_copy(source: Path, target: Path, old: str, new: str) -> Path:
    """``source`` written to ``target`` with the first ``old`` replaced by ``new`` (which must occur)."""
    text = source.read_text()
    assert old in text
    target.write_text(text.replace(old, new, 1))
    return target


def assert_one_line_error(load: Callable[[Path], object], path: Path, content: str, fault: str) -> None:
    """``content`` written to ``path`` makes ``load`` raise one BomiError line naming the file and ``fault``."""
    path.write_text(content)
    with pytest.raises(BomiError) as err:
        load(path)
    message = str(err.value)
    assert str(path) in message and fault in message and "\n" not in message
