"""Table-driven checks of settings: one :class:`Range` per setting, :func:`check_settings` for a
config object against its table, :class:`SettingError` naming the first setting out of range.

Every config of the project (``SimulatorConfig``, ``TrainConfig``, the PPO and planner configs)
states its allowed values as a ``field -> Range`` table and checks itself with
:func:`check_settings` when it is built; only checks across fields are written out by hand. The
message always reads ``"{prefix}{name} must be {allowed values in words}, got {value!r}"``.

Booleans are not integers or numbers here (``True`` is no batch size), and numbers must be
finite. Standard library only: the core imports this module.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

#: The kinds of value a :class:`Range` describes.
Kind = Literal["int", "float", "bool", "str"]
_KINDS = ("int", "float", "bool", "str")


class SettingError(ValueError):
    """A setting outside its allowed values.

    Attributes:
        setting: the field's name (without the prefix of the message, e.g. ``"lr"``, not
            ``"training.lr"``): a command line maps it to its option.
        detail: the message after the name (``"must be ..., got ..."``).
    """

    def __init__(self, setting: str, detail: str, prefix: str = "") -> None:
        super().__init__(f"{prefix}{setting} {detail}")
        self.setting = setting
        self.detail = detail


def _bound(x: float) -> str:
    """A bound as the messages print it: integers in full, other numbers by ``:g``."""
    return str(x) if isinstance(x, int) else f"{x:g}"


@dataclass(frozen=True)
class Range:
    """The allowed values of one setting.

    Args:
        kind: ``"int"`` (an ``int``, not a ``bool``), ``"float"`` (a finite ``int`` or ``float``,
            not a ``bool``), ``"bool"`` or ``"str"``.
        low, high: bounds of an ``"int"`` or ``"float"`` (``None``: unbounded on that side).
        low_open, high_open: the bound itself is excluded.
        none_ok: ``None`` is allowed too.
        choices: the only values allowed (of ``kind``); bounds do not apply then.
        also: further values of ``kind`` allowed outside the bounds (``-1`` in "-1 or an
            integer >= 1").
    """

    kind: Kind
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    none_ok: bool = False
    choices: tuple[Any, ...] | None = None
    also: tuple[Any, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise ValueError(f"Range kind must be one of {_KINDS}, got {self.kind!r}")
        bounded = self.low is not None or self.high is not None
        if bounded and (self.kind not in ("int", "float") or self.choices is not None):
            raise ValueError("bounds apply to 'int' and 'float' ranges without choices")
        if self.low is not None and self.high is not None and self.low > self.high:
            raise ValueError(f"Range low {self.low} above high {self.high}")

    def _of_kind(self, value: Any) -> bool:
        if self.kind == "bool":
            return isinstance(value, bool)
        if self.kind == "str":
            return isinstance(value, str)
        if isinstance(value, bool):
            return False
        if self.kind == "int":
            return isinstance(value, int)
        return isinstance(value, (int, float)) and math.isfinite(value)

    def _in_bounds(self, value: float) -> bool:
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return False
        return self.high is None or (value < self.high if self.high_open else value <= self.high)

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` is one of the allowed values."""
        if value is None:
            return self.none_ok
        if not self._of_kind(value):
            return False
        if value in self.also:
            return True
        if self.choices is not None:
            return value in self.choices
        return self._in_bounds(value)

    def words(self) -> str:
        """The allowed values in words: ``"an integer >= 1"``, ``"a number in (0, 1]"``,
        ``"one of ('float32', 'bfloat16')"``, ``"true or false"``, ``"None or an integer >= 1"``
        (a ``"float"`` bounded on one side at most is ``"a finite number ..."``)."""
        if self.kind == "bool":
            main = "true or false"
        elif self.choices is not None:
            main = f"one of {self.choices}"
        elif self.kind == "str":
            main = "a string"
        else:
            low, high = self.low, self.high
            main = "an integer" if self.kind == "int" else "a number"
            if low is not None and high is not None:
                main += (f" in {'(' if self.low_open else '['}{_bound(low)}, "
                         f"{_bound(high)}{')' if self.high_open else ']'}")
            else:  # unbounded on a side: the finiteness is news
                main = "a finite number" if self.kind == "float" else main
                if low is not None:
                    main += f" {'>' if self.low_open else '>='} {_bound(low)}"
                if high is not None:
                    main += f" {'<' if self.high_open else '<='} {_bound(high)}"
        return " or ".join([*(["None"] if self.none_ok else []), *map(repr, self.also), main])


def check_value(name: str, value: Any, allowed: Range, prefix: str = "") -> None:
    """:class:`SettingError` ``"{prefix}{name} must be {words}, got {value!r}"`` unless
    ``allowed`` accepts ``value``."""
    if not allowed.accepts(value):
        raise SettingError(name, f"must be {allowed.words()}, got {value!r}", prefix)


def check_settings(obj: Any, table: Mapping[str, Range], prefix: str = "") -> None:
    """Check the attribute of ``obj`` named by each entry of ``table``, in the table's order;
    :class:`SettingError` for the first one out of its range (``prefix`` starts the message,
    e.g. ``"training."``; ``setting`` is the bare name)."""
    for name, allowed in table.items():
        check_value(name, getattr(obj, name), allowed, prefix)
