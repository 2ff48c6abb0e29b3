"""The head as the gaze solver sees it: two camera frames on a :class:`PinocchioRobot`.

The joints on each camera's path decide the class of every joint: those both cameras share
move the head, prismatic ones are the *table* and revolute ones the *neck*; the joints on only
one camera's path are that camera's *eye*. *Version* is the eyes' common turn:
``(eye_L - home_L) + s (eye_R - home_R)`` on the first eye joint of each side, with ``s`` = +1
when those two joints turn about (nearly) the same world direction, -1 otherwise; ``home`` is
the middle of every joint's limits.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError, SpecError, UnknownNameError
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.pinocchio import PinocchioRobot

Index = NDArray[np.intp]  # joint indices into q
DEFAULT_CAMERAS = ("camera_left_optical", "camera_right_optical")


class GazeHead:
    """Camera frames, joint classes, limits and version of a head, on one Pinocchio ``Data``.

    Args:
        robot: The head's URDF through Pinocchio.
        cameras: Names of the left and right camera optical frames (z along the optical axis).

    Raises:
        ConfigurationError: Not exactly two camera frames.
        UnknownNameError: A camera frame the URDF does not have.
        SpecError: A joint without finite limits, or the two cameras share every joint (no
            eye joints).

    Attributes:
        robot: The :class:`PinocchioRobot`.
        pin: The ``pinocchio`` module (the solver's hot path calls it through here).
        model: ``pinocchio.Model``; ``data`` its ``pinocchio.Data``, used by every computation
            on this head (so a head is not thread-safe).
        cameras: The (left, right) camera frame names; ``frame_ids`` their Pinocchio ids.
        joint_names: Joints in the order of the readings ``q``; ``n`` their number.
        joint_kinds: ``{joint: "revolute" | "prismatic"}``.
        lower: Lower joint limits [rad]/[m], shape (n,); ``upper`` the upper ones.
        velocity_limit: URDF joint speed limits [rad/s]/[m/s], shape (n,).
        home: The middle of every joint's limits, shape (n,).
        table: Indices of the table joints; ``neck`` of the neck joints; ``eye_joints`` of each
            eye's joints (left, right); ``eyes_all`` of both eyes' joints.
        e0: Index of the left eye's first joint; ``e1`` of the right eye's.
        version_sign: ``s`` in the version (module docstring).
        version_row: The version as a row over ``q``, shape (n,).
        table_link: Pinocchio joint id of the last table joint (0 without a table);
            ``table_chain`` the indices of the joints up to it.
        baseline: Distance between the camera centres at ``home`` [m].
    """

    def __init__(self, robot: PinocchioRobot, cameras: Sequence[str] = DEFAULT_CAMERAS) -> None:
        self.robot = robot
        self.pin = pin
        model = robot.model
        self.model = model
        self.data = model.createData()
        if len(cameras) != 2:
            raise ConfigurationError(f"need exactly two camera frames (left, right), got {list(cameras)}")
        self.frame_ids: list[int] = [robot.frame_id(name) for name in cameras]
        self.cameras: tuple[str, str] = (cameras[0], cameras[1])

        names = robot.joint_names
        self.joint_names: tuple[str, ...] = names
        self.joint_kinds: dict[str, str] = dict(zip(names, robot.joint_kinds, strict=True))
        self.n = len(names)
        self.lower: Array = robot.lower.copy()
        self.upper: Array = robot.upper.copy()
        self.velocity_limit: Array = robot.velocity_limit.copy()
        if not (np.all(np.isfinite(self.lower)) and np.all(np.isfinite(self.upper))):
            raise SpecError("every joint needs finite <limit lower/upper> for gaze control")
        self.home: Array = 0.5 * (self.lower + self.upper)
        self.lower_list: list[float] = self.lower.tolist()
        self.home_list: list[float] = self.home.tolist()
        self.upper_list: list[float] = self.upper.tolist()

        # Joints on each camera's path: shared ones move the head, the others are the eyes.
        paths: list[set[int]] = []
        for fid in self.frame_ids:
            jid = model.frames[fid].parentJoint
            chain: set[int] = set()
            while jid > 0:
                chain.add(jid - 1)
                jid = model.parents[jid]
            paths.append(chain)
        shared = paths[0] & paths[1]
        kinds = robot.joint_kinds
        self.table: Index = np.array(sorted(i for i in shared if kinds[i] == "prismatic"), dtype=int)
        self.neck: Index = np.array(sorted(i for i in shared if kinds[i] == "revolute"), dtype=int)
        self.eye_joints: list[Index] = [np.array(sorted(p - shared), dtype=int) for p in paths]
        if any(len(e) == 0 for e in self.eye_joints):
            raise SpecError(f"cameras {list(self.cameras)} share all their joints: nothing can verge")
        self.eyes_all: Index = np.concatenate(self.eye_joints)
        self.e0, self.e1 = int(self.eye_joints[0][0]), int(self.eye_joints[1][0])
        self.version_sign = self._eye_version_sign()
        # version = (eye_L - home_L) + s (eye_R - home_R), first eye joint of each side
        self.version_row: Array = np.zeros(self.n)
        self.version_row[self.e0] = 1.0
        self.version_row[self.e1] = self.version_sign

        self.table_link = int(max(self.table)) + 1 if len(self.table) else 0
        chain_l, jid = [], self.table_link
        while jid > 0:
            chain_l.append(jid - 1)
            jid = model.parents[jid]
        self.table_chain: Index = np.array(sorted(chain_l), dtype=int)
        pin.framesForwardKinematics(model, self.data, self.home)
        o0 = self.data.oMf[self.frame_ids[0]].translation
        o1 = self.data.oMf[self.frame_ids[1]].translation
        self.baseline = float(np.linalg.norm(o0 - o1))

    def _eye_version_sign(self) -> float:
        """+1 if the first eye joints of both eyes turn about (nearly) the same world direction."""
        pin.computeJointJacobians(self.model, self.data, self.home)
        # The world Jacobian's angular column of a revolute joint is its axis direction.
        J = pin.getJointJacobian(self.model, self.data, self.e0 + 1, pin.WORLD)
        a0 = J[3:, self.e0]
        J = pin.getJointJacobian(self.model, self.data, self.e1 + 1, pin.WORLD)
        a1 = J[3:, self.e1]
        return 1.0 if float(a0 @ a1) >= 0.0 else -1.0

    def version(self, q: Array) -> float:
        """Version [rad]: ``(eye_L - home_L) + s (eye_R - home_R)``, first eye joint of each side."""
        e0, e1 = self.e0, self.e1
        return (float(q[e0]) - self.home_list[e0]) + self.version_sign * (float(q[e1]) - self.home_list[e1])

    def cyclopean_ray(self, q: Array) -> tuple[Array, Array]:
        """Cyclopean point (midpoint of the camera centres) and unit direction (sum of the optical
        axes) at readings ``q``, in the frame of the last table link, each (3,)."""
        pin.framesForwardKinematics(self.model, self.data, q)
        T_world_table = self.data.oMi[self.table_link]
        o = [T_world_table.actInv(self.data.oMf[fid].translation) for fid in self.frame_ids]
        z = [T_world_table.rotation.T @ self.data.oMf[fid].rotation[:, 2] for fid in self.frame_ids]
        d = z[0] + z[1]
        return 0.5 * (o[0] + o[1]), d / np.linalg.norm(d)

    def camera_centre_jacobians(self, q: Array) -> list[Array]:
        """World Jacobians of the two camera centres at ``q``, each (3, n) [m/rad]/[-]."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        return [
            self.data.oMf[fid].rotation @ pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL)[:3]
            for fid in self.frame_ids
        ]

    def camera_poses(self, q: ArrayLike) -> tuple[Array, Array]:
        """``T_world_<camera>`` of the left and right camera at readings ``q`` (shape (n,)), each (4, 4)."""
        qa = np.asarray(q, dtype=float)
        if qa.shape != (self.n,) or not np.all(np.isfinite(qa)):
            raise ConfigurationError(f"q must be {self.n} finite readings, got shape {qa.shape}")
        pin.framesForwardKinematics(self.model, self.data, qa)
        left, right = (self.data.oMf[fid].homogeneous.copy() for fid in self.frame_ids)
        return left, right

    def check_q(self, q: ArrayLike | Mapping[str, float] | None) -> Array | None:
        """Readings ``q_current`` as an array of shape (n,) inside the limits, or None for None.

        Args:
            q: Readings [rad]/[m], shape (n,) in :attr:`joint_names` order, or ``{joint: reading}``
                naming every joint.

        Raises:
            UnknownNameError: A joint the head does not have.
            ConfigurationError: Missing joints, the wrong shape, NaN/inf, or a reading outside
                its limits (by more than 1e-9).
        """
        if q is None:
            return None
        return check_readings(self.joint_names, self.lower, self.upper, q)

    @staticmethod
    def check_readings(robot: PinocchioRobot, q: ArrayLike | Mapping[str, float]) -> Array:
        """:meth:`check_q` on any robot (its joints and limits)."""
        return check_readings(robot.joint_names, robot.lower, robot.upper, q)


