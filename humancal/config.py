"""The base of humancal's configuration dataclasses: validated copies, a plain dict, a digest, and range checks
declared on the fields.

Every stage's settings are a frozen dataclass deriving from :class:`Config`; a field whose values are bounded says
so in its metadata, and :meth:`Config.__post_init__` checks it:

>>> from dataclasses import dataclass, field
>>> @dataclass(frozen=True)
... class ToyConfig(Config):
...     scale_m: float = field(default=0.3, metadata=positive())
...     min_views: int = field(default=2, metadata=at_least(2, integer=True))
>>> ToyConfig().replace(scale_m=0.5).scale_m
0.5
>>> ToyConfig(scale_m=0.0)
Traceback (most recent call last):
...
ValueError: ToyConfig.scale_m must be a positive number, got 0.0
>>> ToyConfig().replace(scale=1.0)
Traceback (most recent call last):
...
ValueError: ToyConfig has no field(s) ['scale']; fields are ['min_views', 'scale_m']

A subclass with further checks (between fields, of types, of choices) defines its own ``__post_init__`` and calls
``super().__post_init__()`` first.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import asdict, dataclass, fields
from typing import Any, TypeVar

import numpy as np

__all__ = ["Config", "Range", "RANGE_KEY", "at_least", "in_range", "ordered_pair", "positive"]

RANGE_KEY = "humancal/range"
"""The field-metadata key of a :class:`Range`."""

C = TypeVar("C", bound="Config")


@dataclass(frozen=True)
class Range:
    """The values a config field admits.

    Attributes:
        low, high: the bounds (None: unbounded on that side).
        low_open, high_open: whether the bound itself is excluded.
        integer: integers only (not booleans); otherwise any finite real number.
        optional: None is admitted too.
    """

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    integer: bool = False
    optional: bool = False

    def admits(self, value: Any) -> bool:
        """Whether ``value`` lies in this range."""
        if value is None:
            return self.optional
        kinds = (int, np.integer) if self.integer else (int, float, np.integer, np.floating)
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, kinds) or not math.isfinite(value):
            return False
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return False
        return self.high is None or (value < self.high if self.high_open else value <= self.high)

    def describe(self) -> str:
        """The range in words, e.g. ``a number in [0, 1)``, ``an integer >= 2``, ``a positive number``."""
        kind = "an integer" if self.integer else "a number"
        if self.low is not None and self.high is not None:
            text = (f"{kind} in {'(' if self.low_open else '['}{_bound(self.low)}, "
                    f"{_bound(self.high)}{')' if self.high_open else ']'}")
        elif self.low == 0 and self.low_open:
            text = f"a positive {kind.split()[-1]}"
        elif self.low is not None:
            text = f"{kind} {'>' if self.low_open else '>='} {_bound(self.low)}"
        elif self.high is not None:
            text = f"{kind} {'<' if self.high_open else '<='} {_bound(self.high)}"
        else:
            text = f"a finite {kind.split()[-1]}"
        return f"None or {text}" if self.optional else text


def _bound(value: float) -> str:
    """A bound as written: ``1``, ``0.5``, ``1e-07``, ``9223372036854775807``."""
    return str(int(value)) if float(value).is_integer() else f"{value:g}"


def in_range(low: float | None = None, high: float | None = None, *, low_open: bool = False,
             high_open: bool = False, integer: bool = False, optional: bool = False) -> dict[str, Range]:
    """Field metadata declaring the field's range (``field(default=..., metadata=in_range(0, 1))``)."""
    return {RANGE_KEY: Range(low, high, low_open, high_open, integer, optional)}


def positive(*, integer: bool = False, optional: bool = False) -> dict[str, Range]:
    """Field metadata: a number (or an integer) > 0."""
    return in_range(0, low_open=True, integer=integer, optional=optional)


def at_least(low: float, *, integer: bool = False, optional: bool = False) -> dict[str, Range]:
    """Field metadata: a number (or an integer) >= ``low``."""
    return in_range(low, integer=integer, optional=optional)


def ordered_pair(owner: str, name: str, value: Any, low: float, high: float) -> tuple[float, float]:
    """``value`` as a (min, max) pair of floats with ``low <= min <= max <= high`` (a field holding a range).

    Raises:
        ValueError: ``<owner>.<name>=<value> must be a (min, max) pair with min <= max within [low, high]``.
    """
    ok = isinstance(value, (tuple, list)) and len(value) == 2
    ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok or not low <= value[0] <= value[1] <= high:
        raise ValueError(f"{owner}.{name}={value!r} must be a (min, max) pair with min <= max within [{low}, {high}]")
    return float(value[0]), float(value[1])


class Config:
    """Base of the frozen configuration dataclasses (a mixin: it holds no fields)."""

    def __post_init__(self) -> None:
        self.check_ranges()

    def check_ranges(self) -> None:
        """Check every field that declares a :class:`Range` in its metadata.

        Raises:
            ValueError: ``<Class>.<field> must be <range>, got <value>`` for the first field out of its range.
        """
        for f in fields(self):
            bounds = f.metadata.get(RANGE_KEY)
            value = getattr(self, f.name)
            if bounds is not None and not bounds.admits(value):
                raise ValueError(f"{type(self).__name__}.{f.name} must be {bounds.describe()}, got {value!r}")

    def replace(self: C, **changes: Any) -> C:
        """A validated copy with some fields changed.

        Raises:
            ValueError: an unknown field, or a value the config does not admit.
        """
        known = sorted(f.name for f in fields(self))
        unknown = sorted(set(changes) - set(known))
        if unknown:
            raise ValueError(f"{type(self).__name__} has no field(s) {unknown}; fields are {known}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """A plain nested dict of the fields (``dataclasses.asdict``)."""
        return asdict(self)

    def digest(self) -> str:
        """Short hex digest of every field (names a configuration, e.g. in an asset's code version)."""
        text = json.dumps(self.to_dict(), sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:12]
