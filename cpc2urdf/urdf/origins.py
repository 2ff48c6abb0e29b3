"""Where a calibrated model puts each joint of the URDF it was built from (the write-back's geometry).

A model built from a URDF (:mod:`cpc2urdf.urdf.robot`) is written back by changing only the
``<origin>`` of the *calibrated joints*: every moving joint of the model, and the fixed joint
carrying each of the model's frames (a measured link, or a camera link placed by hand-eye
calibration). Every other joint keeps its origin, including the fixed joints whose transforms the
model's constants fold in; the new origin of a calibrated joint is derived through them.

With ``L_K`` the model's link frame of joint K (eq. (6)), ``E_J`` joint J's CPC constants
(eq. (3)), ``C_F`` frame F's, ``R_J`` the rotation taking z onto J's URDF axis (recorded in the
model's ``urdf`` section) and ``T_K_P`` the pose of J's parent link P in ``L_K`` (through
unchanged fixed joints), the new origins are

- moving joint J on K: ``T_P_J = T_K_P^-1 E_J R_J^T``; its child link then sits at
  ``L_J R_J^T`` and its ``<axis>`` is unchanged (the axis tilt is in the origin's rotation);
- fixed joint carrying frame F on K: ``T_P_F = T_K_P^-1 C_F``.

So forward kinematics of the written file puts every link on the paths from the root to the
model's frames where the model puts it (:func:`urdf_link_poses`), and a model equal to its nominal
gives back the file's own origins.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.errors import InputFileError, SpecError
from cpc2urdf.model import BASE, CPCModel
from cpc2urdf.transforms import Array, homogeneous, inverse, rotation_error
from cpc2urdf.urdf.robot import UrdfSource, urdf_source
from cpc2urdf.urdf.tree import UrdfJoint, UrdfTree, read_urdf_tree

# A calibrated origin within this of the file's own [m] / [rad] is the file's own (rounding of the
# CPC round trip, ~1e-16): its text is kept, so a nominal model writes back the file unchanged.
SAME_ORIGIN_TOL = 1e-14
# A frame on a moving joint's child link must sit exactly where the URDF puts that link [m]/[-].
ON_AXIS_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class OriginChange:
    """The new origin of one calibrated joint.

    Attributes:
        joint: The URDF joint.
        role: ``"joint"`` (a moving joint), ``"measured link"`` or ``"camera"`` (the fixed joint
            carrying a model frame of that kind).
        owner: The model joint or frame the origin comes from.
        nominal: ``T_parent_joint`` in the file, shape (4, 4).
        calibrated: ``T_parent_joint`` the model gives, shape (4, 4).
        axis: The joint's unit axis in its own frame (moving joints), else None, shape (3,).
    """

    joint: UrdfJoint
    role: str
    owner: str
    nominal: Array
    calibrated: Array
    axis: Array | None = None

    @property
    def delta_xyz(self) -> Array:
        """Change of the origin's position, in the parent link's frame [m], shape (3,)."""
        return self.calibrated[:3, 3] - self.nominal[:3, 3]

    @property
    def translation(self) -> float:
        """How far the joint frame moved [m]."""
        return float(np.linalg.norm(self.delta_xyz))

    @property
    def rotation(self) -> float:
        """How far the joint frame turned [rad]."""
        return float(rotation_error(self.nominal[:3, :3], self.calibrated[:3, :3]))

    @property
    def axis_change(self) -> float | None:
        """Angle between the old and new axis directions in the parent link's frame [rad]."""
        if self.axis is None:
            return None
        a, b = self.nominal[:3, :3] @ self.axis, self.calibrated[:3, :3] @ self.axis
        return float(np.arctan2(np.linalg.norm(np.cross(a, b)), float(a @ b)))

    @property
    def changed(self) -> bool:
        """False when the model gives the file's own origin (to :data:`SAME_ORIGIN_TOL`)."""
        return self.translation > SAME_ORIGIN_TOL or self.rotation > SAME_ORIGIN_TOL


@dataclass(frozen=True, eq=False)
class WritebackPlan:
    """Everything the write-back changes, and where the model puts the links it covers.

    Attributes:
        tree: The source URDF.
        source: The model's record of it.
        changes: One :class:`OriginChange` per calibrated joint, root first.
        placements: URDF link -> (model joint whose link frame carries it, or ``"base"``; its
            pose in that frame, shape (4, 4)), for every link on the paths to the model's frames.
    """

    tree: UrdfTree
    source: UrdfSource
    changes: tuple[OriginChange, ...]
    placements: Mapping[str, tuple[str, Array]]


def _check_unchanged(tree: UrdfTree, source: UrdfSource) -> None:
    """Refuse a file whose joints the model's constants were derived from have changed."""
    for name, then in source.kinematics.items():
        j = tree.joints.get(name)
        if j is None:
            raise InputFileError(
                tree.source,
                f"joint {name!r}, which the model was built from, is not in the file; "
                "write back into the URDF the model was identified from",
            )
        now = j.kinematics()
        for key, value in then.items():
            if now.get(key) != value:
                raise InputFileError(
                    tree.source,
                    f"joint {name!r} (line {j.line}): {key} is {now.get(key)}, but the model was built from "
                    f"{value}; write back into the URDF the model was identified from, or identify again",
                )


