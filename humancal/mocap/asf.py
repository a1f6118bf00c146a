"""Acclaim ASF skeleton files (the CMU motion capture database's format).

ASF describes a skeleton at rest: the root (AMC channel ``order``, ``axis`` and ``orientation``), then bones,
each with a ``direction`` (unit vector in the rest-pose world frame), a ``length``, an ``axis`` (Euler
angles with their order, giving the bone's local coordinate frame in the rest-pose world frame) and the
``dof`` rotated per frame (e.g. ``rx ry rz``); ``:hierarchy`` gives the tree. :mod:`humancal.mocap.asf_amc`
reads the motion (AMC) against it.

Units: CMU lengths are inches times the ``:units length`` value (0.45), so a file unit is
``0.0254 / 0.45 = 0.05644`` m (``docs/mocap.md`` gives the evidence: human statures with it, 2x off or worse
with any other reading).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humancal.mocap.clip import MocapFormatError
from humancal.mocap.reading import read_text_lines

__all__ = ["AsfBone", "AsfSkeleton", "read_asf", "INCH_M"]

INCH_M = 0.0254
"""Metres per inch."""

_ROOT_CHANNELS = ("tx", "ty", "tz", "rx", "ry", "rz")


@dataclass(frozen=True)
class AsfBone:
    """One bone of an ASF skeleton, in file units and the file's (Y-up) rest-pose world frame.

    Attributes:
        name: bone name; the joint at the bone's end carries it.
        parent: index of the parent bone in ``AsfSkeleton.bones``, -1 when the parent is the root.
        direction: (3,) unit vector from the bone's start to its end at rest.
        length: bone length, file units.
        axis_angles: (3,) Euler angles of the bone's local frame, in the skeleton's ``angle_unit`` (CMU: degrees),
            applied in ``axis_order``.
        axis_order: e.g. ``"xyz"``.
        dof: rotational degrees of freedom in AMC order, e.g. ``("rx", "ry", "rz")``; may be empty.
    """

    name: str
    parent: int
    direction: tuple[float, float, float]
    length: float
    axis_angles: tuple[float, float, float]
    axis_order: str
    dof: tuple[str, ...]


@dataclass(frozen=True)
class AsfSkeleton:
    """A parsed ASF file.

    Attributes:
        path: the file.
        length_unit: the ``:units length`` value (CMU: 0.45, i.e. one file unit is 1/0.45 inch).
        angle_unit: ``"deg"`` or ``"rad"``, from ``:units angle``.
        root_order: AMC channel order of the root, e.g. ``("tx", "ty", "tz", "rx", "ry", "rz")``.
        root_axis_order: order of the root ``orientation`` angles, e.g. ``"xyz"``.
        root_orientation: (3,) root orientation angles, in ``angle_unit``.
        bones: parents before children.
    """

    path: Path
    length_unit: float
    angle_unit: str
    root_order: tuple[str, ...]
    root_axis_order: str
    root_orientation: tuple[float, float, float]
    bones: tuple[AsfBone, ...]

    @property
    def metres_per_unit(self) -> float:
        """Metres per file length unit, ``0.0254 / length_unit`` (CMU's lengths are inches x length_unit)."""
        return INCH_M / self.length_unit

    @property
    def joint_names(self) -> tuple[str, ...]:
        """``("root", <bone names>...)``: the joints of a clip read with this skeleton."""
        return ("root",) + tuple(b.name for b in self.bones)

    @property
    def parents(self) -> tuple[int, ...]:
        """Parent index of each of :attr:`joint_names` (-1 for the root)."""
        return (-1,) + tuple(b.parent + 1 for b in self.bones)


def _floats(path: Path, line_no: int, parts: list[str], count: int, what: str) -> tuple[float, ...]:
    if len(parts) < count:
        raise MocapFormatError(path, line_no, f"expected {count} numbers for {what}, found {len(parts)}: {parts}")
    try:
        values = tuple(float(p) for p in parts[:count])
    except ValueError:
        raise MocapFormatError(path, line_no, f"expected {count} numbers for {what}, found {parts[:count]}") from None
    if not all(np.isfinite(values)):
        raise MocapFormatError(path, line_no, f"expected finite numbers for {what}, found {parts[:count]}")
    return values


def _axis_order(path: Path, line_no: int, token: str) -> str:
    order = token.lower()
    if len(order) != 3 or sorted(order) != ["x", "y", "z"]:
        raise MocapFormatError(path, line_no, f"expected an axis order such as XYZ, found {token!r}")
    return order


def _units_line(path: Path, no: int, key: str, parts: list[str], raw: str, units: dict) -> None:
    """Read a ``:units`` line (``length`` and ``angle``; others ignored) into ``units``."""
    if key == "length":
        units["length"] = _floats(path, no, parts[1:], 1, ":units length")[0]
        if units["length"] <= 0:
            raise MocapFormatError(path, no, f"expected a positive :units length, found {parts[1]}")
    elif key == "angle":
        if len(parts) < 2 or parts[1].lower() not in ("deg", "rad"):
            raise MocapFormatError(path, no, f"expected ':units angle deg|rad', found {raw.strip()!r}")
        units["angle"] = parts[1].lower()


def _root_line(path: Path, no: int, key: str, parts: list[str], root: dict) -> None:
    """Read a ``:root`` line (``order``, ``axis``, ``orientation``; others ignored) into ``root``."""
    if key == "order":
        root["order"] = tuple(p.lower() for p in parts[1:])
        unknown = [p for p in root["order"] if p not in _ROOT_CHANNELS]
        if unknown or len(set(root["order"])) != len(root["order"]):
            raise MocapFormatError(
                path, no, f"expected root order tokens from TX TY TZ RX RY RZ, found {parts[1:]}"
            )
    elif key == "axis":
        root["axis"] = _axis_order(path, no, parts[1] if len(parts) > 1 else "")
    elif key == "orientation":
        root["orientation"] = _floats(path, no, parts[1:], 3, "root orientation")


def _bone_field(path: Path, no: int, key: str, parts: list[str], current: dict) -> None:
    """Read one field line of an open bone block (``name``, ``direction``, ...; others ignored) into ``current``."""
    if key == "name":
        current["name"] = parts[1] if len(parts) > 1 else ""
    elif key == "direction":
        direction = np.array(_floats(path, no, parts[1:], 3, "bone direction"))
        norm = float(np.linalg.norm(direction))
        # A zero direction is legal for a zero-length bone (it then adds nothing).
        current["direction"] = tuple(direction / norm) if norm > 0 else (0.0, 0.0, 0.0)
    elif key == "length":
        current["length"] = _floats(path, no, parts[1:], 1, "bone length")[0]
    elif key == "axis":
        current["axis"] = _floats(path, no, parts[1:], 3, "bone axis")
        current["axis_order"] = _axis_order(path, no, parts[4] if len(parts) > 4 else "")
    elif key == "dof":
        dof = tuple(p.lower() for p in parts[1:])
        bad = [d for d in dof if d not in ("rx", "ry", "rz")]
        if bad:
            raise MocapFormatError(
                path, no, f"unsupported dof {bad} of bone {current.get('name')!r}; expected rx, ry, rz"
            )
        current["dof"] = dof


def _bonedata_line(
    path: Path, no: int, key: str, parts: list[str], current: dict | None, bones: dict[str, dict]
) -> dict | None:
    """Read a ``:bonedata`` line; returns the open bone block (``None`` after ``end``, which files it in ``bones``)."""
    if key == "begin":
        return {"line": no}
    if key == "end":
        if current is None or "name" not in current:
            raise MocapFormatError(path, no, "bone block without a 'name'")
        missing = [k for k in ("direction", "length", "axis") if k not in current]
        if missing:
            raise MocapFormatError(path, no, f"bone {current['name']!r} lacks {', '.join(missing)}")
        if current["name"] in bones or current["name"] == "root":
            raise MocapFormatError(path, current["line"], f"bone name {current['name']!r} repeated")
        bones[current["name"]] = current
        return None
    if current is None:
        raise MocapFormatError(path, no, f"expected 'begin' of a bone block, found {parts[0]!r}")
    _bone_field(path, no, key, parts, current)
    return current


def _hierarchy_line(
    path: Path, no: int, key: str, parts: list[str], children: dict[str, list[str]], child_line: dict[str, int]
) -> None:
    """Read a ``:hierarchy`` line (``parent child...``) into ``children``; a child's line goes to ``child_line``."""
    if key in ("begin", "end"):
        return
    for child in parts[1:]:
        if child in child_line:
            raise MocapFormatError(
                path, no, f"bone {child!r} has a second parent (first on line {child_line[child]})"
            )
        child_line[child] = no
    children.setdefault(parts[0], []).extend(parts[1:])


def _ordered_bones(
    path: Path, bones: dict[str, dict], children: dict[str, list[str]], child_line: dict[str, int]
) -> tuple[AsfBone, ...]:
    """The bones in depth-first order from the root (parents first), checked against the hierarchy."""
    for parent, kids in children.items():
        for name in [parent] + kids:
            if name != "root" and name not in bones:
                raise MocapFormatError(
                    path, child_line.get(name), f"hierarchy names bone {name!r}, absent from :bonedata"
                )
    ordered: list[AsfBone] = []
    stack = [(kid, -1) for kid in reversed(children.get("root", []))]
    while stack:
        name, parent = stack.pop()
        b = bones[name]
        ordered.append(AsfBone(name, parent, b["direction"], b["length"], b["axis"], b["axis_order"], b.get("dof", ())))
        stack.extend((kid, len(ordered) - 1) for kid in reversed(children.get(name, [])))
    unreachable = sorted(set(bones) - {b.name for b in ordered})
    if unreachable:
        raise MocapFormatError(path, None, f"bones not reachable from root in ':hierarchy': {', '.join(unreachable)}")
    return tuple(ordered)


def read_asf(path: str | Path) -> AsfSkeleton:
    """Parse an ASF skeleton file (plain or gzip).

    Args:
        path: ``.asf`` or ``.asf.gz`` file.

    Returns:
        The skeleton, bones ordered parents first.

    Raises:
        FileNotFoundError: no such file.
        MocapFormatError: naming the file, line and what was expected.
    """
    path = Path(path)
    lines = read_text_lines(path)
    section = None
    units = {"length": 1.0, "angle": "deg"}
    root: dict = {"order": None, "axis": "xyz", "orientation": (0.0, 0.0, 0.0)}
    bones: dict[str, dict] = {}
    current: dict | None = None
    children: dict[str, list[str]] = {}
    child_line: dict[str, int] = {}
    for i, raw in enumerate(lines):
        no = i + 1
        parts = raw.split("#", 1)[0].split()
        if not parts:
            continue
        key = parts[0].lower()
        if key.startswith(":"):
            section = key
            if section in (":name", ":version", ":documentation", ":skin"):
                continue
            if section not in (":units", ":root", ":bonedata", ":hierarchy"):
                raise MocapFormatError(path, no, f"unknown ASF section {parts[0]!r}")
            continue
        if section == ":units":
            _units_line(path, no, key, parts, raw, units)
        elif section == ":root":
            _root_line(path, no, key, parts, root)
        elif section == ":bonedata":
            current = _bonedata_line(path, no, key, parts, current, bones)
        elif section == ":hierarchy":
            _hierarchy_line(path, no, key, parts, children, child_line)
    if root["order"] is None:
        raise MocapFormatError(path, None, "no ':root' section with an 'order' line")
    if not bones:
        raise MocapFormatError(path, None, "no bones in ':bonedata'")
    ordered = _ordered_bones(path, bones, children, child_line)
    return AsfSkeleton(path, units["length"], units["angle"], root["order"], root["axis"], root["orientation"], ordered)
