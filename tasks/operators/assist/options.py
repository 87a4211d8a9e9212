"""Which assistances are on: their names, as ``--assist`` and a profile's ``[assist] options`` spell them."""
from __future__ import annotations

import enum

from bomi.errors import BomiError
from bomi.profiles import Profile

NONE = "none"


class Assist(enum.Enum):
    """The assistances one may choose (``--assist``, a profile's ``[assist] options``)."""

    AUTO_MODE = "auto-mode"
    GRASP_HELP = "grasp-help"


def parse_assist(names: str | list[str] | tuple[str, ...], what: str = "--assist") -> frozenset[Assist]:
    """``"none"``, one name or a comma list (or a list of names) -> the set of assistances."""
    items = [n.strip() for n in names.split(",")] if isinstance(names, str) else [str(n).strip() for n in names]
    items = [n for n in items if n]
    what = f"{what}: " if what else ""
    allowed = ", ".join([NONE] + [a.value for a in Assist])
    if not items:
        raise BomiError(f"{what}empty (expected {allowed})")
    if NONE in items:
        if len(items) > 1:
            raise BomiError(f"{what}{NONE!r} cannot be combined with {', '.join(n for n in items if n != NONE)}")
        return frozenset()
    by_name = {a.value: a for a in Assist}
    bad = [n for n in items if n not in by_name]
    if bad:
        raise BomiError(f"{what}unknown {', '.join(bad)} (expected {allowed})")
    return frozenset(by_name[n] for n in items)


def assist_option(text: str) -> frozenset[Assist]:
    """``--assist`` as the command line gives it (``parse_assist`` naming the option): a one-line BomiError
    when it names no assistance."""
    return parse_assist(text, "--assist")


ASSIST_HELP = ("assistance between the stick and the arm: none, or a comma list of "
               f"{', '.join(a.value for a in Assist)} (default: the profile's [assist] options; joystick: none)")


def profile_assist(profile: Profile) -> frozenset[Assist]:
    """The assistances a profile switches on (its ``[assist] options``)."""
    return parse_assist(list(profile.assist), f"{profile.source}: [assist] options") if profile.assist else frozenset()


def assist_label(options: frozenset[Assist]) -> str:
    """The set as ``--assist`` spells it (enum order): "none", "auto-mode", "auto-mode,grasp-help"."""
    return ",".join(a.value for a in Assist if a in options) or NONE