def writeback_plan(model: CPCModel, urdf: str | os.PathLike[str] | None = None) -> WritebackPlan:
    """The calibrated joints' new origins (module docstring).

    Args:
        model: A model built from a URDF (it carries a :class:`~cpc2urdf.urdf.robot.UrdfSource`).
        urdf: The URDF to write into (default: the file the model was built from).

    Raises:
        SpecError: The model was not built from a URDF.
        InputFileError: Naming the URDF and the element: it does not parse, a joint the model was
            built from changed, a model frame that is not a link of it, a moving joint on a
            frame's path that the model does not have, a frame off its link's joint axis.
    """
    source = urdf_source(model)
    if source is None:
        raise SpecError(
            f"model {model.structure.name!r} was not built from a URDF (it has no 'urdf' section), "
            "so there is no URDF to write back into"
        )
    tree = read_urdf_tree(urdf if urdf is not None else source.path)
    _check_unchanged(tree, source)
    return plan_for_tree(model, tree, source)


def plan_for_tree(model: CPCModel, tree: UrdfTree, source: UrdfSource) -> WritebackPlan:
    """:func:`writeback_plan` on a tree already read and checked (for repeated evaluation)."""
    s = model.structure
    cpc_of_joint = {u: c for c, u in source.joints.items()}
    unknown = [n for n in s.joint_names if n not in source.joints]
    if unknown:
        raise InputFileError(
            tree.source, f"the model's joint {unknown[0]!r} is not a joint of this URDF"
        )
    frame_of_link: dict[str, str] = {}
    for f in s.frame_names:
        link = source.urdf_link(f)
        if not tree.has_link(link) or link == tree.root:
            what = "its root link" if tree.has_link(link) else "not a link of it"
            raise InputFileError(
                tree.source,
                f"the model's frame {f!r} is {what}; name a frame after the URDF link "
                "it belongs to (a camera link, a marker link on a fixed joint)",
            )
        frame_of_link[link] = f
    on_paths: dict[str, UrdfJoint] = {}
    needed_by: dict[str, str] = {}  # joint -> a frame link whose path has it
    for link in frame_of_link:
        for j in tree.path(link):
            on_paths.setdefault(j.name, j)
            needed_by.setdefault(j.name, link)
    owner: dict[str, tuple[str, Array]] = {tree.root: (BASE, np.eye(4))}
    changes: list[OriginChange] = []
    for j in on_paths.values():
        K, T_K_P = owner[j.parent]
        frame = frame_of_link.get(j.child)
        if j.moving:
            cpc = cpc_of_joint.get(j.name)
            if cpc is None or s.joint(cpc).parent != K:
                what = (
                    "is not a joint of the model"
                    if cpc is None
                    else f"is not on {K!r} in the model"
                )
                raise InputFileError(
                    tree.source,
                    f"joint {j.name!r} ({j.type}, line {j.line}) on the path to "
                    f"link {needed_by[j.name]!r} {what}",
                )
            R = homogeneous(source.axis_rotation(cpc), np.zeros(3))
            T_P_J = inverse(T_K_P) @ model.joints[cpc].matrix() @ R.T
            changes.append(OriginChange(j, "joint", cpc, j.origin, T_P_J, j.unit_axis))
            owner[j.child] = (cpc, R.T)
            if frame is not None and (
                s.frame(frame).parent != cpc
                or not np.allclose(model.frames[frame].matrix(), R.T, rtol=0.0, atol=ON_AXIS_TOL)
            ):
                raise InputFileError(
                    tree.source,
                    f"the model's frame {frame!r} is not where joint {j.name!r} "
                    f"(line {j.line}) puts link {j.child!r}; a URDF link moved by a joint sits on "
                    "its axis (measure a marker link on a fixed joint instead)",
                )
        elif frame is not None:
            fr = s.frame(frame)
            if fr.parent != K:
                raise InputFileError(
                    tree.source,
                    f"the model's frame {frame!r} hangs on {fr.parent!r}, but link "
                    f"{j.child!r} on {K!r} in the URDF",
                )
            C = model.frames[frame].matrix()
            role = "camera" if fr.kind == "camera" else "measured link"
            changes.append(OriginChange(j, role, frame, j.origin, inverse(T_K_P) @ C))
            owner[j.child] = (K, C)
        else:
            owner[j.child] = (K, T_K_P @ j.origin)
    missed = [n for n in s.joint_names if n not in {c.owner for c in changes}]
    if missed:
        raise InputFileError(
            tree.source, f"the model's joint {missed[0]!r} leads to none of its frames"
        )
    return WritebackPlan(tree, source, tuple(changes), owner)


def urdf_link_poses(model: CPCModel, plan: WritebackPlan, q: ArrayLike) -> dict[str, Array]:
    """Where the model puts each URDF link of the plan, in the URDF's root frame.

    Args:
        model: The model (the one the plan was made for).
        plan: Its write-back plan.
        q: Readings [rad]/[m] in ``model.structure.joint_names`` order, shape (N, n) or (n,).

    Returns:
        URDF link -> ``T_root_link``, shape (N, 4, 4) (or (4, 4) for one configuration): what
        forward kinematics of the written URDF gives, to rounding.
    """
    qq = np.asarray(q, dtype=float)
    _, link = model.link_poses(qq)
    T_base_world = inverse(model.T_world_base())
    out: dict[str, Array] = {}
    for name, (K, T_K_link) in plan.placements.items():
        if K == BASE:
            T = np.broadcast_to(np.eye(4), (link.shape[0], 4, 4)) @ T_K_link
        else:
            T = T_base_world @ link[:, model.structure.joint_index(K)] @ T_K_link
        out[name] = T[0] if qq.ndim == 1 else T
    return out


__all__ = [
    "ON_AXIS_TOL",
    "SAME_ORIGIN_TOL",
    "OriginChange",
    "WritebackPlan",
    "plan_for_tree",
    "urdf_link_poses",
    "writeback_plan",
]
