"""The one loader of the project's TOML configuration files (profiles, participants, operators, the
human model, the assistance, the simulation, sweep grids): a file -> its TOML document -> validated
frozen dataclasses, every fault one line, ``path: [section] key: what is wrong``.

``load_toml`` reads the file (a path, or a shipped file by bare name), applies overrides and rejects
numbers no setting takes (``check_numbers``); its ``parse`` builds the dataclasses. A section whose
keys are the fields of a dataclass is read by ``from_table`` (each value checked against the field's
type hint, then the dataclass's ``__post_init__`` checks, which raise ValueError: ``positive``,
``at_most``, ``within``), and a document by a dataclass whose fields are such sections (optional
ones, arrays of them, tables of any keys). A value in a format its type does not say (a comma list
of names, a list or a range of seeds) is read by the function its ``Annotated`` hint names.
``parse_text`` reads a configuration's text (one about to be written) the same way; ``parse_toml``
only the document (a sweep grid, whose seeds go beyond ``check_numbers``' bound). A record of every
key of a file's sections at once (the operator's, the human model's) subclasses their dataclasses
and is made by ``section_keys``.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
import types
import typing
from collections.abc import Callable, Mapping
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
    try:
        return toml_document(read_config_text(path, kind), kind)
    except ValueError as exc:
        raise BomiError(f"{path}: {exc}") from None


def parse_text(text: str, source: str, kind: str, parse: Callable[[dict, str], T]) -> T:
    """``load_toml`` of a configuration's text rather than its file (one about to be written is
    checked so): the document (``toml_document``), its numbers (``check_numbers``), then ``parse``;
    every fault a ValueError."""
    data = toml_document(text, kind)
    check_numbers(data)
    return parse(data, source)


def toml_document(text: str, kind: str) -> dict:
    """The TOML document in ``text``, nested at most MAX_TOML_DEPTH deep; ValueError otherwise."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"not valid TOML ({exc})") from None
    except RecursionError:
        raise ValueError(f"not a {kind} file (nested deeper than {MAX_TOML_DEPTH} levels)") from None
    if _depth(data) > MAX_TOML_DEPTH:
        raise ValueError(f"not a {kind} file (nested deeper than {MAX_TOML_DEPTH} levels)")
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
    """ValueError naming the key (``[section] key``) of the first number that is not finite (TOML
    allows nan and inf) or beyond +-MAX_ABS_SETTING."""
    if isinstance(data, dict):
        for key, value in data.items():
            check_numbers(value, f"{where}.{key}" if where else str(key))
    elif isinstance(data, list):
        for k, value in enumerate(data):
            check_numbers(value, f"{where}[{k}]")
    elif isinstance(data, (int, float)) and not isinstance(data, bool):
        if not math.isfinite(data) or abs(data) > MAX_ABS_SETTING:
            table, dot, key = where.rpartition(".")
            raise ValueError(f"{f'[{table}] ' if dot else ''}{key}: {data!r} is not a finite number within "
                             f"+-{MAX_ABS_SETTING:g}")


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


