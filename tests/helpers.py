"""Small helpers shared by test modules."""
from __future__ import annotations

from pathlib import Path


def edited_copy(source: Path, target: Path, old: str, new: str) -> Path:
    """``source`` written to ``target`` with the first ``old`` replaced by ``new`` (which must occur)."""
    text = source.read_text()
    assert old in text
    target.write_text(text.replace(old, new, 1))
    return target
