"""A user's URDF as a kinematic tree: links, joints, their origins, axes and limits, read from the text.

:func:`read_urdf_tree` first validates the file (:func:`cpc2urdf.urdf.input.read_urdf`, one line
naming the file, element and line for anything a URDF parser would stumble on), then reads what
kinematics needs. It also remembers where each joint's ``<origin>`` and ``<axis>`` tags sit in the
text (byte offsets of the UTF-8 text), so that a calibrated URDF can be written by changing those
tags alone and leaving every other byte of the file as it was (:mod:`cpc2urdf.urdf.writeback`).

URDF conventions (m, rad): a joint's ``<origin>`` is the pose of its frame in its parent link's
frame, ``T_parent_joint``; the child link's frame is the joint frame moved by the joint:
``Rot(axis, q)`` (revolute, continuous) or ``Trans(axis q)`` (prismatic). A missing ``<origin>``
is the identity, a missing ``<axis>`` is ``1 0 0``, a missing ``lower``/``upper`` is 0.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from xml.parsers import expat

import numpy as np

from cpc2urdf.errors import InputFileError
from cpc2urdf.transforms import Array, homogeneous, matrix_from_rpy
from cpc2urdf.urdf.input import read_urdf, validate_urdf

MOVING = ("revolute", "continuous", "prismatic")  # the joint types a calibration identifies
CALIBRATABLE = (*MOVING, "fixed")  # the types a measured link's path may have


@dataclass(frozen=True)
class TagSpan:
    """Where an element's start tag sits in the UTF-8 bytes of the text.

    Attributes:
        start: Offset of its ``<``.
        end: Offset just past its ``>``.
        empty: True for ``<tag .../>`` (no end tag).
    """

    start: int
    end: int
    empty: bool


@dataclass(frozen=True, eq=False)
class UrdfJoint:
    """One ``<joint>`` as its file gives it.

    Attributes:
        name: Joint name.
        type: URDF type (``revolute``, ``continuous``, ``prismatic``, ``fixed``, ``floating``, ``planar``).
        parent: Parent link.
        child: Child link.
        xyz: ``<origin xyz>`` [m].
        rpy: ``<origin rpy>`` [rad].
        axis: ``<axis xyz>`` as written (``1 0 0`` when absent).
        lower: ``<limit lower>`` [rad] or [m] (0 when absent).
        upper: ``<limit upper>`` [rad] or [m] (0 when absent).
        velocity: ``<limit velocity>``, or None without a ``<limit>``.
        effort: ``<limit effort>``, or None without a ``<limit>``.
        line: Line of the ``<joint>`` tag.
        tag: Where the ``<joint ...>`` start tag is.
        origin_tag: Where its ``<origin>`` tag is, or None.
        axis_tag: Where its ``<axis>`` tag is, or None.
    """

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float
    upper: float
    velocity: float | None
    effort: float | None
    line: int
    tag: TagSpan
    origin_tag: TagSpan | None
    axis_tag: TagSpan | None

    @property
    def origin(self) -> Array:
        """``T_parent_joint``, shape (4, 4)."""
        return homogeneous(matrix_from_rpy(self.rpy), np.asarray(self.xyz, dtype=float))

    @property
    def unit_axis(self) -> Array:
        """The axis as a unit vector in the joint frame, shape (3,)."""
        a = np.asarray(self.axis, dtype=float)
        return a / np.linalg.norm(a)

    @property
    def moving(self) -> bool:
        """True for revolute, continuous and prismatic joints."""
        return self.type in MOVING

    def motion(self, q: float) -> Array:
        """``T_joint_child`` at reading ``q`` [rad] or [m], shape (4, 4)."""
        T = np.eye(4)
        if not self.moving:
            return T
        a = self.unit_axis
        if self.type in ("revolute", "continuous"):
            K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
            T[:3, :3] = np.eye(3) + math.sin(q) * K + (1.0 - math.cos(q)) * (K @ K)
        elif self.type == "prismatic":
            T[:3, 3] = a * q
        return T

    def kinematics(self) -> dict[str, object]:
        """What the joint contributes to kinematics, as JSON (type, links, origin, axis)."""
        return {
            "type": self.type,
            "parent": self.parent,
            "child": self.child,
            "xyz": list(self.xyz),
            "rpy": list(self.rpy),
            "axis": list(self.axis),
        }


@dataclass(frozen=True, eq=False)
class UrdfTree:
    """The kinematic tree of one URDF file.

    Attributes:
        source: The file (errors name it).
        text: Its text (validated).
        name: ``<robot name>``.
        root: The root link.
        links: Link names in file order.
        joints: Joint name -> :class:`UrdfJoint`, in file order.
        link_lines: Link name -> line of its ``<link>`` tag.
    """

    source: str
    text: str
    name: str
    root: str
    links: tuple[str, ...]
    joints: Mapping[str, UrdfJoint]
    link_lines: Mapping[str, int]

    def __post_init__(self) -> None:
        children: dict[str, list[UrdfJoint]] = {}
        for j in self.joints.values():
            children.setdefault(j.parent, []).append(j)
        object.__setattr__(self, "_parent", {j.child: j for j in self.joints.values()})
        object.__setattr__(self, "_children", children)

    def parent_joint(self, link: str) -> UrdfJoint | None:
        """The joint whose child is ``link`` (None for the root)."""
        parent: dict[str, UrdfJoint] = self._parent  # type: ignore[attr-defined]
        return parent.get(link)

    def path(self, link: str) -> list[UrdfJoint]:
        """The joints from the root to ``link``, root first (empty for the root)."""
        out: list[UrdfJoint] = []
        j = self.parent_joint(link)
        while j is not None:
            out.append(j)
            j = self.parent_joint(j.parent)
        return out[::-1]

    def children(self, link: str) -> list[UrdfJoint]:
        """Joints whose parent is ``link``, in file order."""
        children: dict[str, list[UrdfJoint]] = self._children  # type: ignore[attr-defined]
        return list(children.get(link, []))

    def has_link(self, link: str) -> bool:
        return link in self.link_lines

    def fk(self, q: Mapping[str, float] | None = None) -> dict[str, Array]:
        """``T_root_link`` of every link at readings ``q`` (URDF joint names; 0 where absent).

        The reference forward kinematics of the file itself, shape (4, 4) per link.
        """
        q = q or {}
        out = {self.root: np.eye(4)}
        todo = [self.root]
        while todo:
            link = todo.pop()
            for j in self.children(link):
                out[j.child] = out[link] @ j.origin @ j.motion(float(q.get(j.name, 0.0)))
                todo.append(j.child)
        return out


def _numbers(value: str | None, n: int, default: tuple[float, ...]) -> tuple[float, ...]:
    return (
        default if value is None else tuple(float(v) for v in value.split())
    )  # validated: n numbers


def _tag_end(data: bytes, start: int) -> tuple[int, bool]:
    """Offset just past the ``>`` of the start tag at ``start`` (quotes respected), and whether
    it is an empty-element tag."""
    quote = 0
    i = start + 1
    while i < len(data):
        c = data[i]
        if quote:
            if c == quote:
                quote = 0
        elif c in (0x22, 0x27):  # " or '
            quote = c
        elif c == 0x3E:  # >
            return i + 1, data[i - 1] == 0x2F  # /
        i += 1
    raise ValueError(f"unterminated tag at byte {start}")  # expat accepted the text: unreachable


def parse_urdf_tree(text: str, source: str | os.PathLike[str]) -> UrdfTree:
    """The tree of URDF ``text`` (validated first; see :func:`cpc2urdf.urdf.input.validate_urdf`).

    Raises:
        InputFileError: Naming ``source``, the element and its line.
    """
    validate_urdf(text, source)
    return _tree(text, source)


def _tree(text: str, source: str | os.PathLike[str]) -> UrdfTree:
    """The tree of a validated URDF ``text``."""
    data = text.encode("utf-8")
    parser = expat.ParserCreate()
    stack: list[str] = []
    links: dict[str, int] = {}
    joints: list[dict[str, object]] = []
    robot_name: list[str] = []

    def start(tag: str, attrib: dict[str, str]) -> None:
        depth = len(stack)
        stack.append(tag)
        offset = parser.CurrentByteIndex
        if depth == 0:
            robot_name.append(attrib.get("name", ""))
        elif depth == 1 and tag == "link":
            links[attrib["name"]] = parser.CurrentLineNumber
        elif depth == 1 and tag == "joint":
            end, empty = _tag_end(data, offset)
            joints.append(
                {
                    "attrib": attrib,
                    "line": parser.CurrentLineNumber,
                    "tag": TagSpan(offset, end, empty),
                }
            )
        elif (
            depth == 2
            and stack[1] == "joint"
            and tag in ("origin", "axis", "limit", "parent", "child")
        ):
            end, empty = _tag_end(data, offset)
            joints[-1].setdefault(tag, (attrib, TagSpan(offset, end, empty)))

    def end(tag: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.Parse(data, True)
    parsed: dict[str, UrdfJoint] = {}
    for j in joints:
        attrib: dict[str, str] = j["attrib"]  # type: ignore[assignment]
        origin = j.get("origin")
        axis = j.get("axis")
        limit = j.get("limit")
        o = origin[0] if origin else {}  # type: ignore[index]
        lim = limit[0] if limit else None  # type: ignore[index]
        parsed[attrib["name"]] = UrdfJoint(
            name=attrib["name"],
            type=attrib["type"],
            parent=j["parent"][0]["link"],  # type: ignore[index]
            child=j["child"][0]["link"],  # type: ignore[index]
            xyz=_numbers(o.get("xyz"), 3, (0.0, 0.0, 0.0)),  # type: ignore[arg-type]
            rpy=_numbers(o.get("rpy"), 3, (0.0, 0.0, 0.0)),  # type: ignore[arg-type]
            axis=_numbers(axis[0].get("xyz") if axis else None, 3, (1.0, 0.0, 0.0)),  # type: ignore[arg-type, index]
            lower=float(lim.get("lower", 0.0)) if lim else 0.0,
            upper=float(lim.get("upper", 0.0)) if lim else 0.0,
            velocity=float(lim["velocity"]) if lim and "velocity" in lim else None,
            effort=float(lim["effort"]) if lim and "effort" in lim else None,
            line=j["line"],  # type: ignore[arg-type]
            tag=j["tag"],  # type: ignore[arg-type]
            origin_tag=origin[1] if origin else None,  # type: ignore[index]
            axis_tag=axis[1] if axis else None,  # type: ignore[index]
        )
    children = {j.child for j in parsed.values()}
    root = next(n for n in links if n not in children)  # validate_urdf: exactly one root
    return UrdfTree(str(source), text, robot_name[0], root, tuple(links), parsed, links)


def read_urdf_tree(path: str | os.PathLike[str]) -> UrdfTree:
    """The tree of the URDF file ``path``.

    Raises:
        InputFileError: Missing, unreadable, or a problem :func:`cpc2urdf.urdf.input.validate_urdf`
            names (file, element, line).
    """
    return _tree(read_urdf(path), path)


def link_error(tree: UrdfTree, link: str, what: str) -> InputFileError:
    """An error naming a link of ``tree`` that is missing (``what`` says who asked for it)."""
    known = ", ".join(tree.links[:8]) + (" ..." if len(tree.links) > 8 else "")
    return InputFileError(tree.source, f"no link {link!r} ({what}); links: {known}")


__all__ = [
    "CALIBRATABLE",
    "MOVING",
    "TagSpan",
    "UrdfJoint",
    "UrdfTree",
    "link_error",
    "parse_urdf_tree",
    "read_urdf_tree",
]
