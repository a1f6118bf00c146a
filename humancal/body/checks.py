"""Input validation for the body model's public entry points (clear ValueErrors, no asserts)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

__all__ = ["check_tensor", "check_finite", "check_unit_interval"]


def check_tensor(value: object, name: str, expected: Sequence[int | str], what: str = "") -> Tensor:
    """Check that ``value`` is a floating tensor of the expected shape.

    Args:
        value: the argument.
        name: argument name for the message.
        expected: expected shape; ints must match, strings name free dimensions (the same string must match
            the same size within one call).
        what: optional description of the dimensions, appended to the message.

    Returns:
        The tensor, unchanged.

    Raises:
        ValueError: not a tensor, not floating point, or the wrong shape.
    """
    spelled = "(" + ", ".join(str(e) for e in expected) + ")"
    hint = f" ({what})" if what else ""
    if not isinstance(value, Tensor):
        raise ValueError(f"{name} must be a torch.Tensor of shape {spelled}{hint}, got {type(value).__name__}")
    if not value.is_floating_point():
        raise ValueError(f"{name} must be a floating-point tensor of shape {spelled}{hint}, got dtype {value.dtype}")
    shape = tuple(value.shape)
    ok = len(shape) == len(expected)
    bound: dict[str, int] = {}
    if ok:
        for size, want in zip(shape, expected):
            if isinstance(want, int):
                ok = ok and size == want
            elif want in bound:
                ok = ok and size == bound[want]
            else:
                bound[want] = size
    if not ok:
        raise ValueError(f"{name} must have shape {spelled}{hint}, got {shape}")
    return value


def check_finite(value: Tensor, name: str) -> Tensor:
    """Raise ValueError if ``value`` holds NaN or infinite entries."""
    if not bool(torch.isfinite(value).all()):
        raise ValueError(f"{name} must be finite, got NaN or infinite values")
    return value


def check_unit_interval(value: Tensor, name: str, labels: Sequence[str]) -> Tensor:
    """Raise ValueError if any entry of ``value`` (..., len(labels)) lies outside [0, 1]."""
    bad = (value < 0) | (value > 1)
    if bool(bad.any()):
        columns = sorted({int(c) for c in torch.nonzero(bad)[:, -1].tolist()})
        names = [labels[c] for c in columns]
        raise ValueError(
            f"{name} must lie in [0, 1] (columns {list(labels)}); out of range: {names}, "
            f"min {float(value.min()):.4g}, max {float(value.max()):.4g}"
        )
    return value