def check_readings(
    joint_names: Sequence[str], lower: Array, upper: Array, q: ArrayLike | Mapping[str, float]
) -> Array:
    """Readings ``q`` (shape (n,) in ``joint_names`` order, or ``{joint: reading}`` naming every
    joint) as an array inside ``lower``..``upper`` (1e-9 slack, then clipped).

    Raises:
        UnknownNameError: A joint not in ``joint_names``.
        ConfigurationError: Missing joints, the wrong shape, NaN/inf, or a reading outside its
            limits.
    """
    n = len(joint_names)
    if isinstance(q, Mapping):
        unknown = set(q) - set(joint_names)
        if unknown:
            raise UnknownNameError("joint", sorted(unknown)[0], tuple(joint_names))
        missing = [j for j in joint_names if j not in q]
        if missing:
            raise ConfigurationError(f"q_current lacks joints {missing}")
        q = [q[j] for j in joint_names]
    try:
        qa = np.asarray(q, dtype=float)
    except (TypeError, ValueError) as e:
        raise ConfigurationError(f"q_current must be {n} numbers, got {q!r}") from e
    if qa.shape != (n,):
        raise ConfigurationError(f"q_current must have shape ({n},) for joints {list(joint_names)}, got shape {qa.shape}")
    if not np.all(np.isfinite(qa)):
        raise ConfigurationError(f"q_current must be finite, got {qa.tolist()}")
    tol = 1e-9
    bad = np.flatnonzero((qa < lower - tol) | (qa > upper + tol))
    if bad.size:
        i = int(bad[0])
        raise ConfigurationError(
            f"q_current: joint {joint_names[i]!r} reading {qa[i]:.9g} outside its limits [{lower[i]:.9g}, {upper[i]:.9g}]"
        )
    return np.clip(qa, lower, upper)


__all__ = ["DEFAULT_CAMERAS", "GazeHead", "Index", "check_readings"]