# ------------------------------------------------------------------------------ tables as dataclasses
def from_table(cls: type[T], table: Any, section: str | None = None, **given: Any) -> T:
    """A ``cls`` dataclass from a TOML table: the document itself (``section`` None) or the table
    ``[section]``. No key outside the fields of ``cls`` (but those ``given``), every field without a
    default present, each value read by its field's type hint (``_read``). Then ``cls``'s own checks
    (its ``__post_init__``, raising ValueError). ValueError ``[section] key: ...``, one line."""
    where = f"[{section}] " if section else ""
    if not isinstance(table, dict):
        raise ValueError(f"{where}must be a table, got {table!r}")
    hints = typing.get_type_hints(cls, include_extras=True)
    fields = [f for f in dataclasses.fields(cls) if f.init and f.name not in given]
    values = {}
    for f in fields:
        inner, kind = f.name if section is None else f"{section}.{f.name}", hints[f.name]
        if f.name in table:
            values[f.name] = _read(table[f.name], kind, inner, f"{where}{f.name}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ValueError(f"[{inner}] section missing" if _table_kind(kind) else f"{where}{f.name}: missing")
    unknown = set(table) - {f.name for f in fields}
    if unknown:
        raise ValueError(f"{where}unknown key(s) {sorted(unknown)}")
    try:
        return cls(**values, **given)
    except ValueError as exc:
        raise ValueError(f"{where}{exc}") from None


def _read(value: Any, kind: Any, section: str, key: str) -> Any:
    """The value of the key ``key`` (as errors name it) by its type hint ``kind``: a dataclass (or an
    optional one) is the table ``[section]`` (``from_table``), a ``tuple[Dataclass, ...]`` an array of
    tables (``[section[k]]``), a ``dict[str, X]`` a table of any keys (``[section] name``), anything
    else ``coerce``d. ValueError naming where."""
    table = _table_kind(kind)
    if table is not None:
        return from_table(table, value, section)
    args = typing.get_args(kind)
    if typing.get_origin(kind) is tuple and dataclasses.is_dataclass(args[0]):
        if not isinstance(value, list):
            raise ValueError(f"{key}: expected an array of tables ([[{section}]]), got {value!r}")
        return tuple(from_table(args[0], item, f"{section}[{k}]") for k, item in enumerate(value))
    if typing.get_origin(kind) is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{key}: expected a table ([{section}]), got {value!r}")
        return {name: _read(item, args[1], f"{section}.{name}", f"[{section}] {name}") for name, item in value.items()}
    try:
        return coerce(value, kind)
    except ValueError as exc:
        raise ValueError(f"{key}: {exc}") from None


def section_keys(*sections: Any) -> dict[str, Any]:
    """Every field of the dataclasses ``sections`` by name: a record that holds the keys of a file's
    sections at once (a subclass of their dataclasses) is made of them."""
    return {f.name: getattr(section, f.name) for section in sections for f in dataclasses.fields(section)}


def _table_kind(kind: Any) -> Any:
    """The dataclass a type hint names (``X`` or ``X | None``), else None."""
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        kinds = [k for k in typing.get_args(kind) if k is not type(None)]
        kind = kinds[0] if len(kinds) == 1 else None
    return kind if dataclasses.is_dataclass(kind) else None


def coerce(value: Any, kind: Any) -> Any:
    """A TOML value checked against a type hint: bool, int, float (an integer is taken), str, a
    fixed-length ``tuple[X, Y]`` or a ``tuple[X, ...]`` (from an array), a union (the first of its
    kinds that takes the value; ``None`` only as an absent key's default: TOML has no null), ``Any``
    (the value as written), or ``Annotated[X, read]``: ``read(value)``, for a format the type does
    not say (``read`` checks the value itself). ValueError saying what was expected."""
    if typing.get_origin(kind) is typing.Annotated:
        return kind.__metadata__[0](value)
    if kind is Any:
        return value
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        kinds = [k for k in typing.get_args(kind) if k is not type(None)]
        if len(kinds) == 1:
            return coerce(value, kinds[0])
        faults = []
        for each in kinds:
            try:
                return coerce(value, each)
            except ValueError as exc:
                faults.append(str(exc).split(", got ")[0])
        raise ValueError(f"expected {' or '.join(f.removeprefix('expected ') for f in faults)}, got {value!r}")
    if kind is bool:
        if not isinstance(value, bool):
            raise ValueError(f"expected true/false, got {value!r}")
        return value
    if kind is str:
        if not isinstance(value, str):
            raise ValueError(f"expected a string, got {value!r}")
        return value
    if kind in (int, float):
        if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
            raise ValueError(f"expected an integer, got {value!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ValueError(f"expected a finite number, got {value!r}")
        return kind(value)
    if typing.get_origin(kind) is not tuple:
        raise TypeError(f"no TOML reading of {kind}")
    args = typing.get_args(kind)
    if not isinstance(value, list):
        raise ValueError(f"expected a list, got {value!r}")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(coerce(item, args[0]) for item in value)
    if len(value) != len(args):
        raise ValueError(f"expected {len(args)} values, got {len(value)}")
    return tuple(coerce(item, arg) for item, arg in zip(value, args))


def positive(section: Any, *names: str) -> None:
    """ValueError ``name: must be > 0`` for the first of the ``section``'s fields ``names`` that is not."""
    for name in names:
        if not getattr(section, name) > 0:
            raise ValueError(f"{name}: must be > 0, got {getattr(section, name)!r}")


def at_most(section: Any, limit: float, *names: str) -> None:
    """ValueError ``name: must be at most limit`` for the first of the fields ``names`` above ``limit``."""
    for name in names:
        if getattr(section, name) > limit:
            raise ValueError(f"{name}: must be at most {limit!r}, got {getattr(section, name)!r}")


def within(section: Any, low: float, high: float, *names: str) -> None:
    """ValueError ``name: must be in [low, high]`` (``>= low`` when ``high`` is inf) for the first of
    the fields ``names`` outside."""
    for name in names:
        value = getattr(section, name)
        if not low <= value <= high:
            least, most = (f"{b:g}" if isinstance(b, float) else str(b) for b in (low, high))
            raise ValueError(f"{name}: must be {f'>= {least}' if high == math.inf else f'in [{least}, {most}]'}, "
                             f"got {value!r}")
