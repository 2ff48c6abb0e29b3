"""Reading a user's URDF: the rules every URDF parser needs, checked once, before any of them.

Pinocchio (urdfdom, in-process), yourdfpy (lxml) and urdfdom's ``check_urdf`` each react in their
own way to a broken file: C++ complaints on the terminal, a traceback, or a silent fallback (urdfdom
drops a visual it cannot parse; Python's ``float`` reads ``"nan"``). :func:`validate_urdf` checks a
URDF against what all of them need and turns the first problem into one
:class:`~cpc2urdf.errors.InputFileError` naming the file, the element, its line and what was
expected, e.g. ``head.urdf: joint 'pan': origin xyz 'nan 0 0' is not finite (line 40)``:

- well-formed XML (no entity declarations, UTF-8, at most :data:`URDF_MAX_DEPTH` elements deep),
  whose root is a named ``<robot>``;
- links, joints and materials named and unique, at least one link;
- every joint of a URDF type, with ``<parent link>`` and ``<child link>`` naming links of the file;
  revolute and prismatic joints with a ``<limit effort velocity>``; a moving joint's axis not zero;
- the links form one tree: each link the child of at most one joint, one root, no cycle;
- visuals and collisions with one known shape (box, cylinder, sphere, mesh) and its attributes;
  inertials with a mass and the six inertia values;
- every number of an origin, axis, limit, safety controller, calibration, dynamics, mimic, mass,
  inertia, shape or colour: a decimal number (the grammar C's ``strtod`` and Python's ``float``
  read alike), finite, and as many as the attribute takes; shape sizes and masses not negative.

Frames and units are the URDF's own (m, rad); nothing here changes the file.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.jsonio import read_text_file

URDF_MAX_DEPTH = 64  # XML elements deep; a URDF needs 5 (robot/link/visual/geometry/box)
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
MOVING_TYPES = ("revolute", "continuous", "prismatic", "planar")  # those with an axis
SHAPES = {
    "box": ("size",),
    "cylinder": ("radius", "length"),
    "sphere": ("radius",),
    "mesh": ("filename",),
}
# element -> numeric attribute -> how many numbers it holds
NUMBERS: dict[str, dict[str, int]] = {
    "origin": {"xyz": 3, "rpy": 3},
    "axis": {"xyz": 3},
    "limit": {"lower": 1, "upper": 1, "effort": 1, "velocity": 1},
    "safety_controller": {
        "soft_lower_limit": 1,
        "soft_upper_limit": 1,
        "k_position": 1,
        "k_velocity": 1,
    },
    "calibration": {"rising": 1, "falling": 1, "reference_position": 1},
    "dynamics": {"damping": 1, "friction": 1},
    "mimic": {"multiplier": 1, "offset": 1},
    "mass": {"value": 1},
    "inertia": {name: 1 for name in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")},
    "box": {"size": 3},
    "cylinder": {"radius": 1, "length": 1},
    "sphere": {"radius": 1},
    "mesh": {"scale": 3},
    "color": {"rgba": 4},
}
# Sizes and masses: a negative one describes no body (urdfdom and Pinocchio read it without a word).
NON_NEGATIVE = frozenset(
    {
        ("box", "size"),
        ("cylinder", "radius"),
        ("cylinder", "length"),
        ("sphere", "radius"),
        ("mass", "value"),
    }
)
# The URDF elements below a link, joint or material; others (<gazebo>, ...) are no parser's business here.
URDF_ELEMENTS = frozenset(
    {"visual", "collision", "inertial", "geometry", "material", "texture", *NUMBERS}
)
_DECIMAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")


@dataclass(eq=False)
class _Element:
    tag: str
    attrib: dict[str, str]
    line: int
    children: list[_Element] = field(default_factory=list)

    def all(self, tag: str) -> list[_Element]:
        return [c for c in self.children if c.tag == tag]

    def first(self, tag: str) -> _Element | None:
        return next((c for c in self.children if c.tag == tag), None)


class _Refused(Exception):
    """Raised from an expat handler: the XML is well-formed but not something we read."""


def _quote(value: str, limit: int = 60) -> str:
    """``value`` quoted on one line (``repr`` escapes newlines), shortened past ``limit``."""
    return repr(value if len(value) <= limit else value[: limit - 3] + "...")


def _count(n: int) -> str:
    return "a number" if n == 1 else f"{n} numbers"


def _parse_xml(text: str) -> _Element:
    """The element tree of ``text`` with line numbers; ``ValueError`` with the reason if it is
    not well-formed XML we read."""
    if not text.strip():
        raise ValueError("is empty, expected a URDF file")
    parser = expat.ParserCreate()
    root: list[_Element] = []
    stack: list[_Element] = []

    def start(tag: str, attrib: dict[str, str]) -> None:
        el = _Element(tag, attrib, parser.CurrentLineNumber)
        if stack:
            stack[-1].children.append(el)
        else:
            root.append(el)
        stack.append(el)
        if len(stack) > URDF_MAX_DEPTH:
            raise _Refused(f"elements nested more than {URDF_MAX_DEPTH} deep (line {el.line})")

    def end(tag: str) -> None:
        stack.pop()

    def entity(name: str, *_: object) -> None:
        # Parsers differ on DTD entities (TinyXML2 ignores them, lxml and expat expand them).
        raise _Refused(
            f"declares the XML entity {name!r} (line {parser.CurrentLineNumber}); URDF files use none"
        )

    def instruction(target: str, data: str) -> None:
        # TinyXML2 (urdfdom) reads <?...?> only as the XML declaration.
        raise _Refused(
            f"has the processing instruction <?{target} ...?> (line {parser.CurrentLineNumber}); URDF files use none"
        )

    def declaration(version: str, encoding: str | None, standalone: int) -> None:
        if encoding is not None and encoding.lower().replace("_", "-") not in (
            "utf-8",
            "utf8",
            "us-ascii",
            "ascii",
        ):
            raise _Refused(f"declares encoding {encoding!r}; URDF files are read as UTF-8")

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.EntityDeclHandler = entity
    parser.XmlDeclHandler = declaration
    parser.ProcessingInstructionHandler = instruction
    try:
        parser.Parse(text, True)
    except expat.ExpatError as e:
        raise ValueError(
            f"not well-formed XML ({expat.ErrorString(e.code)}: line {e.lineno}, column {e.offset})"
        ) from None
    except _Refused as e:
        raise ValueError(str(e)) from None
    return root[0]


class _Checker:
    """Collects the problems of one URDF tree, in file order."""

    def __init__(self) -> None:
        self.problems: list[str] = []

    def add(self, owner: str, what: str, el: _Element | None) -> None:
        """A problem of ``owner`` (``"joint 'pan'"``, or ``""`` when ``what`` names it) at ``el``'s line."""
        where = f" (line {el.line})" if el is not None else ""
        self.problems.append(f"{owner}{': ' if owner else ''}{what}{where}")

    def numbers(self, owner: str, el: _Element, path: str = "", depth: int = 0) -> None:
        """Every numeric attribute in ``el``'s subtree; ``path`` names the elements between the
        owner (a link, joint or material, ``depth`` 0) and ``el``: ``"visual 'v' "``."""
        for attr, n in NUMBERS.get(el.tag, {}).items():
            if attr in el.attrib:
                found = len(self.problems)
                self.number(owner, f"{path}{el.tag} {attr}", el.attrib[attr], n, el)
                if (
                    (el.tag, attr) in NON_NEGATIVE
                    and len(self.problems) == found
                    and any(float(v) < 0 for v in el.attrib[attr].split())
                ):
                    self.add(
                        owner, f"{path}{el.tag} {attr} {_quote(el.attrib[attr])} is negative", el
                    )
        below = (
            f"{path}{el.tag}{' ' + _quote(el.attrib['name']) if 'name' in el.attrib else ''} "
            if depth
            else ""
        )
        for child in el.children:
            if child.tag in URDF_ELEMENTS:
                self.numbers(owner, child, below, depth + 1)

    def number(self, owner: str, what: str, value: str, n: int, el: _Element) -> None:
        """One attribute of ``n`` numbers: decimal, finite, ``n`` of them."""
        parts = value.split()
        for part in parts:
            if _DECIMAL.match(part):
                finite = math.isfinite(float(part))  # "1e999" overflows
            elif part.lower().lstrip("+-") in ("nan", "inf", "infinity"):
                finite = False
            else:
                hint = " (an unexpanded xacro expression? run xacro first)" if "${" in value else ""
                self.add(owner, f"{what} {_quote(value)} is not {_count(n)}{hint}", el)
                return
            if not finite:
                self.add(owner, f"{what} {_quote(value)} is not finite", el)
                return
        if len(parts) != n:
            self.add(owner, f"{what} {_quote(value)} is not {_count(n)}", el)

    def named(self, kind: str, el: _Element, seen: dict[str, _Element]) -> str | None:
        name = el.attrib.get("name")
        if name is None:
            self.add("", f"a <{kind}> has no name attribute", el)
            return None
        if name in seen:
            self.add(
                "",
                f"{kind} {_quote(name)} is defined twice (lines {seen[name].line} and {el.line})",
                None,
            )
            return None
        seen[name] = el
        return name

    def shape(self, owner: str, part: _Element) -> None:
        what = f"{part.tag}{' ' + _quote(part.attrib['name']) if 'name' in part.attrib else ''}"
        geometry = part.first("geometry")
        if geometry is None:
            self.add(owner, f"{what} has no <geometry>", part)
            return
        if not geometry.children:
            self.add(
                owner, f"{what} geometry has no shape (box, cylinder, sphere or mesh)", geometry
            )
            return
        shape = geometry.children[0]
        if shape.tag not in SHAPES:
            self.add(
                owner,
                f"{what} geometry <{shape.tag}> is not a URDF shape (box, cylinder, sphere or mesh)",
                shape,
            )
            return
        for attr in SHAPES[shape.tag]:
            if attr not in shape.attrib:
                self.add(owner, f"{what} geometry {shape.tag} has no {attr} attribute", shape)
        if part.tag == "visual":
            for material in part.all("material"):
                if "name" not in material.attrib:
                    self.add(owner, f"{what} material has no name attribute", material)

    def link(self, name: str, el: _Element) -> None:
        owner = f"link {_quote(name)}"
        for part in el.all("visual") + el.all("collision"):
            self.shape(owner, part)
        for inertial in el.all("inertial"):
            mass = inertial.first("mass")
            if mass is None or "value" not in mass.attrib:
                self.add(owner, "inertial has no <mass value>", inertial)
            inertia = inertial.first("inertia")
            missing = [a for a in NUMBERS["inertia"] if inertia is None or a not in inertia.attrib]
            if missing:
                self.add(
                    owner,
                    f"inertial has no <inertia> {', '.join(missing)}",
                    inertial if inertia is None else inertia,
                )
        self.numbers(owner, el)

    def joint(
        self, name: str, el: _Element, links: dict[str, _Element], joints: set[str]
    ) -> tuple[str, str] | None:
        owner = f"joint {_quote(name)}"
        kind = el.attrib.get("type")
        if kind is None:
            self.add("", f"{owner} has no type attribute", el)
        elif kind not in JOINT_TYPES:
            self.add(
                owner,
                f"type {_quote(kind)} is not a URDF joint type ({', '.join(JOINT_TYPES)})",
                el,
            )
        ends = []
        for end in ("parent", "child"):
            e = el.first(end)
            if e is None or "link" not in e.attrib:
                self.add("", f"{owner} has no <{end} link=...>", el if e is None else e)
            elif e.attrib["link"] not in links:
                self.add(
                    owner, f"{end} link {_quote(e.attrib['link'])} is not a link of this URDF", e
                )
            else:
                ends.append(e.attrib["link"])
        if kind in ("revolute", "prismatic"):
            limit = el.first("limit")
            if limit is None:
                self.add("", f"{owner} is {kind} but has no <limit>", el)
            else:
                for attr in ("effort", "velocity"):
                    if attr not in limit.attrib:
                        self.add(owner, f"limit has no {attr} attribute", limit)
                    elif (
                        _DECIMAL.match(limit.attrib[attr].strip()) and float(limit.attrib[attr]) < 0
                    ):
                        self.add(
                            owner, f"limit {attr} {_quote(limit.attrib[attr])} is negative", limit
                        )
        mimic = el.first("mimic")
        if mimic is not None and mimic.attrib.get("joint") not in joints:
            self.add(
                owner,
                f"mimic joint {_quote(mimic.attrib.get('joint', ''))} is not a joint of this URDF",
                mimic,
            )
        n_before = len(self.problems)
        self.numbers(owner, el)
        axis = el.first("axis")
        if (
            kind in MOVING_TYPES
            and axis is not None
            and "xyz" in axis.attrib
            and len(self.problems) == n_before
        ):
            xyz = [float(v) for v in axis.attrib["xyz"].split()]
            if not any(xyz):
                self.add(owner, f"axis xyz {_quote(axis.attrib['xyz'])} is zero", axis)
        if len(ends) == 2 and ends[0] == ends[1]:
            self.add(owner, f"parent and child are the same link {_quote(ends[0])}", el)
            return None
        return (ends[0], ends[1]) if len(ends) == 2 else None

    def tree(
        self,
        links: dict[str, _Element],
        edges: dict[str, tuple[str, str]],
        joint_el: dict[str, _Element],
    ) -> None:
        """One tree: each link the child of at most one joint, one root, every link reachable."""
        parent_joint: dict[str, str] = {}
        for joint, (_, child) in edges.items():
            if child in parent_joint:
                self.add(
                    f"joint {_quote(joint)}",
                    f"link {_quote(child)} is already the child of joint "
                    f"{_quote(parent_joint[child])}; a link has one parent",
                    joint_el[joint],
                )
            else:
                parent_joint[child] = joint
        if self.problems:
            return
        roots = [n for n in links if n not in parent_joint]
        if len(roots) > 1:
            self.add(
                "",
                f"links {', '.join(_quote(r) for r in roots[:4])}{' ...' if len(roots) > 4 else ''} are "
                "all roots (the child of no joint); a URDF is one tree",
                links[roots[1]],
            )
            return
        children: dict[str, list[str]] = {}
        for parent, child in edges.values():
            children.setdefault(parent, []).append(child)
        reached = set(roots)
        todo = list(roots)
        while todo:
            for child in children.get(todo.pop(), []):
                if child not in reached:
                    reached.add(child)
                    todo.append(child)
        cycle = [n for n in links if n not in reached]
        if cycle:
            self.add(
                "",
                f"the joints of links {', '.join(_quote(c) for c in cycle[:4])}"
                f"{' ...' if len(cycle) > 4 else ''} form a cycle; a URDF is a tree",
                links[cycle[0]],
            )

    def robot(self, root: _Element) -> None:
        if root.tag != "robot":
            self.add("", f"the root element is <{root.tag}>, expected <robot>", root)
            return
        if "name" not in root.attrib:
            self.add("", "<robot> has no name attribute", root)
        macro = next((el for el in root.children if el.tag.startswith("xacro:")), None)
        if macro is not None:  # (an expanded file may keep xmlns:xacro on <robot>: not a sign)
            self.add(
                "",
                f"is a xacro file (<{macro.tag}>), not a URDF: expand it first (xacro FILE > FILE.urdf)",
                macro,
            )
            return
        if root.attrib.get("version", "1.0") != "1.0":  # urdfdom reads only version 1.0
            self.add("", f"<robot> version {_quote(root.attrib['version'])} is not 1.0", root)
        links: dict[str, _Element] = {}
        joints: dict[str, _Element] = {}
        materials: dict[str, _Element] = {}
        edges: dict[str, tuple[str, str]] = {}  # joint -> (parent link, child link)
        for el in root.all("link"):
            self.named("link", el, links)
        if not links and not self.problems:
            self.add("", "<robot> has no <link>", root)
        for el in root.all("joint"):
            self.named("joint", el, joints)
        for el in root.children:
            if el.tag == "material" and self.named("material", el, materials) is not None:
                owner = f"material {_quote(el.attrib['name'])}"
                color, texture = el.first("color"), el.first("texture")
                if (color is None or "rgba" not in color.attrib) and (
                    texture is None or "filename" not in texture.attrib
                ):
                    self.add("", f"{owner} has no <color rgba> and no <texture filename>", el)
                self.numbers(owner, el)
            elif el.tag == "link" and links.get(el.attrib.get("name", "")) is el:
                self.link(el.attrib["name"], el)
            elif el.tag == "joint" and joints.get(el.attrib.get("name", "")) is el:
                ends = self.joint(el.attrib["name"], el, links, set(joints))
                if ends is not None:
                    edges[el.attrib["name"]] = ends
        if not self.problems:
            self.tree(links, edges, joints)


