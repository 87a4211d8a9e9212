"""Loading the project's TOML configuration files (profiles, participants, operators)."""
from __future__ import annotations

import copy
import tomllib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from bomi.errors import BomiError

T = TypeVar("T")


def load_toml(path_or_name: str | Path, shipped_dir: Path, kind: str, parse: Callable[[dict, str], T],
              overrides: Mapping[str, Any] | None = None) -> T:
    """Parse a TOML file given by path, or a shipped one by bare name (``"P1"`` -> ``shipped_dir/P1.toml``).

    ``overrides`` maps dotted keys (``"post_processing.vote_length"``) to values that replace (or add)
    the file's before it is parsed, so an edited setting is validated like one written in the file.
    ``parse(data, source)`` raises ValueError for invalid content; every failure becomes a one-line
    BomiError that names the file (and the overrides, when there are any).
    """
    path = Path(path_or_name)
    shipped = shipped_dir / f"{path_or_name}.toml"
    if not path.suffix and shipped.is_file():
        path = shipped
    if not path.is_file():
        names = ", ".join(sorted(p.stem for p in shipped_dir.glob("*.toml")))
        raise BomiError(f"{path}: no such {kind} file (shipped: {names})")
    source = str(path) if not overrides else f"{path} with {', '.join(f'{k} = {v!r}' for k, v in overrides.items())}"
    try:
        return parse(with_overrides(tomllib.loads(path.read_text(encoding="utf-8")), overrides or {}), source)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise BomiError(f"{path}: not valid TOML ({exc})") from None
    except OSError as exc:
        raise BomiError(f"{path}: cannot be read ({exc.strerror})") from None
    except ValueError as exc:
        raise BomiError(f"{source}: {exc}") from None


def with_overrides(data: dict, overrides: Mapping[str, Any]) -> dict:
    """A copy of the TOML document ``data`` with each dotted key of ``overrides`` set to its value;
    ValueError when a key runs through something that is not a table."""
    data = copy.deepcopy(data)
    for dotted, value in overrides.items():
        *tables, leaf = dotted.split(".")
        table = data
        for name in tables:
            table = table.setdefault(name, {})
            if not isinstance(table, dict):
                raise ValueError(f"{dotted}: '{name}' is not a table")
        table[leaf] = value
    return data
