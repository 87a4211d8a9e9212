"""Loading the project's TOML configuration files (profiles, participants, operators)."""
from __future__ import annotations

import copy
import math
import tomllib
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from bomi.errors import BomiError
from bomi.files import read_config_text

T = TypeVar("T")


def load_toml(path_or_name: str | Path, shipped_dir: Path, kind: str, parse: Callable[[dict, str], T],
              overrides: Mapping[str, Any] | None = None) -> T:
    """Parse a TOML file given by path, or a shipped one by bare name (``"P1"`` -> ``shipped_dir/P1.toml``).

    ``overrides`` maps dotted keys (``"post_processing.vote_length"``) to values that replace (or add)
    the file's before it is parsed, so an edited setting is validated like one written in the file.
    ``parse(data, source)`` raises ValueError for invalid content; every failure becomes a one-line
    BomiError that names the file (and the overrides, when there are any).
    """
    path = config_path(path_or_name, shipped_dir)
    if not path.exists():
        names = ", ".join(sorted(p.stem for p in shipped_dir.glob("*.toml")))
        raise BomiError(f"{path}: no such {kind} file (shipped: {names})")
    source = str(path) if not overrides else f"{path} with {', '.join(f'{k} = {v!r}' for k, v in overrides.items())}"
    document = parse_toml(path, kind)
    try:
        data = with_overrides(document, overrides or {})
        check_numbers(data)
        return parse(data, source)
    except ValueError as exc:
        raise BomiError(f"{source}: {exc}") from None


def config_path(path_or_name: str | Path, shipped_dir: Path) -> Path:
    """The file a configuration is read from: a shipped one by bare name (``"P1"`` ->
    ``shipped_dir/P1.toml``), else the path as given."""
    path = Path(path_or_name)
    shipped = shipped_dir / f"{path_or_name}.toml"
    return shipped if not path.suffix and shipped.is_file() else path


def beside(reference: str, config: Path) -> str:
    """A file named inside the configuration file ``config`` (a TOML file, by its suffix) resolved
    against ``config``'s directory, not the working directory; any other reference (a shipped
    name) as it is."""
    if Path(reference).suffix.lower() != ".toml":
        return reference
    return str((config.parent / reference).resolve())


# Tables and arrays nested deeper than this are no configuration of this project (the deepest
# shipped one is 3: a table of arrays of tables); deeper would exhaust Python's recursion.
MAX_TOML_DEPTH = 16


def parse_toml(path: Path, kind: str) -> dict:
    """The TOML document of the configuration file ``path`` (a regular file of at most
    MAX_CONFIG_BYTES, nested at most MAX_TOML_DEPTH deep); every fault a one-line BomiError."""
    text = read_config_text(path, kind)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise BomiError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:
        raise BomiError(f"{path}: not a {kind} file (nested deeper than {MAX_TOML_DEPTH} levels)") from None
    if _depth(data) > MAX_TOML_DEPTH:
        raise BomiError(f"{path}: not a {kind} file (nested deeper than {MAX_TOML_DEPTH} levels)")
    return data


def _depth(value: Any) -> int:
    """How deep tables and arrays nest in ``value`` (iterative: the depth is not known yet)."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, (dict, list)):
            deepest = max(deepest, depth + 1)
            stack.extend((child, depth + 1) for child in (value.values() if isinstance(value, dict) else value))
    return deepest


# No setting of this project is near a million in size (the largest shipped one is the video width,
# 640): a number beyond this is a garbled value, and would overflow the arithmetic it feeds.
MAX_ABS_SETTING = 1e6


def check_numbers(data: Any, where: str = "") -> None:
    """ValueError naming the key of the first number that is not finite (TOML allows nan and inf) or
    beyond +-MAX_ABS_SETTING."""
    if isinstance(data, dict):
        for key, value in data.items():
            check_numbers(value, f"{where}.{key}" if where else str(key))
    elif isinstance(data, list):
        for k, value in enumerate(data):
            check_numbers(value, f"{where}[{k}]")
    elif isinstance(data, (int, float)) and not isinstance(data, bool):
        if not math.isfinite(data) or abs(data) > MAX_ABS_SETTING:
            raise ValueError(f"{where} = {data!r}: not a finite number within +-{MAX_ABS_SETTING:g}")


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


# The checks every configuration parser uses (profiles, participants, operators): each raises a
# ValueError saying where (``where``: the table, e.g. "[timing]" or "classes[2]") and what is wrong.
def check_table(table: Any, where: str, allowed: Iterable[str], required: Iterable[str] = ()) -> dict:
    """``table`` itself, once it is a table with no key outside ``allowed`` and every key of ``required``."""
    if table is None:
        raise ValueError(f"{where}: missing table")
    if not isinstance(table, dict):
        raise ValueError(f"{where}: must be a table")
    allowed = set(allowed)
    unknown, missing = sorted(set(table) - allowed), sorted(set(required) - set(table))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {', '.join(unknown)} (allowed: {', '.join(sorted(allowed))})")
    if missing:
        raise ValueError(f"{where}: missing key(s) {', '.join(missing)}")
    return table


def typed(table: dict, key: str, kind: type | tuple[type, ...], where: str, default: Any = ...) -> Any:
    """``table[key]`` if it is of ``kind`` (a boolean never counts as a number), else ``default``
    when the key is absent and there is one."""
    if key not in table:
        if default is ...:
            raise ValueError(f"{where}: missing '{key}'")
        return default
    value = table[key]
    if isinstance(value, bool) is not (kind is bool) or not isinstance(value, kind):
        raise ValueError(f"{where}: '{key}' has the wrong type ({type(value).__name__})")
    return value


def number(table: dict, key: str, where: str, low: float = -math.inf, high: float = math.inf,
           default: Any = ...) -> float:
    """``table[key]`` as a float, if it is a finite number in [low, high]."""
    if key not in table and default is not ...:
        return default
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not low <= value <= high:
        raise ValueError(f"{where}: '{key}' must be a number in [{low}, {high}], got {value!r}")
    return float(value)
