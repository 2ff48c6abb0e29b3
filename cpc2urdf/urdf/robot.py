"""A user's URDF as a robot description: its tree in CPC form (:mod:`cpc2urdf.model`).

The mapping, one to one and exact (``T_a_b`` = pose of b in a):

- The URDF's root link is ``base``; ``world`` is the measuring system, placed by ``T_world_base``
  (identity in the nominal model: the URDF does not know where the robot stands).
- Each moving joint (revolute, prismatic; ``continuous`` is read as revolute with limits
  [-pi, pi]) is a CPC joint. Its *axis frame* is the URDF joint frame turned so that z lies on the
  joint axis: ``T_joint_axis = R(a)``, the minimal rotation taking z onto the unit axis ``a``
  (eq. (4); for ``a = -z`` exactly, a half turn about x). The rotation is recorded per joint so
  that write-back inverts it exactly. The child link's frame is then ``T_axislink_child = R(a)^T``.
- Fixed joints are folded into the CPC constants of what follows them: a joint's constants place
  its axis frame on the CPC link frame of the nearest moving joint above it (or on ``base``)
  through every fixed joint in between.
- Named frames are URDF links.

**Which links.** With measured links (a measurement file's pose/point keys), only the joints on
the paths from the root to those links are modelled, the links are the frames (kind ``"plate"``),
and everything else in the URDF is carried along untouched for write-back. A joint on such a path
that cannot be calibrated (floating, planar) is refused, naming it; elsewhere in the file it does
not matter. A measured link must hang on a fixed joint (it is the target: a plate, marker or
camera link; add a ``<link>`` with a fixed joint if the target sits elsewhere), because the
identified placement of a link carried directly by a moving joint need not lie on that joint's
axis, which a URDF cannot express. Without measured links (``load_robot("robot.urdf")`` for
``export``, ``gaze``, ``view``, ``check``), every link reachable from the root through
calibratable joints is a frame (kind ``"frame"``).

**Names.** Joint and frame names of the CPC model are the URDF's where they are legal there; a
name ending in ``_joint``/``_link`` or equal to ``base``/``world`` (which the CPC model reserves)
loses that suffix, or gets ``_axis`` (joints) / ``_frame`` (links) where it would clash. Files
the user writes and reads (measurement files, the calibrated URDF, the calibration report) use
the URDF's own names; the model file records the mapping (:class:`UrdfSource`).
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from cpc2urdf.errors import Cpc2UrdfError, InputFileError
from cpc2urdf.files.spec import DEFAULT_EFFORT, DEFAULT_VELOCITY, RobotSpec
from cpc2urdf.model import (
    BASE,
    IDENTITY,
    RESERVED_NAMES,
    CPCModel,
    CPCParams,
    Frame,
    Joint,
    RobotStructure,
)
from cpc2urdf.model_metadata import ModelMetadata
from cpc2urdf.transforms import Array, cpc_rotation, homogeneous
from cpc2urdf.urdf.tree import CALIBRATABLE, UrdfJoint, UrdfTree, link_error, read_urdf_tree

URDF_SECTION = "urdf"  # the model file section (cpc2urdf.files.model_file)


def _legal(name: str) -> bool:
    return bool(name) and name not in RESERVED_NAMES and not name.endswith(("_link", "_joint"))


@dataclass(frozen=True)
class NameMap:
    """CPC names of a URDF's joints and links (module docstring, "Names").

    Attributes:
        joints: URDF joint -> CPC joint name.
        links: URDF link -> CPC frame name.
    """

    joints: Mapping[str, str]
    links: Mapping[str, str]

    @classmethod
    def of(cls, tree: UrdfTree) -> NameMap:
        """The names of every joint and link of ``tree`` (joints first, each in file order)."""
        taken: set[str] = set()
        out: dict[str, dict[str, str]] = {"joint": {}, "link": {}}
        groups = (("joint", list(tree.joints)), ("link", list(tree.links)))
        for kind, names in groups:  # legal names stay as they are
            for n in names:
                if _legal(n) and n not in taken:
                    out[kind][n] = n
                    taken.add(n)
        for kind, names in groups:
            for n in names:
                if n in out[kind]:
                    continue
                stem = n.removesuffix(f"_{kind}")
                candidates = [stem, f"{stem}_{'axis' if kind == 'joint' else 'frame'}"]
                name = next((c for c in candidates if _legal(c) and c not in taken), None)
                k = 2
                while name is None:
                    c = f"{candidates[1]}_{k}"
                    name = c if c not in taken else None
                    k += 1
                out[kind][n] = name
                taken.add(name)
        return cls(out["joint"], out["link"])

    def urdf_joint(self, cpc: str) -> str:
        """The URDF joint a CPC joint name stands for (the name itself if unknown)."""
        return next((u for u, c in self.joints.items() if c == cpc), cpc)

    def urdf_link(self, cpc: str) -> str:
        """The URDF link a CPC frame name stands for (the name itself if unknown)."""
        return next((u for u, c in self.links.items() if c == cpc), cpc)


@dataclass(frozen=True)
class UrdfSource:
    """What a model built from a URDF remembers of it: the model file's ``"urdf"`` section.

    Attributes:
        path: The URDF file (absolute).
        robot: Its ``<robot name>``.
        root: Its root link (the model's ``base``).
        sha256: SHA-256 of its text when the model was made (informative).
        joints: CPC joint -> URDF joint.
        frames: CPC frame -> URDF link.
        axis_rotations: CPC joint -> ``T_joint_axis`` rotation ``R(a)`` (z onto the URDF axis),
            shape (3, 3) as nested tuples.
        kinematics: URDF joint -> its type, links, origin and axis, for every joint the model's
            constants depend on (write-back refuses a file where one of them changed).
    """

    path: str
    robot: str
    root: str
    sha256: str
    joints: Mapping[str, str]
    frames: Mapping[str, str]
    axis_rotations: Mapping[str, tuple[tuple[float, ...], ...]]
    kinematics: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def axis_rotation(self, joint: str) -> Array:
        """``R(a)`` of CPC joint ``joint``, shape (3, 3)."""
        return np.array(self.axis_rotations[joint], dtype=float)

    def urdf_link(self, frame: str) -> str:
        """The URDF link of CPC frame ``frame`` (a frame added later, e.g. a camera from hand-eye
        calibration, is its own URDF link name)."""
        return self.frames.get(frame, frame)

    def to_json(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "robot": self.robot,
            "root": self.root,
            "sha256": self.sha256,
            "joints": [
                {"name": c, "urdf": u, "axis_rotation": [list(r) for r in self.axis_rotations[c]]}
                for c, u in self.joints.items()
            ],
            "frames": [{"name": c, "urdf": u} for c, u in self.frames.items()],
            "kinematics": {j: dict(k) for j, k in self.kinematics.items()},
        }

    @classmethod
    def from_json(cls, d: Any) -> UrdfSource:
        """Parse the section (``ValueError`` naming what is wrong)."""
        try:
            joints = {str(e["name"]): str(e["urdf"]) for e in d["joints"]}
            rotations = {}
            for e in d["joints"]:
                R = np.asarray(e["axis_rotation"], dtype=float)
                if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
                    raise ValueError(
                        f"joint {e['name']!r}: axis_rotation must be a 3x3 rotation matrix"
                    )
                rotations[str(e["name"])] = tuple(tuple(float(v) for v in row) for row in R)
            return cls(
                path=str(d["path"]),
                robot=str(d["robot"]),
                root=str(d["root"]),
                sha256=str(d.get("sha256", "")),
                joints=joints,
                frames={str(e["name"]): str(e["urdf"]) for e in d["frames"]},
                axis_rotations=rotations,
                kinematics={str(j): dict(k) for j, k in d.get("kinematics", {}).items()},
            )
        except (KeyError, TypeError, AttributeError) as e:
            raise ValueError(f"bad {URDF_SECTION!r} section: missing or malformed {e}") from e
        except ValueError as e:
            raise ValueError(f"bad {URDF_SECTION!r} section: {e}") from e


@dataclass(frozen=True)
class UrdfModelMetadata(ModelMetadata):
    """:class:`~cpc2urdf.model_metadata.ModelMetadata` of a model built from a URDF: ``urdf``
    names the source, so that the calibrated model can be written back into it."""

    urdf: UrdfSource | None = None


def urdf_source(model: CPCModel) -> UrdfSource | None:
    """The URDF ``model`` was built from, or None."""
    return model.metadata.urdf if isinstance(model.metadata, UrdfModelMetadata) else None


def with_urdf_source(model: CPCModel, source: UrdfSource | None) -> CPCModel:
    """A copy of ``model`` that remembers ``source`` (or forgets it, with None)."""
    meta = model.metadata
    kept = {f.name: getattr(meta, f.name) for f in fields(ModelMetadata)}
    return model.with_params(metadata=UrdfModelMetadata(**kept, urdf=source))


@dataclass
class UrdfRobot(RobotSpec):
    """A robot spec read from a URDF (:class:`~cpc2urdf.files.spec.RobotSpec` plus the file's tree).

    Attributes:
        tree: The whole URDF.
        names: CPC names of its joints and links.
        measured: The measured links the structure was built for, or None (every link).
    """

    tree: UrdfTree | None = None
    names: NameMap | None = None
    measured: tuple[str, ...] | None = None

    def restricted(self, links: Iterable[str]) -> UrdfRobot:
        """The robot of the sub-tree on the paths from the root to the measured ``links``."""
        assert self.tree is not None
        return urdf_robot(self.tree, links)

    def cpc_joint(self, urdf_joint: str) -> str | None:
        """CPC name of a URDF joint, or None if it is not in the model."""
        assert self.names is not None
        name = self.names.joints.get(urdf_joint)
        return name if name in self.structure.joint_names else None

    def cpc_frame(self, urdf_link: str) -> str | None:
        """CPC name of a URDF link that is a frame of the model, or None."""
        assert self.names is not None
        name = self.names.links.get(urdf_link)
        return name if name in self.structure.frame_names else None


def _limits(j: UrdfJoint, source: str) -> tuple[str, float, float, float, float]:
    kind = "prismatic" if j.type == "prismatic" else "revolute"
    lower, upper = (-math.pi, math.pi) if j.type == "continuous" else (j.lower, j.upper)
    if lower > upper:
        raise InputFileError(
            source, f"joint {j.name!r}: limit lower {lower:g} > upper {upper:g} (line {j.line})"
        )
    velocity = j.velocity if j.velocity is not None and j.velocity > 0 else DEFAULT_VELOCITY[kind]
    effort = j.effort if j.effort is not None and j.effort > 0 else DEFAULT_EFFORT[kind]
    return kind, lower, upper, velocity, effort


def _check_measured(tree: UrdfTree, links: list[str]) -> None:
    for link in links:
        if not tree.has_link(link):
            raise link_error(tree, link, "a measured link")
        parent = tree.parent_joint(link)
        if parent is None:
            raise InputFileError(
                tree.source,
                f"link {link!r} is the root of the tree (the robot's base), "
                "not a measured link; measure a link fixed to it",
            )
        if parent.moving:
            raise InputFileError(
                tree.source,
                f"measured link {link!r} is moved by joint {parent.name!r} ({parent.type}, line {parent.line}) "
                'directly; a measured link must hang on a fixed joint (add <link name="marker"/> with a '
                f"fixed joint to {link!r} where the target is)",
            )
        for j in tree.path(link):
            if j.type not in CALIBRATABLE:
                raise InputFileError(
                    tree.source,
                    f"joint {j.name!r} ({j.type}, line {j.line}) is on the path from the root link "
                    f"{tree.root!r} to the measured link {link!r}; cpc2urdf calibrates revolute, continuous, "
                    "prismatic and fixed joints",
                )


def _reachable_links(tree: UrdfTree) -> list[str]:
    """Links reachable from the root through calibratable joints (root excluded), file order."""
    reached = {tree.root}
    todo = [tree.root]
    while todo:
        for j in tree.children(todo.pop()):
            if j.type in CALIBRATABLE:
                reached.add(j.child)
                todo.append(j.child)
    return [n for n in tree.links if n in reached and n != tree.root]


def urdf_robot(tree: UrdfTree, measured: Iterable[str] | None = None) -> UrdfRobot:
    """The robot of ``tree`` (module docstring): the sub-tree of the ``measured`` links, or with
    ``measured=None`` every link reachable from the root through calibratable joints.

    Raises:
        InputFileError: Naming the URDF and the element: a measured link that is not in it, that
            is its root or is moved directly by a joint; a joint on a measured link's path that
            cannot be calibrated (floating, planar); limits lower > upper; no moving joint.
    """
    links = list(dict.fromkeys(measured)) if measured is not None else _reachable_links(tree)
    if measured is not None:
        _check_measured(tree, links)
    names = NameMap.of(tree)
    on_paths: dict[str, UrdfJoint] = {}
    for link in links:  # root-first paths: a joint comes after every joint above it
        for j in tree.path(link):
            on_paths.setdefault(j.name, j)
    owner: dict[str, str] = {tree.root: BASE}  # link -> CPC joint whose link frame carries it
    T_owner: dict[str, Array] = {tree.root: np.eye(4)}  # link -> pose in that link frame
    joints: list[Joint] = []
    params: dict[str, CPCParams] = {}
    rotations: dict[str, tuple[tuple[float, ...], ...]] = {}
    for j in on_paths.values():
        K, T_K_parent = owner[j.parent], T_owner[j.parent]
        if j.moving:
            name = names.joints[j.name]
            kind, lower, upper, velocity, effort = _limits(j, tree.source)
            R = cpc_rotation(j.unit_axis)  # T_joint_axis: z onto the axis, eq. (4)
            joints.append(Joint(name, kind, K, lower, upper, velocity, effort))
            params[name] = CPCParams.from_matrix(
                T_K_parent @ j.origin @ homogeneous(R, np.zeros(3))
            )
            rotations[name] = tuple(tuple(float(v) for v in row) for row in R)
            owner[j.child], T_owner[j.child] = name, homogeneous(R.T, np.zeros(3))
        else:
            owner[j.child], T_owner[j.child] = K, T_K_parent @ j.origin
    if not joints:
        what = f"the measured links {links}" if measured is not None else "its links"
        raise InputFileError(
            tree.source,
            f"no revolute, continuous or prismatic joint between the root link "
            f"{tree.root!r} and {what}: nothing to calibrate",
        )
    kind = "plate" if measured is not None else "frame"
    frames = [Frame(names.links[n], owner[n], kind) for n in links]
    frame_params = {names.links[n]: CPCParams.from_matrix(T_owner[n]) for n in links}
    source = UrdfSource(
        path=os.path.abspath(tree.source),
        robot=tree.name,
        root=tree.root,
        sha256=hashlib.sha256(tree.text.encode("utf-8")).hexdigest(),
        joints={names.joints[j.name]: j.name for j in on_paths.values() if j.moving},
        frames={names.links[n]: n for n in links},
        axis_rotations=rotations,
        kinematics={j.name: j.kinematics() for j in on_paths.values()},
    )
    try:
        structure = RobotStructure(tree.name, joints, frames)
        nominal = CPCModel(
            structure, IDENTITY, params, frame_params, UrdfModelMetadata(urdf=source)
        )
    except Cpc2UrdfError as e:  # names are legal by construction; limits were checked above
        raise InputFileError(tree.source, str(e)) from e
    return UrdfRobot(
        structure=structure,
        nominal=nominal,
        source=tree.source,
        tree=tree,
        names=names,
        measured=tuple(links) if measured is not None else None,
    )


def load_urdf_robot(
    path: str | os.PathLike[str], measured: Iterable[str] | None = None
) -> UrdfRobot:
    """The robot of the URDF file ``path`` (see :func:`urdf_robot`).

    Raises:
        InputFileError: The file does not parse or is not a URDF (file, element, line), or a
            problem :func:`urdf_robot` names.
    """
    return urdf_robot(read_urdf_tree(path), measured)


def attach_urdf_source(model: CPCModel, robot: RobotSpec | None) -> CPCModel:
    """``model`` remembering the URDF of ``robot`` when ``robot`` was read from one (call it on a
    model identified from measurements of a URDF robot, so that it can be written back)."""
    if isinstance(robot, UrdfRobot) and robot.nominal is not None:
        source = urdf_source(robot.nominal)
        if source is not None:
            return with_urdf_source(model, source)
    return model


__all__ = [
    "URDF_SECTION",
    "NameMap",
    "UrdfModelMetadata",
    "UrdfRobot",
    "UrdfSource",
    "attach_urdf_source",
    "load_urdf_robot",
    "urdf_robot",
    "urdf_source",
    "with_urdf_source",
]
