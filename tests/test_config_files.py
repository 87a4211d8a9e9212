"""bomi.config_files, the one loader: TOML tables -> dataclasses by their type hints, every fault one
line ``path: [section] key: ...``."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any

import pytest

from bomi.config_files import coerce, from_table, load_toml, parse_text, within
from bomi.errors import BomiError


@dataclass(frozen=True)
class Wheel:
    radius: float
    spokes: int = 32

    def __post_init__(self) -> None:
        if not self.radius > 0:
            raise ValueError(f"radius: must be > 0, got {self.radius!r}")


@dataclass(frozen=True)
class Bike:
    name: str
    wheels: tuple[Wheel, ...]
    frame: Wheel
    gears: tuple[int, int] = (1, 1)
    brake: float | str = "none"
    bell: bool | None = None


def test_a_document_becomes_nested_dataclasses_with_defaults_and_integers_taken_as_floats():
    bike = from_table(Bike, {"name": "b", "wheels": [{"radius": 1}, {"radius": 0.5, "spokes": 28}],
                             "frame": {"radius": 2.0}, "brake": 0.25})
    assert bike == Bike("b", (Wheel(1.0), Wheel(0.5, 28)), Wheel(2.0), (1, 1), 0.25, None)
    assert isinstance(bike.wheels[0].radius, float) and from_table(Bike, {"name": "b", "wheels": [], "frame": {
        "radius": 1}, "brake": "disc"}).brake == "disc"


@pytest.mark.parametrize("document, fault", [
    ({"wheels": [], "frame": {"radius": 1}}, "name: missing"),
    ({"name": "b", "wheels": []}, "[frame] section missing"),
    ({"name": "b", "wheels": [], "frame": {"radius": 1}, "horn": 1}, "unknown key(s) ['horn']"),
    ({"name": "b", "wheels": [{"radius": -1}], "frame": {"radius": 1}}, "[wheels[0]] radius: must be > 0, got -1.0"),
    ({"name": "b", "wheels": [{"radius": 1, "spokes": 2.5}], "frame": {"radius": 1}},
     "[wheels[0]] spokes: expected an integer, got 2.5"),
    ({"name": "b", "wheels": {"radius": 1}, "frame": {"radius": 1}}, "wheels: expected an array of tables ([[wheels]]), got {'radius': 1}"),
    ({"name": "b", "wheels": [], "frame": {"radius": 1, "tyre": "x"}}, "[frame] unknown key(s) ['tyre']"),
    ({"name": "b", "wheels": [], "frame": 3}, "[frame] must be a table, got 3"),
    ({"name": "b", "wheels": [], "frame": {"radius": 1}, "gears": [1, 2, 3]}, "gears: expected 2 values, got 3"),
    ({"name": "b", "wheels": [], "frame": {"radius": 1}, "brake": True}, "brake: expected a number or a string, got True"),
    ({"name": "b", "wheels": [], "frame": {"radius": 1}, "bell": 1}, "bell: expected true/false, got 1"),
])
def test_every_fault_is_one_line_naming_its_section_and_key(document, fault):
    with pytest.raises(ValueError) as info:
        from_table(Bike, document)
    assert str(info.value) == fault


def _gear_list(value: Any) -> tuple[int, ...]:
    """A format no type says: "1-3" for gears 1, 2, 3."""
    low, _, high = coerce(value, str).partition("-")
    if not (low.isdigit() and high.isdigit()):
        raise ValueError(f"expected FIRST-LAST, got {value!r}")
    return tuple(range(int(low), int(high) + 1))


@dataclass(frozen=True)
class Trailer:
    load: float = 0.0
    hitch: Wheel | None = None                   # an optional table
    notes: dict[str, str] = field(default_factory=dict)   # a table of any keys
    gears: Annotated[tuple[int, ...], _gear_list] = ()
    cargo: Any = None                             # as written

    def __post_init__(self) -> None:
        within(self, 0.0, 500.0, "load")


def test_optional_tables_free_keyed_tables_annotated_readers_and_any():
    assert from_table(Trailer, {}) == Trailer()
    trailer = from_table(Trailer, {"hitch": {"radius": 1}, "notes": {"a.b": "x"}, "gears": "2-4", "cargo": [1, "a"]})
    assert trailer == Trailer(0.0, Wheel(1.0), {"a.b": "x"}, (2, 3, 4), [1, "a"])
    for document, fault in [({"hitch": 3}, "[hitch] must be a table, got 3"),
                            ({"hitch": {"radius": 0}}, "[hitch] radius: must be > 0, got 0.0"),
                            ({"notes": ["x"]}, "notes: expected a table ([notes]), got ['x']"),
                            ({"notes": {"a": "x", "b": 2}}, "[notes] b: expected a string, got 2"),
                            ({"gears": "2-x"}, "gears: expected FIRST-LAST, got '2-x'"),
                            ({"gears": 3}, "gears: expected a string, got 3"),
                            ({"load": 501}, "load: must be in [0, 500], got 501.0")]:
        with pytest.raises(ValueError) as info:
            from_table(Trailer, document)
        assert str(info.value) == fault


def test_coerce_refuses_a_boolean_for_a_number_and_nan():
    for value, kind in [(True, float), (True, int), (float("nan"), float), ("1", float)]:
        with pytest.raises(ValueError):
            coerce(value, kind)
    assert coerce(3, float) == 3.0 and type(coerce(3, float)) is float


def test_a_file_is_named_in_front_of_the_fault(tmp_path):
    path = tmp_path / "bike.toml"
    path.write_text('name = "b"\nwheels = []\n[frame]\nradius = 0\n')
    with pytest.raises(BomiError) as info:
        load_toml(path, tmp_path, "bike", lambda data, source: from_table(Bike, data))
    assert str(info.value) == f"{path}: [frame] radius: must be > 0, got 0.0"
    path.write_text('name = "b"\nwheels = []\n[frame]\nradius = 1e300\n')
    with pytest.raises(BomiError, match=r"bike.toml: \[frame\] radius: 1e\+300 is not a finite number within"):
        load_toml(path, tmp_path, "bike", lambda data, source: from_table(Bike, data))


def test_a_text_is_checked_as_its_file_would_be_with_value_errors():
    def bike(data: dict, source: str) -> Bike:
        return from_table(Bike, data)

    assert parse_text('name = "b"\nwheels = []\n[frame]\nradius = 1\n', "t.toml", "bike", bike).frame == Wheel(1.0)
    for text, fault in [('name = "b', "not valid TOML"), ("a = " + "[" * 40 + "]" * 40, "not a bike file (nested deeper"),
                        ('name = "b"\nwheels = []\n[frame]\nradius = nan\n', "[frame] radius: nan is not a finite number")]:
        with pytest.raises(ValueError) as info:
            parse_text(text, "t.toml", "bike", bike)
        assert str(info.value).startswith(fault)
