"""The HIERARCHY section of a BVH file: the joint tree with each node's OFFSET and CHANNELS.

:mod:`humancal.mocap.bvh` reads the whole file (the MOTION values, the kinematics) and re-exports
:class:`BvhJoint`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humancal.mocap.clip import MocapFormatError

__all__ = ["BvhJoint", "parse_hierarchy"]

_CHANNELS = {
    "xposition": "Xposition",
    "yposition": "Yposition",
    "zposition": "Zposition",
    "xrotation": "Xrotation",
    "yrotation": "Yrotation",
    "zrotation": "Zrotation",
}


@dataclass(frozen=True)
class BvhJoint:
    """One node of a BVH hierarchy.

    Attributes:
        name: joint name; End Sites are named ``<parent>_end``.
        parent: index of the parent node, -1 for a root.
        offset: (3,) OFFSET from the parent, file units and axes.
        channels: channel names as declared (canonical case), e.g. ``("Zrotation", "Xrotation", "Yrotation")``.
        first_column: column of the first channel in a MOTION line.
        is_end_site: whether the node is an End Site (no channels).
    """

    name: str
    parent: int
    offset: tuple[float, float, float]
    channels: tuple[str, ...]
    first_column: int
    is_end_site: bool


def _tokens(lines: list[str], stop: int) -> list[tuple[str, int]]:
    """Whitespace tokens of ``lines[:stop]`` with 1-based line numbers; braces are tokens of their own."""
    out: list[tuple[str, int]] = []
    for i in range(stop):
        for tok in lines[i].replace("{", " { ").replace("}", " } ").split():
            out.append((tok, i + 1))
    return out


class _TokenStream:
    """The HIERARCHY tokens of a file, read in order; reading past the end raises naming the last line."""

    def __init__(self, path: Path, toks: list[tuple[str, int]]) -> None:
        self.path = path
        self.toks = toks
        self.pos = 0
        self.last_line = toks[-1][1] if toks else 1

    def more(self) -> bool:
        """Whether tokens are left."""
        return self.pos < len(self.toks)

    def take(self, expected: str) -> tuple[str, int]:
        """The next token and its line; ``expected`` names it in the error at the end of the section."""
        if self.pos >= len(self.toks):
            raise MocapFormatError(self.path, self.last_line, f"HIERARCHY ends early; expected {expected}")
        tok = self.toks[self.pos]
        self.pos += 1
        return tok

    def expect(self, word: str) -> int:
        """The line of the next token, which must be ``word``."""
        tok, line = self.take(f"'{word}'")
        if tok != word:
            raise MocapFormatError(self.path, line, f"expected '{word}', found {tok!r}")
        return line

    def number(self, what: str) -> float:
        """The next token as a finite number."""
        tok, line = self.take(what)
        try:
            value = float(tok)
        except ValueError:
            raise MocapFormatError(self.path, line, f"expected {what} (a number), found {tok!r}") from None
        if not np.isfinite(value):
            raise MocapFormatError(self.path, line, f"expected {what} (a finite number), found {tok!r}")
        return value


def _channels(tokens: _TokenStream, name: str) -> tuple[str, ...]:
    """The canonical channel names of joint ``name``, read after its ``CHANNELS`` keyword."""
    count_tok, count_line = tokens.take("the channel count")
    if not count_tok.isdigit():
        raise MocapFormatError(tokens.path, count_line, f"expected the channel count of {name!r}, found {count_tok!r}")
    names = []
    for _ in range(int(count_tok)):
        tok, ch_line = tokens.take(f"a channel name of {name!r}")
        canonical = _CHANNELS.get(tok.lower())
        if canonical is None:
            raise MocapFormatError(
                tokens.path, ch_line, f"unknown channel {tok!r} of joint {name!r}; expected one of "
                f"{', '.join(_CHANNELS.values())}"
            )
        names.append(canonical)
    return tuple(names)


class _NodeReader:
    """Reads nodes (ROOT, JOINT, End Site) recursively into :attr:`joints`, numbering the channel columns."""

    def __init__(self, tokens: _TokenStream) -> None:
        self.tokens = tokens
        self.joints: list[BvhJoint] = []
        self.column = 0

    def node(self, kind: str, parent: int) -> None:
        """Read one node of ``kind`` (``"ROOT"``, ``"JOINT"`` or ``"End"``, already taken) and its children."""
        tokens, path = self.tokens, self.tokens.path
        if kind == "End":
            tokens.expect("Site")
            name = f"{self.joints[parent].name}_end"
        else:
            name_tok, line = tokens.take(f"a {kind} name")
            if name_tok == "{":
                raise MocapFormatError(path, line, f"{kind} without a name")
            name = name_tok
        tokens.expect("{")
        tokens.expect("OFFSET")
        offset = (tokens.number("OFFSET x"), tokens.number("OFFSET y"), tokens.number("OFFSET z"))
        channels: tuple[str, ...] = ()
        if kind != "End":
            tokens.expect("CHANNELS")
            channels = _channels(tokens, name)
        index = len(self.joints)
        self.joints.append(BvhJoint(name, parent, offset, channels, self.column, kind == "End"))
        self.column += len(channels)
        while True:
            tok, tok_line = tokens.take(f"JOINT, End Site or '}}' closing {name!r}")
            if tok == "}":
                return
            if kind == "End" or tok not in ("JOINT", "End"):
                raise MocapFormatError(path, tok_line, f"expected JOINT, End Site or '}}' in {name!r}, found {tok!r}")
            self.node(tok, index)


def parse_hierarchy(path: Path, lines: list[str], motion_line: int) -> list[BvhJoint]:
    """The nodes declared in ``lines[:motion_line]`` (the HIERARCHY section), in file order.

    Args:
        path: the file, for error messages.
        lines: the file's lines.
        motion_line: index of the ``MOTION`` line.

    Returns:
        The nodes, parents before children, End Sites included.

    Raises:
        MocapFormatError: naming the file, the line and what was expected (unknown channel, a section that ends
            early, no ROOT, repeated joint names).
    """
    tokens = _TokenStream(path, _tokens(lines, motion_line))
    reader = _NodeReader(tokens)
    first, line = tokens.take("'HIERARCHY'")
    if first != "HIERARCHY":
        raise MocapFormatError(path, line, f"expected 'HIERARCHY' at the start of a BVH file, found {first!r}")
    while tokens.more():
        tok, line = tokens.take("ROOT")
        if tok != "ROOT":
            raise MocapFormatError(path, line, f"expected ROOT or MOTION, found {tok!r}")
        reader.node("ROOT", -1)
    joints = reader.joints
    if not joints:
        raise MocapFormatError(path, tokens.last_line, "HIERARCHY declares no ROOT")
    names = [j.name for j in joints]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise MocapFormatError(path, None, f"joint names must be unique; repeated: {', '.join(duplicates)}")
    return joints
