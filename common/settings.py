"""Settings declared once: name, type, default, one-line description, range or choices, flag spelling.

From one declaration come the command-line flag (its help shows the description, the default and the range),
the one range check (an out-of-range value is refused naming the flag, the range and the value given) and the
values handed to the core. A pure core keeps a plain dataclass; its fields are declared with `setting(...)`,
which returns an ordinary `dataclasses.field` carrying the declaration in its metadata:

    @dataclass(frozen=True)
    class Config:
        window_before: float = setting(1.0, "seconds before the utterance start searched", at_least=0)

    add_settings(parser, Config)               # one flag per field: --window-before S
    config = from_args(Config, parser.parse_args())

A shell's own flag (not a core's field) is declared the same way in one call: `add_option(parser, "--conf",
0.3, "confidence threshold", at_least=0, at_most=1)`. Standard library only: cores import this.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import typing
from dataclasses import dataclass
from typing import Any, Callable, Sequence, TypeVar

T = TypeVar("T")
METADATA_KEY = "setting"


class OutOfRange(ValueError):
    """A value outside its setting's declared range or choices."""


@dataclass(frozen=True)
class Range:
    """[low, high] with each end inclusive unless declared open; None: unbounded on that side."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False  # True: low itself is outside (> low)
    high_open: bool = False  # True: high itself is outside (< high)

    @classmethod
    def of(
        cls,
        at_least: float | None = None,
        above: float | None = None,
        at_most: float | None = None,
        below: float | None = None,
    ) -> Range | None:
        if at_least is not None and above is not None or at_most is not None and below is not None:
            raise TypeError("declare one lower bound (at_least or above) and one upper bound (at_most or below)")
        low = above if above is not None else at_least
        high = below if below is not None else at_most
        if low is None and high is None:
            return None
        if low is not None and high is not None and low > high:
            raise TypeError(f"an empty range: low {low} > high {high}")
        return cls(low, high, above is not None, below is not None)

    def contains(self, value: float) -> bool:
        if isinstance(value, float) and math.isnan(value):
            return False
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return False
        if self.high is not None and (value >= self.high if self.high_open else value > self.high):
            return False
        return True

    def text(self) -> str:
        """As the docs read it: "0–1", "≥ 0", "> 0", "0–1 (exclusive)"…"""
        low, high = _number(self.low), _number(self.high)
        if self.high is None:
            return f"{'>' if self.low_open else '≥'} {low}"
        if self.low is None:
            return f"{'<' if self.high_open else '≤'} {high}"
        if not self.low_open and not self.high_open:
            return f"{low}–{high}"
        return f"{'(' if self.low_open else '['}{low}, {high}{')' if self.high_open else ']'}"


def _number(value: float | None) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


@dataclass(frozen=True)
class Setting:
    """One setting: everything its flag, its check, its documentation and its core need."""

    name: str  # the attribute: the core's field and the parsed namespace's dest
    kind: Callable[[str], Any]  # float, int, str or bool
    default: Any
    description: str  # one line, without the default or the range (they are appended)
    range: Range | None = None
    choices: tuple[Any, ...] | None = None
    flag: str | None = None  # default: --name-with-dashes
    metavar: str | None = None
    default_text: str | None = None  # what the help says about the default when the value alone does not
    optional: bool = False  # None is allowed ("off"); only as the default, never typed

    @property
    def option(self) -> str:
        return self.flag or "--" + self.name.replace("_", "-")

    def limits(self) -> str:
        """The range or the choices, as the help and the docs show them ("" when any value goes)."""
        if self.choices is not None:
            return "|".join(str(c) for c in self.choices)
        return self.range.text() if self.range is not None else ""

    def shown_default(self) -> str:
        if self.default_text is not None:
            return self.default_text
        if self.kind is bool:
            return "on" if self.default else "off"
        return "off" if self.default is None else _number(self.default)

    def help(self) -> str:
        limits = "" if self.choices is not None else self.limits()  # argparse shows choices itself
        return f"{self.description} (default {self.shown_default()}{f'; {limits}' if limits else ''})"

    def check(self, value: Any) -> Any:
        """The one range check: `value` if it is within the declared range and choices, else OutOfRange."""
        if value is None and self.optional:
            return value
        if self.choices is not None and value not in self.choices:
            raise OutOfRange(f"{value!r} is not one of {self.limits()}")
        if self.range is not None and not self.range.contains(value):
            raise OutOfRange(f"{_number(value)} is outside its range {self.range.text()}")
        return value

    def parse(self, text: str) -> Any:
        """The argparse `type`: convert, then check (argparse prefixes the error with the flag)."""
        value = self.kind(text)
        try:
            return self.check(value)
        except OutOfRange as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None


def setting(  # noqa: PLR0913 - a declaration: each bound is an optional keyword, as in dataclasses.field
    default: T,
    description: str,
    *,
    at_least: float | None = None,
    above: float | None = None,
    at_most: float | None = None,
    below: float | None = None,
    choices: Sequence[Any] | None = None,
    flag: str | None = None,
    metavar: str | None = None,
    default_text: str | None = None,
) -> T:
    """A dataclass field with its declaration (name and type come from the field)."""
    declared = dict(
        description=description,
        range=Range.of(at_least, above, at_most, below),
        choices=tuple(choices) if choices is not None else None,
        flag=flag,
        metavar=metavar,
        default_text=default_text,
    )
    return dataclasses.field(default=default, metadata={METADATA_KEY: declared})


def settings_of(cls: type) -> list[Setting]:
    """The declarations of a dataclass's fields, in field order. A field without one is an error: every field
    of a settings dataclass is a setting."""
    hints = typing.get_type_hints(cls)
    found = []
    for f in dataclasses.fields(cls):
        declared = f.metadata.get(METADATA_KEY)
        if declared is None:
            raise TypeError(f"{cls.__name__}.{f.name} is not declared with setting(...)")
        kind, optional = _kind(hints[f.name])
        if declared["choices"] is None and typing.get_origin(hints[f.name]) is typing.Literal:
            declared = {**declared, "choices": typing.get_args(hints[f.name])}  # a Literal's values are its choices
        found.append(Setting(f.name, kind, f.default, optional=optional, **declared))
    return found


def _kind(hint: Any) -> tuple[Callable[[str], Any], bool]:
    args = typing.get_args(hint)
    if args and type(None) in args:  # X | None
        (inner,) = [a for a in args if a is not type(None)]
        return _kind(inner)[0], True
    if typing.get_origin(hint) is typing.Literal:
        return type(args[0]), False
    if hint in (float, int, str, bool):
        return hint, False
    raise TypeError(f"a setting is a float, int, str or bool (or one of them | None), not {hint}")


def add_setting(parser: argparse.ArgumentParser | argparse._ArgumentGroup, s: Setting) -> argparse.Action:
    """The flag of one setting; the action carries the declaration (`action.setting`) for docs and tests."""
    if s.kind is bool:
        action = parser.add_argument(
            s.option,
            dest=s.name,
            action="store_true" if not s.default else argparse.BooleanOptionalAction,
            default=s.default,
            help=s.help().replace("%", "%%"),
        )
    else:
        parse = s.parse
        # argparse names the type in its conversion errors ("invalid float value: 'x'")
        typed = _named(parse, getattr(s.kind, "__name__", "value"))
        action = parser.add_argument(
            s.option,
            dest=s.name,
            type=typed,
            choices=s.choices,
            default=s.default,
            metavar=s.metavar,
            help=s.help().replace("%", "%%"),
        )
    action.setting = s  # type: ignore[attr-defined]
    return action


def _named(fn: Callable[[str], Any], name: str) -> Callable[[str], Any]:
    def parse(text: str) -> Any:
        return fn(text)

    parse.__name__ = name
    return parse


def add_option(  # noqa: PLR0913 - a declaration: the same optional keywords as setting()
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    flag: str,
    default: Any,
    description: str,
    *,
    kind: Callable[[str], Any] | None = None,
    at_least: float | None = None,
    above: float | None = None,
    at_most: float | None = None,
    below: float | None = None,
    choices: Sequence[Any] | None = None,
    metavar: str | None = None,
    default_text: str | None = None,
) -> argparse.Action:
    """A shell's own flag, declared in one call like a core's `setting` (the type from `kind`, else the default's).
    A None default means "off" and needs `kind`."""
    if kind is None:
        if default is None:
            raise TypeError(f"{flag}: a None default needs kind=")
        kind = type(default)
    s = Setting(
        name=flag.lstrip("-").replace("-", "_"),
        kind=kind,
        default=default,
        description=description,
        range=Range.of(at_least, above, at_most, below),
        choices=tuple(choices) if choices is not None else None,
        flag=flag,
        metavar=metavar,
        default_text=default_text,
        optional=default is None,
    )
    return add_setting(parser, s)


def add_settings(parser: argparse.ArgumentParser | argparse._ArgumentGroup, cls: type) -> list[argparse.Action]:
    """One flag per field of the settings dataclass `cls`."""
    return [add_setting(parser, s) for s in settings_of(cls)]


def from_args(cls: type[T], args: argparse.Namespace) -> T:
    """The dataclass `cls` from parsed flags (each field from the dest of the same name)."""
    return cls(**{s.name: getattr(args, s.name) for s in settings_of(cls)})


def check_all(instance: Any) -> None:
    """Every field of a settings dataclass within its declared range (OutOfRange naming the field otherwise)."""
    for s in settings_of(type(instance)):
        try:
            s.check(getattr(instance, s.name))
        except OutOfRange as exc:
            raise OutOfRange(f"{type(instance).__name__}.{s.name}: {exc}") from None


def declared(parser: argparse.ArgumentParser) -> list[Setting]:
    """The settings of a parser's flags that were declared here (for docs and tests), in flag order."""
    # argparse keeps every action, those of its groups included, in _actions (stable since Python 3.2)
    return [a.setting for a in parser._actions if hasattr(a, "setting")]


def table(settings: Sequence[Setting]) -> str:
    """A markdown table of settings: flag, default, range, description."""
    rows = ["| flag | default | range | what |", "|---|---|---|---|"]
    for s in settings:
        # a switch or a choice names its values in the range column
        plain = s.kind is bool or s.choices is not None
        flag = f"`{s.option}`" if plain else f"`{s.option} {s.metavar or s.name.upper()}`"
        cells = [flag, s.shown_default(), s.limits(), s.description]
        rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(rows) + "\n"
