"""The CPC kinematic model of a tree of revolute and prismatic joints (Shih et al. sec. 2).

Frames (paper's convention, generalised from a chain to a tree):

- ``world``: the measuring system (the stereo rig of stage 1).
- ``base``: the paper's frame 0, placed by ``T_world_base`` (eq. (14), all six DoF).
- The *axis frame* of joint j has its z axis on joint j's axis (the paper's frame j-1 for joint j).
  It sits on the parent link: ``T_parentlink_axis = R(b) Rot(z, beta) Trans(l)`` (eq. (3)), with
  ``R(b)`` of eq. (4). For a root joint the parent link is ``base``.
- The *link frame* of joint j is its axis frame moved by the joint (eq. (6)):
  ``Rot(z, q_j)`` for a revolute joint, ``Trans(0, 0, q_j)`` for a prismatic one. Child joints'
  axis frames and named fixed frames (plates, camera optical frames) hang off link frames.

So the paper's link transform ``T_{i-1,i} = Q_i(q_i) R_i Rot(z, beta_i) Trans(l_i)`` (eq. (5)) is,
here, joint i's motion followed by the constant transform (:class:`CPCParams`) that places its
child's axis frame. In a tree, each child edge carries its own constants, so branches that share
a trunk (the head's two vergence joints on the tilt link) share every joint before the branch
point: one physical tilt axis, not the paper's two (eq. (11)), see docs/identification.md.

Joint variables are transducer readings with no offsets: ``q = 0`` is the zero reading.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.errors import ConfigurationError, SpecError, UnknownNameError
from cpc2urdf.model_metadata import ModelMetadata
from cpc2urdf.transforms import Array, cpc_rotation, rotation_z

# Share of a joint's limits a calibration uses when the spec gives no calibration_range.
DEFAULT_RANGE_SHARE = 0.5  # [-]

JointType = Literal["revolute", "prismatic"]
JOINT_TYPES: tuple[str, ...] = ("revolute", "prismatic")
BASE = "base"
WORLD = "world"
RESERVED_NAMES = frozenset({BASE, WORLD})

# Table 1 of Shih et al.: which constants of eq. (3) a link needs when no nominal model fixes the
# redundant ones. Keys: (type of the joint moving the link, type of the next joint), where "E" is
# an end-effector frame and "W" the world->base transform. Values: the free parameter names.
TABLE_1_FREE_PARAMETERS: dict[tuple[str, str], tuple[str, ...]] = {
    ("W", "B"): ("b_x", "b_y", "beta", "l_x", "l_y", "l_z"),
    ("prismatic", "prismatic"): ("b_x", "b_y"),
    ("prismatic", "revolute"): ("b_x", "b_y"),
    ("revolute", "prismatic"): ("b_x", "b_y", "l_x", "l_y"),
    ("revolute", "revolute"): ("b_x", "b_y", "l_x", "l_y"),
    ("revolute", "E"): ("b_x", "b_y", "l_x", "l_y", "l_z"),  # beta: "N/R" (eq. (9))
    ("prismatic", "E"): ("b_x", "b_y", "l_x", "l_y", "l_z"),
}


@dataclass(frozen=True)
class CPCParams:
    """The constant part of a CPC link transform, eq. (3): ``R(b) Rot(z, beta) Trans(l)``.

    Attributes:
        b: Unit vector of the new z axis in the previous frame, shape (3,). The CPC convention
            prefers ``b_z >= 0``; any ``b`` except exactly ``-z`` is exact here (eq. (4)).
        beta: Rotation about the new z axis [rad].
        l: Translation in the rotated frame [m], shape (3,).
    """

    b: tuple[float, float, float] = (0.0, 0.0, 1.0)
    beta: float = 0.0
    l: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        values = (*self.b, self.beta, *self.l)
        if not all(math.isfinite(v) for v in values):
            raise SpecError(
                f"CPC parameters must be finite, got b={self.b}, beta={self.beta}, l={self.l}"
            )
        n = math.sqrt(sum(v * v for v in self.b))
        if abs(n - 1.0) > 1e-6:
            raise SpecError(f"CPC axis b must be a unit vector, |b| = {n:.9g} (b = {list(self.b)})")
        # Store unit length so that eq. (4) is a rotation to rounding; a vector already unit to
        # rounding is kept bit for bit, so that files round-trip exactly.
        scale = 1.0 if abs(n - 1.0) <= 4e-16 else n
        object.__setattr__(self, "b", tuple(float(v) / scale for v in self.b))
        object.__setattr__(self, "beta", float(self.beta))
        object.__setattr__(self, "l", tuple(float(v) for v in self.l))

    def rotation(self) -> Array:
        """``R(b) Rot(z, beta)``, shape (3, 3)."""
        return cpc_rotation(self.b) @ rotation_z(self.beta)

    def matrix(self) -> Array:
        """The (4, 4) transform of eq. (3)."""
        T = np.eye(4)
        R = self.rotation()
        T[:3, :3] = R
        T[:3, 3] = R @ np.asarray(self.l)
        return T

    @classmethod
    def from_matrix(cls, T: ArrayLike) -> CPCParams:
        """The CPC parameters of a rigid transform (exact; ``b`` is its third rotation column).

        ``R(b)^T R`` maps z to z, so it is ``Rot(z, beta)``; ``l = R^T p``.
        """
        T = np.asarray(T, dtype=float)
        R = T[:3, :3]
        b = R[:, 2] / np.linalg.norm(R[:, 2])
        Rz = cpc_rotation(b).T @ R
        beta = math.atan2(Rz[1, 0], Rz[0, 0])
        l = R.T @ T[:3, 3]
        return cls(tuple(b.tolist()), beta, tuple(l.tolist()))  # type: ignore[arg-type]

    def to_vector(self) -> Array:
        """``[b_x, b_y, b_z, beta, l_x, l_y, l_z]``."""
        return np.array([*self.b, self.beta, *self.l])


IDENTITY = CPCParams()


@dataclass(frozen=True)
class Joint:
    """One joint of the tree.

    Attributes:
        name: Joint name (also names the URDF joint; its link is ``<name>_link``).
        type: ``"revolute"`` or ``"prismatic"``.
        parent: Name of the parent joint, or ``"base"`` for a root joint.
        lower: Lower limit of the reading [rad] or [m].
        upper: Upper limit of the reading [rad] or [m].
        velocity: Velocity limit [rad/s] or [m/s].
        effort: Effort limit [N m] or [N] (URDF needs one; not used by kinematics).
        calibration_range: Sub-range of the limits that measurements may use, or None.
    """

    name: str
    type: str
    parent: str = BASE
    lower: float = -math.pi
    upper: float = math.pi
    velocity: float = 1.0
    effort: float = 10.0
    calibration_range: tuple[float, float] | None = None


@dataclass(frozen=True)
class Frame:
    """A named frame fixed to a link: a calibration plate, a camera optical frame, a tool.

    Attributes:
        name: Frame name (also the URDF link name).
        parent: The joint whose link carries it, or ``"base"``.
        kind: ``"plate"``, ``"camera"`` or ``"frame"``; decides the URDF visual.
        layout: For plates, the circle centres in the plate frame [m], shape (K, 3); else None.
    """

    name: str
    parent: str = BASE
    kind: str = "frame"
    layout: tuple[tuple[float, float, float], ...] | None = None


FRAME_KINDS = ("plate", "camera", "frame")


class RobotStructure:
    """The topology of a robot: joints (types, parents, limits) and named frames.

    Joints are kept in a topological order (every parent before its children), which is also
    the order of the configuration vector ``q``.

    Raises:
        SpecError: Duplicate or reserved names, an unknown parent, a cycle, a joint type other
            than revolute/prismatic, lower > upper, non-finite limits.
    """

    def __init__(self, name: str, joints: Sequence[Joint], frames: Sequence[Frame]) -> None:
        self.name = name
        problems: list[str] = []
        names = [j.name for j in joints] + [f.name for f in frames]
        seen: set[str] = set()
        for n in names:
            if not isinstance(n, str) or not n:
                problems.append(f"names must be non-empty strings, got {n!r}")
            elif n in RESERVED_NAMES:
                problems.append(f"{n!r} is reserved (the tree's root frames), choose another name")
            elif n in seen:
                problems.append(f"name {n!r} is used twice")
            elif n.endswith("_link") or n.endswith("_joint"):
                problems.append(f"name {n!r} must not end in _link/_joint (URDF export adds those)")
            seen.add(n)
        joint_names = {j.name for j in joints}
        for j in joints:
            if j.type not in JOINT_TYPES:
                problems.append(
                    f"joint {j.name!r}: type must be revolute or prismatic, got {j.type!r}"
                )
            if j.parent != BASE and j.parent not in joint_names:
                problems.append(
                    f"joint {j.name!r}: parent {j.parent!r} is neither 'base' nor a joint"
                )
            lims = (j.lower, j.upper, j.velocity, j.effort)
            if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in lims):
                problems.append(f"joint {j.name!r}: limits must be finite numbers")
            elif j.lower > j.upper:
                problems.append(f"joint {j.name!r}: lower limit {j.lower} > upper limit {j.upper}")
            elif j.velocity <= 0 or j.effort <= 0:
                problems.append(f"joint {j.name!r}: velocity and effort limits must be positive")
            if j.calibration_range is not None:
                lo, hi = j.calibration_range
                if not (j.lower - 1e-12 <= lo <= hi <= j.upper + 1e-12):
                    problems.append(
                        f"joint {j.name!r}: calibration_range [{lo}, {hi}] must lie within the "
                        f"limits [{j.lower}, {j.upper}]"
                    )
        for f in frames:
            if f.parent != BASE and f.parent not in joint_names:
                problems.append(
                    f"frame {f.name!r}: parent {f.parent!r} is neither 'base' nor a joint"
                )
            if f.kind not in FRAME_KINDS:
                problems.append(
                    f"frame {f.name!r}: kind must be one of {FRAME_KINDS}, got {f.kind!r}"
                )
        if not joints:
            problems.append("a robot needs at least one joint")
        if problems:
            raise SpecError(f"robot {name!r}: " + "; ".join(problems))
        self.joints: tuple[Joint, ...] = _topological_order(name, joints)
        self.frames: tuple[Frame, ...] = tuple(frames)
        self.joint_names: tuple[str, ...] = tuple(j.name for j in self.joints)
        self.frame_names: tuple[str, ...] = tuple(f.name for f in self.frames)
        self._joint_index = {n: i for i, n in enumerate(self.joint_names)}
        self._joints = {j.name: j for j in self.joints}
        self._frames = {f.name: f for f in self.frames}

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def joint(self, name: str) -> Joint:
        """The joint called ``name`` (:class:`UnknownNameError` if there is none)."""
        try:
            return self._joints[name]
        except KeyError:
            raise UnknownNameError("joint", name, self.joint_names) from None

    def frame(self, name: str) -> Frame:
        """The frame called ``name`` (:class:`UnknownNameError` if there is none)."""
        try:
            return self._frames[name]
        except KeyError:
            raise UnknownNameError("frame", name, self.frame_names) from None

    def joint_index(self, name: str) -> int:
        """Position of joint ``name`` in the configuration vector."""
        if name not in self._joint_index:
            raise UnknownNameError("joint", name, self.joint_names)
        return self._joint_index[name]

    def children(self, parent: str) -> list[Joint]:
        """Joints whose parent is ``parent`` (a joint name or ``"base"``)."""
        return [j for j in self.joints if j.parent == parent]

    def path_to(self, name: str) -> list[str]:
        """Joint names from the root to the link carrying frame or joint ``name`` (inclusive)."""
        if name in self._frames:
            parent = self._frames[name].parent
        elif name in self._joints:
            parent = name
        elif name == BASE:
            return []
        else:
            raise UnknownNameError("frame", name, self.frame_names)
        path: list[str] = []
        while parent != BASE:
            path.append(parent)
            parent = self._joints[parent].parent
        return path[::-1]

    @property
    def lower(self) -> Array:
        return np.array([j.lower for j in self.joints])

    @property
    def upper(self) -> Array:
        return np.array([j.upper for j in self.joints])

    def q_from_dict(self, values: Mapping[str, float]) -> Array:
        """Configuration vector from ``{joint name: reading}``; every joint must be given."""
        unknown = set(values) - set(self.joint_names)
        if unknown:
            raise UnknownNameError("joint", sorted(unknown)[0], self.joint_names)
        missing = [n for n in self.joint_names if n not in values]
        if missing:
            raise ConfigurationError(f"configuration lacks joints {missing}")
        return np.array([float(values[n]) for n in self.joint_names])

    def q_to_dict(self, q: ArrayLike) -> dict[str, float]:
        """``{joint name: reading}`` from a configuration vector of shape (n,)."""
        q = np.asarray(q, dtype=float)
        return {n: float(v) for n, v in zip(self.joint_names, q, strict=True)}

    def calibration_ranges(
        self, overrides: Mapping[str, tuple[float, float]] | None = None
    ) -> Array:
        """The part of each joint's travel a calibration measures: per joint ``[lo, hi]``
        [m]/[rad], shape (n, 2). The one rule every simulator, planner, study and test uses:

        1. a range given by the caller (``overrides``, e.g. ``cpc2urdf simulate --range``), else
        2. the joint's ``calibration_range`` from the robot spec, else
        3. the middle :data:`DEFAULT_RANGE_SHARE` (one half) of its limits, centred on their
           middle (where a head's plates and cameras face forward; the extremes of the limits
           often turn them edge-on or out of view).

        Raises:
            UnknownNameError: ``overrides`` names a joint the robot does not have.
            ConfigurationError: An override does not lie within its joint's limits.
        """
        out = np.empty((self.n_joints, 2))
        overrides = dict(overrides or {})
        for name in overrides:
            self.joint(name)
        for i, j in enumerate(self.joints):
            if j.name in overrides:
                lo, hi = (float(v) for v in overrides[j.name])
                if not (j.lower - 1e-12 <= lo <= hi <= j.upper + 1e-12):
                    raise ConfigurationError(
                        f"joint {j.name!r}: calibration range [{lo:.6g}, {hi:.6g}] must lie within the "
                        f"limits [{j.lower:.6g}, {j.upper:.6g}]"
                    )
                out[i] = lo, hi
            elif j.calibration_range is not None:
                out[i] = j.calibration_range
            else:
                mid, half = (j.lower + j.upper) / 2, DEFAULT_RANGE_SHARE * (j.upper - j.lower) / 2
                out[i] = mid - half, mid + half
        return out

    def check_q(self, q: ArrayLike, *, limits: bool = False) -> Array:
        """Validate a configuration of shape (n,) or (N, n): finite, and within limits if asked.

        Raises:
            ConfigurationError: wrong shape, NaN/inf, or (``limits=True``) a reading outside the
                limits, naming the joint.
        """
        q = np.asarray(q, dtype=float)
        if q.ndim not in (1, 2) or q.shape[-1] != self.n_joints:
            raise ConfigurationError(
                f"configuration must have shape ({self.n_joints},) or (N, {self.n_joints}) "
                f"for joints {list(self.joint_names)}, got shape {q.shape}"
            )
        if not np.all(np.isfinite(q)):
            raise ConfigurationError("configuration contains NaN or inf")
        if limits:
            qq = np.atleast_2d(q)
            for i, j in enumerate(self.joints):
                bad = (qq[:, i] < j.lower - 1e-12) | (qq[:, i] > j.upper + 1e-12)
                if np.any(bad):
                    v = qq[np.argmax(bad), i]
                    raise ConfigurationError(
                        f"joint {j.name!r}: reading {v:.9g} outside its limits [{j.lower:.9g}, {j.upper:.9g}]"
                    )
        return q


def _topological_order(name: str, joints: Sequence[Joint]) -> tuple[Joint, ...]:
    by_parent: dict[str, list[Joint]] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j)
    order: list[Joint] = []
    stack = list(reversed(by_parent.get(BASE, [])))
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(by_parent.get(j.name, [])))
    if len(order) != len(joints):
        lost = sorted({j.name for j in joints} - {j.name for j in order})
        raise SpecError(f"robot {name!r}: joints {lost} do not connect to 'base' (a cycle?)")
    return tuple(order)


@dataclass
class CPCModel:
    """Geometry of a robot in CPC form: ``T_world_base`` plus one :class:`CPCParams` per joint
    (placing its axis frame on the parent link) and per named frame (placing it on its link).

    Attributes:
        structure: Joints, limits and frames.
        world_to_base: ``T_world_base`` as CPC parameters (eq. (14)).
        joints: Constants placing each joint's axis frame, by joint name.
        frames: Constants placing each named frame on its link, by frame name.
        metadata: What the model carries besides its geometry (provenance, fit residuals,
            parameter covariance, hand-eye results, notes): :class:`~cpc2urdf.model_metadata.ModelMetadata`.
    """

    structure: RobotStructure
    world_to_base: CPCParams
    joints: dict[str, CPCParams]
    frames: dict[str, CPCParams]
    metadata: ModelMetadata = field(default_factory=ModelMetadata)

    def __post_init__(self) -> None:
        s = self.structure
        missing = [n for n in s.joint_names if n not in self.joints]
        missing += [n for n in s.frame_names if n not in self.frames]
        extra = [n for n in self.joints if n not in s.joint_names]
        extra += [n for n in self.frames if n not in s.frame_names]
        if missing:
            raise SpecError(f"robot {s.name!r}: no geometry for {missing}")
        if extra:
            raise SpecError(f"robot {s.name!r}: geometry given for unknown names {extra}")
        self._compile()

    def _compile(self) -> None:
        s = self.structure
        self._T_world_base = self.world_to_base.matrix()
        self._joint_E = np.stack([self.joints[n].matrix() for n in s.joint_names])
        self._parent_index = np.array(
            [-1 if j.parent == BASE else s.joint_index(j.parent) for j in s.joints], dtype=int
        )
        self._revolute = np.array([j.type == "revolute" for j in s.joints])
        self._frame_E = {n: self.frames[n].matrix() for n in s.frame_names}
        self._frame_parent = {
            f.name: (-1 if f.parent == BASE else s.joint_index(f.parent)) for f in s.frames
        }

    def with_params(
        self,
        *,
        world_to_base: CPCParams | None = None,
        joints: Mapping[str, CPCParams] | None = None,
        frames: Mapping[str, CPCParams] | None = None,
        metadata: ModelMetadata | None = None,
    ) -> CPCModel:
        """A copy with some parameters replaced."""
        return CPCModel(
            self.structure,
            world_to_base or self.world_to_base,
            {**self.joints, **(joints or {})},
            {**self.frames, **(frames or {})},
            metadata if metadata is not None else self.metadata,
        )

    # ---- forward kinematics ------------------------------------------------------------------

    def _as_q(self, q: ArrayLike | Mapping[str, float]) -> tuple[Array, bool]:
        if isinstance(q, Mapping):
            q = self.structure.q_from_dict(q)
        qa = self.structure.check_q(q)
        return np.atleast_2d(qa), qa.ndim == 1

    def link_poses(self, q: ArrayLike | Mapping[str, float]) -> tuple[Array, Array]:
        """World poses of every joint's axis frame and link frame.

        Args:
            q: Readings [rad]/[m], shape (n,) or (N, n) in ``structure.joint_names`` order, or a
                ``{joint: reading}`` mapping.

        Returns:
            ``(T_world_axis, T_world_link)``, each of shape (N, n, 4, 4) (N = 1 for a single q).
        """
        qq, _ = self._as_q(q)
        N, n = qq.shape
        axis = np.empty((N, n, 4, 4))
        link = np.empty((N, n, 4, 4))
        for i in range(n):
            p = self._parent_index[i]
            parent = self._T_world_base if p < 0 else link[:, p]
            A = parent @ self._joint_E[i]  # axis frame of joint i, eq. (3)
            axis[:, i] = A
            L = link[:, i]
            qi = qq[:, i]
            if self._revolute[i]:  # eq. (6): A @ Rot(z, q), written out column by column
                c, s_ = np.cos(qi)[:, None], np.sin(qi)[:, None]
                L[:, :, 0] = c * A[..., :, 0] + s_ * A[..., :, 1]
                L[:, :, 1] = -s_ * A[..., :, 0] + c * A[..., :, 1]
                L[:, :, 2:] = A[..., :, 2:]
            else:  # eq. (6): A @ Trans(0, 0, d)
                L[:] = A
                L[:, :, 3] = A[..., :, 3] + qi[:, None] * A[..., :, 2]
        return axis, link

    def fk(
        self, q: ArrayLike | Mapping[str, float], frames: Iterable[str] | None = None
    ) -> dict[str, Array]:
        """``T_world_<frame>`` for every named frame (or those in ``frames``).

        Vectorised: for q of shape (N, n) every value has shape (N, 4, 4); for shape (n,) or a
        mapping, shape (4, 4). Also answers ``"base"``.
        """
        qq, single = self._as_q(q)
        _, link = self.link_poses(qq)
        names = list(frames) if frames is not None else list(self.structure.frame_names)
        out: dict[str, Array] = {}
        for name in names:
            if name == BASE:
                T = np.broadcast_to(self._T_world_base, (qq.shape[0], 4, 4)).copy()
            else:
                self.structure.frame(name)  # raises UnknownNameError
                p = self._frame_parent[name]
                if p < 0:  # a frame fixed to the base: the same pose at every configuration
                    T = np.broadcast_to(
                        self._T_world_base @ self._frame_E[name], (qq.shape[0], 4, 4)
                    ).copy()
                else:
                    T = link[:, p] @ self._frame_E[name]
            out[name] = T[0] if single else T
        return out

    def fk_frame(self, name: str, q: ArrayLike | Mapping[str, float]) -> Array:
        """``T_world_<name>``: shape (4, 4) for one configuration, (N, 4, 4) for many."""
        return self.fk(q, [name])[name]

    def T_world_base(self) -> Array:
        """The (4, 4) pose of ``base`` in ``world``."""
        return self._T_world_base.copy()

    def joint_axes_world(self, q: ArrayLike | Mapping[str, float]) -> tuple[Array, Array]:
        """Each joint's axis in world: a point on it [m] and its unit direction.

        Returns:
            ``(p_world, axis_world)``, each of shape (N, n, 3).
        """
        axis, _ = self.link_poses(q)
        return axis[..., :3, 3].copy(), axis[..., :3, 2].copy()

    # ---- conveniences --------------------------------------------------------------------------

    def renamed(self, name: str) -> CPCModel:
        s = self.structure
        return CPCModel(
            RobotStructure(name, s.joints, s.frames),
            self.world_to_base,
            dict(self.joints),
            dict(self.frames),
            self.metadata,
        )

    def without_frames(self, kinds: Iterable[str]) -> CPCModel:
        """A copy without the named frames of the given kinds (e.g. drop cameras)."""
        drop = {f.name for f in self.structure.frames if f.kind in set(kinds)}
        s = self.structure
        return CPCModel(
            RobotStructure(s.name, s.joints, [f for f in s.frames if f.name not in drop]),
            self.world_to_base,
            dict(self.joints),
            {n: p for n, p in self.frames.items() if n not in drop},
            self.metadata,
        )

    def with_frame(self, frame: Frame, params: CPCParams) -> CPCModel:
        """A copy with ``frame`` added (or replaced) at ``params`` on its parent link."""
        s = self.structure
        frames = [f for f in s.frames if f.name != frame.name] + [frame]
        return CPCModel(
            RobotStructure(s.name, s.joints, frames),
            self.world_to_base,
            dict(self.joints),
            {**{n: p for n, p in self.frames.items() if n != frame.name}, frame.name: params},
            self.metadata,
        )


def replace_joint(joint: Joint, **changes: Any) -> Joint:
    """A copy of ``joint`` with fields changed (dataclasses.replace, re-exported for callers)."""
    return replace(joint, **changes)


__all__ = [
    "BASE",
    "DEFAULT_RANGE_SHARE",
    "FRAME_KINDS",
    "IDENTITY",
    "JOINT_TYPES",
    "RESERVED_NAMES",
    "TABLE_1_FREE_PARAMETERS",
    "WORLD",
    "CPCModel",
    "CPCParams",
    "Frame",
    "Joint",
    "JointType",
    "RobotStructure",
    "replace_joint",
]
