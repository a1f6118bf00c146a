"""The options of a user's capture as text and values: image sizes, known principal points, frame rates and time
offsets.

``humancal.captures`` uses them for a datasets file's options, ``humancal add`` for its flags.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["camera_file_option", "is_size", "named_numbers_option", "parse_image_size", "parse_named_numbers",
           "parse_principal_point", "principal_points_option"]


def parse_image_size(text: str, where: str = "image size") -> tuple[int, int]:
    """``"1920x1080"`` as (width_px, height_px).

    Raises:
        ValueError: not two positive integers joined by ``x`` (the message names ``where``).
    """
    parts = str(text).lower().split("x")
    if len(parts) == 2 and all(p.strip().isdigit() for p in parts):
        w, h = int(parts[0]), int(parts[1])
        if w > 0 and h > 0:
            return w, h
    raise ValueError(f"{where}: expected WIDTHxHEIGHT in pixels (e.g. 1920x1080), got {text!r}")


def parse_principal_point(text: str, where: str = "principal point") -> tuple[float, float]:
    """``"963.5,541.2"`` as (cx_px, cy_px).

    Raises:
        ValueError: not two finite numbers joined by ``,`` (the message names ``where``).
    """
    parts = str(text).split(",")
    try:
        cx, cy = (float(p) for p in parts) if len(parts) == 2 else (np.nan, np.nan)
    except ValueError:
        cx = cy = np.nan
    if np.isfinite(cx) and np.isfinite(cy):
        return cx, cy
    raise ValueError(f"{where}: expected CX,CY in pixels (e.g. 963.5,541.2), got {text!r}")


def principal_points_option(value: object, image_sizes_px: Sequence[tuple[int, int]],
                            where: str = "principal_point") -> tuple[tuple[float, float], ...]:
    """Known principal points from an option: ``[cx, cy]`` for every view or one ``[cx, cy]`` per view, pixels, each
    inside its image (``0 <= cx <= width``, ``0 <= cy <= height``).

    Returns:
        (V,) (cx_px, cy_px), V = ``len(image_sizes_px)``.

    Raises:
        ValueError: another form, a count other than 1 or V, or a point outside its image (the message names
            ``where`` and the view).
    """
    def is_point(p: object) -> bool:
        return (isinstance(p, (list, tuple)) and len(p) == 2
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in p))

    V = len(image_sizes_px)
    if is_point(value):
        points = [tuple(float(x) for x in value)] * V  # type: ignore[union-attr]
    elif isinstance(value, (list, tuple)) and len(value) == V and all(is_point(p) for p in value):
        points = [tuple(float(x) for x in p) for p in value]  # type: ignore[union-attr]
    else:
        raise ValueError(f"{where}: expected [cx, cy] in pixels for every view or one [cx, cy] per view ({V}), "
                         f"got {value!r}")
    for v, ((cx, cy), (w, h)) in enumerate(zip(points, image_sizes_px)):
        if not (0.0 <= cx <= w and 0.0 <= cy <= h):
            raise ValueError(f"{where}: view {v}'s ({cx:g}, {cy:g}) is outside its {w}x{h} image")
    return tuple(points)  # type: ignore[return-value]


def is_size(value: object) -> bool:
    """Whether ``value`` is [width, height]: two positive integers."""
    return (isinstance(value, (list, tuple)) and len(value) == 2
            and all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in value))


def camera_file_option(value: object, name: str, path: Callable[[object, str], Path], extra: tuple[str, ...]
                       ) -> dict[str, Any]:
    """A ``{path: FILE, format: FORMAT, ...}`` option as a dict with its path resolved by ``path`` ({} when absent).

    Raises:
        ValueError: not such a mapping, or keys other than ``path``, ``format`` and ``extra``.
    """
    if value is None:
        return {}
    allowed = ("path", "format", *extra)
    if not isinstance(value, dict) or "path" not in value or set(value) - set(allowed):
        raise ValueError(f"{name}: expected {{{', '.join(f'{k}: ...' for k in allowed)}}} with a path, got {value!r}")
    return {**value, "path": path(value["path"], f"{name}.path")}


def parse_named_numbers(texts: Sequence[str], where: str, unit: str, *, positive: bool, allow_default: bool
                        ) -> tuple[float | None, tuple[tuple[str, float], ...]]:
    """Command-line values ``NAME=NUMBER`` (and, with ``allow_default``, one plain ``NUMBER`` for the views not
    named), e.g. ``--fps 30 cam2=60`` or ``--time-offsets cam2=1.25``.

    Returns:
        ``(default, ((name, value), ...))``: the plain number (None when not given) and the named ones, in order.

    Raises:
        ValueError: a malformed entry, a name given twice, two plain numbers, a non-finite number, or (``positive``)
            one that is not above 0 (the message names ``where``).
    """
    default: float | None = None
    named: dict[str, float] = {}
    form = f"NAME={unit}" + (f" or {unit}" if allow_default else "")
    for text in texts:
        name, sep, number = str(text).rpartition("=")
        try:
            value = float(number)
        except ValueError:
            value = float("nan")
        if not np.isfinite(value) or (positive and value <= 0) or (sep and not name):
            raise ValueError(f"{where}: expected {form}{' (a positive number)' if positive else ''}, got {text!r}")
        if not sep:
            if not allow_default or default is not None:
                raise ValueError(f"{where}: expected {form}, got {text!r}"
                                 + (" (a second plain number)" if allow_default else ""))
            default = value
        elif name in named:
            raise ValueError(f"{where}: view {name!r} given twice")
        else:
            named[name] = value
    return default, tuple(named.items())


def named_numbers_option(value: object, where: str, *, positive: bool) -> tuple[tuple[str, float], ...]:
    """A datasets-file option ``{view name: number, ...}`` as ``((name, value), ...)``.

    Raises:
        ValueError: not such a mapping of finite numbers (above 0 with ``positive``); the message names ``where``.
    """
    def number(x: object) -> bool:
        return (isinstance(x, (int, float)) and not isinstance(x, bool) and bool(np.isfinite(x))
                and (not positive or x > 0))

    if not (isinstance(value, dict) and all(isinstance(k, str) and number(x) for k, x in value.items())):
        kind = "positive numbers" if positive else "numbers"
        raise ValueError(f"{where}: expected a mapping of view names to {kind}, got {value!r}")
    return tuple((k, float(x)) for k, x in value.items())