def urdf_problems(text: str) -> list[str]:
    """Every problem :func:`validate_urdf` would name in ``text`` (empty if none), in file order."""
    try:
        root = _parse_xml(text)
    except ValueError as e:
        return [str(e)]
    checker = _Checker()
    checker.robot(root)
    return checker.problems


def validate_urdf(text: str, source: object) -> None:
    """Refuse ``text`` unless it is a URDF every parser reads the same way (module docstring).

    Args:
        text: The URDF.
        source: What errors name (the file's path, or e.g. ``"<URDF string>"``).

    Raises:
        InputFileError: The first problem, with how many more there are.
    """
    problems = urdf_problems(text)
    if problems:
        more = (
            f" (and {len(problems) - 1} more problem{'s' if len(problems) > 2 else ''})"
            if len(problems) > 1
            else ""
        )
        raise InputFileError(source, problems[0] + more)


def read_urdf(path: str | os.PathLike[str]) -> str:
    """The text of the URDF file ``path``, validated (:func:`validate_urdf`).

    Raises:
        InputFileError: Missing, a folder, binary or not UTF-8, or a problem :func:`validate_urdf` names.
    """
    text = read_text_file(Path(path), "a URDF file", encoding="utf-8-sig")
    validate_urdf(text, path)
    return text


__all__ = [
    "JOINT_TYPES",
    "MOVING_TYPES",
    "NUMBERS",
    "SHAPES",
    "URDF_ELEMENTS",
    "URDF_MAX_DEPTH",
    "read_urdf",
    "urdf_problems",
    "validate_urdf",
]
