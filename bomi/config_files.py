"""Loading the project's TOML configuration files (profiles, participants, operators)."""
from __future__ import annotations

import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from bomi.errors import BomiError

T = TypeVar("T")


def load_toml(path_or_name: str | Path, shipped_dir: Path, kind: str, parse: Callable[[dict, str], T]) -> T:
    """Parse a TOML file given by path, or a shipped one by bare name (``"P1"`` -> ``shipped_dir/P1.toml``).

    ``parse(data, source)`` raises ValueError for invalid content; every failure becomes a one-line
    BomiError that names the file.
    """
    path = Path(path_or_name)
    shipped = shipped_dir / f"{path_or_name}.toml"
    if not path.suffix and shipped.is_file():
        path = shipped
    if not path.is_file():
        names = ", ".join(sorted(p.stem for p in shipped_dir.glob("*.toml")))
        raise BomiError(f"{path}: no such {kind} file (shipped: {names})")
    try:
        return parse(tomllib.loads(path.read_text(encoding="utf-8")), str(path))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise BomiError(f"{path}: not valid TOML ({exc})") from None
    except OSError as exc:
        raise BomiError(f"{path}: cannot be read ({exc.strerror})") from None
    except ValueError as exc:
        raise BomiError(f"{path}: {exc}") from None
