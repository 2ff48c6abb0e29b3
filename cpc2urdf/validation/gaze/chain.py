"""A head's kinematics flattened to arrays for the compiled gaze loop: :class:`HeadChain`.

Built once, in Python, from a :class:`~cpc2urdf.urdf.pinocchio.PinocchioRobot` and
one or two camera (optical, REP-103: z forward) frame names. Only the joints on the root->camera
paths matter. Per such joint: its parent (an index into the chain, -1 for the root), its type
(revolute / prismatic), its axis in its own frame and its fixed placement in the parent joint's
frame, as Pinocchio has them (``oMi[j] = oMi[parent] * jointPlacements[j] * M_j(q_j)``). Per
camera: the joint it hangs on and its placement there (``oMf = oMi[parent] * placement``).

The solver's unknowns are ``u`` (shape (m,)); the chain's readings are ``q = A u + b``:

- a joint that may move and is not coupled: its own ``u`` component;
- a joint that may not move: a zero row, held at its reading (``b``, the middle of its limits
  unless set per solve);
- a URDF ``<mimic joint=i multiplier=k offset=c>`` joint: ``q_j = k q_i + c``;
- a stated linear coupling (:class:`Coupling`, e.g. iCub's eyes: ``l = version + vergence / 2``,
  ``r = version - vergence / 2``): the joints it names, over its own variables with their bounds.

Box bounds are on ``u``. A coupling's bounds must map inside the joints' limits (checked here:
the extreme of each row over the box); a mimic joint's driver is bounded so that both stay inside.

Cameras: two cameras with no joint between them (a rigid stereo pair) are solved as one virtual
camera, the *cyclopean* one (midpoint of the centres, z along the sum of the optical axes, x
along the baseline), or as a chosen master eye (``rigid="left"`` / ``"right"``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError, SpecError, UnknownNameError
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.pinocchio import PinocchioRobot

REVOLUTE, PRISMATIC = 0, 1  # joint type codes of the compiled chain
KIND_ONE_CAMERA = "look-at"  # one camera: its optical axis through the target
KIND_BINOCULAR = "binocular"  # two cameras on independent eyes: both axes through the target
KIND_RIGID_STEREO = "rigid-stereo"  # two cameras, no joint between them: one (virtual) camera
RIGID_MODES = ("cyclopean", "left", "right")
PRISMATIC_WEIGHT = 100.0  # [-]: cost of 1 m of a prismatic joint vs 1 rad of a shared revolute one
EYE_WEIGHT = 4.0  # [-]: cost of 1 rad of an eye joint (one camera's only) vs a shared revolute one


@dataclass(frozen=True)
class Coupling:
    """A stated linear coupling of some joints: ``q[joints] = A @ v + b`` over variables ``v``.

    Attributes:
        joints: The coupled joints (rows of ``A``).
        variables: Names of the coupling's variables (columns of ``A``), e.g. ``("version",
            "vergence")``.
        A: Shape (len(joints), len(variables)).
        b: Shape (len(joints),) [rad]/[m].
        lower: Lower bounds of the variables, shape (len(variables),); ``upper`` the upper ones.
    """

    joints: tuple[str, ...]
    variables: tuple[str, ...]
    A: Array
    b: Array
    lower: Array
    upper: Array

    @classmethod
    def version_vergence(
        cls, left: str, right: str, version: tuple[float, float], vergence: tuple[float, float]
    ) -> Coupling:
        """iCub-style eyes: ``left = version + vergence / 2``, ``right = version - vergence / 2``
        (both pan joints turn about parallel axes; bounds [rad])."""
        return cls(
            (left, right),
            ("version", "vergence"),
            np.array([[1.0, 0.5], [1.0, -0.5]]),
            np.zeros(2),
            np.array([version[0], vergence[0]], dtype=float),
            np.array([version[1], vergence[1]], dtype=float),
        )


@dataclass
class HeadChain:
    """The arrays of the compiled loop (see the module docstring) and what they stand for.

    Attributes:
        robot: The robot.
        cameras: The camera frame names (one or two).
        kind: :data:`KIND_ONE_CAMERA`, :data:`KIND_BINOCULAR` or :data:`KIND_RIGID_STEREO`.
        joint_index: Per chain joint, its index into the robot's readings, shape (K,).
        parent, jtype, axis, R, t: Per chain joint: parent chain index (-1: root), type code,
            axis (3,), placement rotation (3, 3) and translation (3,) in the parent joint frame.
        cam_parent, cam_R, cam_t: Per camera: chain index of its joint (-1: root), placement.
        anc: ``anc[c, k]``: chain joint ``k`` moves camera ``c``, shape (C, K).
        solve_cameras: The cameras the residual uses: the real ones, or for a rigid pair the
            virtual one (index 2 in ``cam_*``), shape (S,).
        A, b: ``q_chain = A u + b``, shapes (K, m), (K,).
        variables: Names of the unknowns ``u``.
        lower, upper: Bounds of ``u``, shape (m,).
        weight: Secondary-task weight per unknown (cost of moving it), shape (m,).
        eye: Per unknown, whether it moves only one camera (an eye), shape (m,).
        robot_A, robot_b: ``q_robot = robot_A u + robot_b`` for every robot joint, (n, m), (n,).
    """

    robot: PinocchioRobot
    cameras: tuple[str, ...]
    kind: str
    joint_index: NDArray[np.intp]
    parent: NDArray[np.int64]
    jtype: NDArray[np.int64]
    axis: Array
    R: Array
    t: Array
    cam_parent: NDArray[np.int64]
    cam_R: Array
    cam_t: Array
    anc: NDArray[np.bool_]
    solve_cameras: NDArray[np.int64]
    A: Array
    b: Array
    variables: tuple[str, ...]
    lower: Array
    upper: Array
    weight: Array
    eye: NDArray[np.bool_]
    robot_A: Array
    robot_b: Array
    moving: tuple[str, ...] = field(default=())
    _pinv: Array | None = field(default=None, repr=False)

    @property
    def m(self) -> int:
        """Number of unknowns."""
        return len(self.variables)

    def q_from_u(self, u: ArrayLike) -> Array:
        """The robot's readings (shape (..., n)) of unknowns ``u`` (shape (..., m))."""
        return np.asarray(u, dtype=float) @ self.robot_A.T + self.robot_b

    @property
    def robot_pinv(self) -> Array:
        """The pseudo-inverse of ``robot_A``, shape (m, n): computed once, on first use."""
        if self._pinv is None:
            self._pinv = np.asarray(np.linalg.pinv(self.robot_A), dtype=float)
        return self._pinv

    def u_from_q(self, q: Array) -> Array:
        """Unknowns ``u`` (shape (m,)) whose readings are closest to ``q`` (shape (n,)) in least
        squares, clipped to the bounds (exact for readings that satisfy the coupling)."""
        return np.clip(self.robot_pinv @ (q - self.robot_b), self.lower, self.upper)


def _mimics(urdf: str) -> dict[str, tuple[str, float, float]]:
    """``{joint: (driver, multiplier, offset)}`` of the URDF's ``<mimic>`` tags."""
    out = {}
    for joint in ET.fromstring(urdf).findall("joint"):
        mim = joint.find("mimic")
        if mim is not None and mim.get("joint"):
            out[str(joint.get("name"))] = (
                str(mim.get("joint")),
                float(mim.get("multiplier", "1")),
                float(mim.get("offset", "0")),
            )
    return out


def _axis(model: pin.Model, jid: int) -> Array:
    """Unit axis of 1-DoF joint ``jid`` in its own frame (from its motion subspace)."""
    jm = model.joints[jid]
    jd = jm.createData()
    jm.calc(jd, np.zeros(model.nq))
    S = np.array(jd.S).reshape(6)
    a = S[3:] if np.linalg.norm(S[3:]) > 0.5 else S[:3]
    return a / np.linalg.norm(a)


def build_chain(
    robot: PinocchioRobot,
    cameras: Sequence[str],
    joints: Sequence[str] | None = None,
    coupling: Coupling | None = None,
    rigid: str = "cyclopean",
) -> HeadChain:
    """The :class:`HeadChain` of ``cameras`` on ``robot``.

    Args:
        robot: The robot.
        cameras: One or two camera optical frame names.
        joints: The joints allowed to move; None: every joint on the root->camera paths.
        coupling: A stated linear coupling of some of those joints, or None.
        rigid: For two cameras with no joint between them: ``"cyclopean"`` (the mid axis
            through the target) or the master eye ``"left"`` / ``"right"``.

    Raises:
        ConfigurationError: Not one or two cameras, an unknown ``rigid`` mode, or a joint to move
            that is on no camera's path.
        UnknownNameError: A camera frame or joint the robot does not have.
        SpecError: A moving joint without finite limits, a coupling outside the joints' limits,
            or no joint that moves a camera.
    """
    cameras = tuple(cameras)
    if len(cameras) not in (1, 2):
        raise ConfigurationError(f"need one or two camera frames, got {list(cameras)}")
    if len(cameras) == 2 and cameras[0] == cameras[1]:
        raise ConfigurationError(
            f"camera frame {cameras[0]!r} is named twice; give two different "
            "frames, or one for a single camera"
        )
    if rigid not in RIGID_MODES:
        raise ConfigurationError(
            f"unknown rigid-stereo mode {rigid!r}; expected one of {', '.join(RIGID_MODES)}"
        )
    model = robot.model
    fids = [robot.frame_id(c) for c in cameras]
    names = robot.joint_names
    paths: list[list[int]] = []  # Pinocchio joint ids, root first
    for fid in fids:
        jid, path = model.frames[fid].parentJoint, []
        while jid > 0:
            path.append(jid)
            jid = model.parents[jid]
        paths.append(path[::-1])
    on_path = sorted(set().union(*paths))
    chain_of = {jid: k for k, jid in enumerate(on_path)}
    K = len(on_path)
    parent = np.array([chain_of.get(model.parents[j], -1) for j in on_path], dtype=np.int64)
    jtype = np.array(
        [PRISMATIC if robot.joint_kinds[j - 1] == "prismatic" else REVOLUTE for j in on_path],
        dtype=np.int64,
    )
    axis = np.array([_axis(model, j) for j in on_path]).reshape(K, 3)
    R = np.array([model.jointPlacements[j].rotation for j in on_path]).reshape(K, 3, 3)
    t = np.array([model.jointPlacements[j].translation for j in on_path]).reshape(K, 3)
    joint_index = np.array([j - 1 for j in on_path], dtype=np.intp)
    chain_names = [names[j - 1] for j in on_path]

    moving: list[str]
    if joints is None:
        moving = list(chain_names)
    else:
        moving = []
        for name in joints:
            robot.joint_index(name)  # UnknownNameError listing the robot's joints
            if name not in chain_names:
                raise ConfigurationError(
                    f"joint {name!r} moves none of the cameras {list(cameras)} (on their paths: {chain_names})"
                )
            if name not in moving:
                moving.append(name)
    mimic = _mimics(robot.urdf)
    coupled = set(coupling.joints) if coupling is not None else set()
    if coupling is not None:
        for name in coupling.joints:
            robot.joint_index(name)
            if name not in chain_names:
                raise ConfigurationError(
                    f"coupled joint {name!r} moves none of the cameras {list(cameras)}"
                )
    # the unknowns: moving joints that are neither mimic followers nor coupled, then the coupling's
    drivers = [n for n in moving if n not in coupled and not (n in mimic and mimic[n][0] in names)]
    variables = list(drivers) + (list(coupling.variables) if coupling is not None else [])
    m = len(variables)
    if m == 0:
        raise SpecError(f"no joint moves the cameras {list(cameras)}")
    lower, upper, rA, rb = _unknowns_map(
        robot, drivers, variables, moving, mimic, coupled, coupling
    )
    A = rA[joint_index]
    b = rb[joint_index]

    kind, solve_cameras, cam_parent, cam_R, cam_t, anc = _camera_placements(
        model, fids, paths, chain_of, rigid
    )
    C = len(cam_parent)
    eye, weight = _eyes_and_weights(kind, A, anc, jtype)
    return HeadChain(
        robot=robot,
        cameras=cameras,
        kind=kind,
        joint_index=joint_index,
        parent=parent,
        jtype=jtype,
        axis=np.ascontiguousarray(axis),
        R=np.ascontiguousarray(R),
        t=np.ascontiguousarray(t),
        cam_parent=np.array(cam_parent, dtype=np.int64),
        cam_R=np.ascontiguousarray(np.array(cam_R).reshape(C, 3, 3)),
        cam_t=np.ascontiguousarray(np.array(cam_t).reshape(C, 3)),
        anc=np.ascontiguousarray(anc[:C]),
        solve_cameras=np.array(solve_cameras, dtype=np.int64),
        A=np.ascontiguousarray(A),
        b=np.ascontiguousarray(b),
        variables=tuple(variables),
        lower=lower,
        upper=upper,
        weight=weight,
        eye=eye,
        robot_A=rA,
        robot_b=rb,
        moving=tuple(moving),
    )


def _unknowns_map(
    robot: PinocchioRobot,
    drivers: list[str],
    variables: list[str],
    moving: list[str],
    mimic: dict[str, tuple[str, float, float]],
    coupled: set[str],
    coupling: Coupling | None,
) -> tuple[Array, Array, Array, Array]:
    """The unknowns' bounds ``lower``, ``upper`` (m,) and the map ``q = rA u + rb`` from them to
    every joint reading (n, m), (n,): drivers as themselves, mimic followers through their driver
    (the driver bounded so the follower stays inside its limits), coupled joints through the
    coupling.

    Raises:
        SpecError: A limit PyBullet reads as none, a coupling outside the joints' limits, a
            moving joint without finite limits, or followers' limits that leave no range.
        ConfigurationError: A coupling of the wrong shape or with bad bounds.
    """
    m = len(variables)
    for name in moving:
        i = robot.joint_index(name)
        if robot.lower[i] > robot.upper[i]:  # PyBullet's way of writing "no limit"
            raise SpecError(
                f"{robot.source}: joint {name!r}: limit lower {robot.lower[i]:.9g} is above upper "
                f"{robot.upper[i]:.9g} (PyBullet reads that as no limit); gaze control needs finite "
                "limits with lower <= upper"
            )
    n = len(robot.joint_names)
    lower = np.empty(m)
    upper = np.empty(m)
    rA = np.zeros((n, m))
    rb = home_readings(robot)
    for v, name in enumerate(drivers):
        i = robot.joint_index(name)
        lower[v], upper[v] = robot.lower[i], robot.upper[i]
        rA[i], rb[i] = 0.0, 0.0
        rA[i, v] = 1.0
    for name in moving:  # mimic followers of a driver among the unknowns
        if name in mimic and name not in coupled and mimic[name][0] in drivers:
            drv, mult, off = mimic[name]
            v, i = drivers.index(drv), robot.joint_index(name)
            rA[i], rb[i] = 0.0, off
            rA[i, v] = mult
            # bound the driver so that the follower stays inside its limits too
            lo, hi = (
                sorted(((robot.lower[i] - off) / mult, (robot.upper[i] - off) / mult))
                if mult
                else (-np.inf, np.inf)
            )
            lower[v], upper[v] = max(lower[v], lo), min(upper[v], hi)
    if coupling is not None:
        c0 = len(drivers)
        Ac, bc = np.asarray(coupling.A, dtype=float), np.asarray(coupling.b, dtype=float)
        lo_c, hi_c = (
            np.asarray(coupling.lower, dtype=float),
            np.asarray(coupling.upper, dtype=float),
        )
        if Ac.shape != (len(coupling.joints), len(coupling.variables)) or bc.shape != (
            len(coupling.joints),
        ):
            raise ConfigurationError(
                f"coupling A must be ({len(coupling.joints)}, {len(coupling.variables)}) and b ({len(coupling.joints)},)"
            )
        if not (np.all(np.isfinite(lo_c)) and np.all(np.isfinite(hi_c)) and np.all(lo_c <= hi_c)):
            raise ConfigurationError(
                f"coupling bounds must be finite with lower <= upper, got {lo_c.tolist()}..{hi_c.tolist()}"
            )
        lower[c0:], upper[c0:] = lo_c, hi_c
        mid, half = 0.5 * (lo_c + hi_c), 0.5 * (hi_c - lo_c)
        for r, name in enumerate(coupling.joints):
            i = robot.joint_index(name)
            centre = float(Ac[r] @ mid + bc[r])
            reach = float(np.abs(Ac[r]) @ half)
            if centre - reach < robot.lower[i] - 1e-12 or centre + reach > robot.upper[i] + 1e-12:
                raise SpecError(
                    f"coupling drives joint {name!r} over [{centre - reach:.6g}, {centre + reach:.6g}], "
                    f"outside its limits [{robot.lower[i]:.6g}, {robot.upper[i]:.6g}]"
                )
            rA[i], rb[i] = 0.0, bc[r]
            rA[i, c0:] = Ac[r]
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        bad = [
            variables[v]
            for v in range(m)
            if not (math.isfinite(lower[v]) and math.isfinite(upper[v]))
        ]
        raise SpecError(f"joints {bad} need finite <limit lower/upper> for gaze control")
    if np.any(lower > upper):
        bad = [variables[v] for v in range(m) if lower[v] > upper[v]]
        raise SpecError(f"joints {bad}: their mimic followers' limits leave no range")
    return lower, upper, rA, rb


def _camera_placements(
    model: pin.Model, fids: list[int], paths: list[list[int]], chain_of: dict[int, int], rigid: str
) -> tuple[str, list[int], list[int], list[Array], list[Array], NDArray[np.bool_]]:
    """The head's kind, the cameras it solves, each camera's parent in the chain and placement
    (a rigid pair solved on its cyclopean axis adds a virtual camera, index 2), and which chain
    joints move each camera (3, K)."""
    cam_parent = [chain_of.get(model.frames[f].parentJoint, -1) for f in fids]
    cam_R = [model.frames[f].placement.rotation for f in fids]
    cam_t = [model.frames[f].placement.translation for f in fids]
    anc = np.zeros((3, len(chain_of)), dtype=bool)
    for c, path in enumerate(paths):
        for j in path:
            anc[c, chain_of[j]] = True
    if len(fids) == 1:
        kind, solve_cameras = KIND_ONE_CAMERA, [0]
    elif set(paths[0]) == set(paths[1]):
        kind = KIND_RIGID_STEREO
        if rigid == "cyclopean":
            cam_parent.append(cam_parent[0])
            cam_R_v, cam_t_v = _cyclopean_placement(
                model, fids, int(model.frames[fids[0]].parentJoint)
            )
            cam_R.append(cam_R_v)
            cam_t.append(cam_t_v)
            anc[2] = anc[0]
            solve_cameras = [2]
        else:
            solve_cameras = [0 if rigid == "left" else 1]
    else:
        kind, solve_cameras = KIND_BINOCULAR, [0, 1]
    return kind, solve_cameras, cam_parent, cam_R, cam_t, anc


def _eyes_and_weights(
    kind: str, A: Array, anc: NDArray[np.bool_], jtype: NDArray[np.int64]
) -> tuple[NDArray[np.bool_], Array]:
    """Which unknowns are an eye's (on a binocular head, moving joints on one camera's path only),
    and each unknown's step weight (prismatic, eye, or 1)."""
    m = A.shape[1]
    eye = np.zeros(m, dtype=bool)
    if kind == KIND_BINOCULAR:  # an eye unknown moves joints on one camera's path only
        for v in range(m):
            cols = np.flatnonzero(np.abs(A[:, v]) > 0)
            eye[v] = len(cols) > 0 and not np.any(anc[0, cols] & anc[1, cols])
    weight = np.ones(m)
    for v in range(m):
        cols = np.flatnonzero(np.abs(A[:, v]) > 0)
        if len(cols) and np.all(jtype[cols] == PRISMATIC):
            weight[v] = PRISMATIC_WEIGHT
        elif eye[v]:
            weight[v] = EYE_WEIGHT
    return eye, weight


def _cyclopean_placement(model: pin.Model, fids: list[int], jid: int) -> tuple[Array, Array]:
    """Placement, on joint ``jid``, of the virtual camera of a rigid pair: at the midpoint of the
    two centres, z along the sum of the optical axes, x along the baseline (left to right)
    made orthogonal to z."""
    P = [model.frames[f].placement for f in fids]
    if any(model.frames[f].parentJoint != jid for f in fids):  # on different links of one body
        data = model.createData()
        q = pin.neutral(model)
        pin.framesForwardKinematics(model, data, q)
        base = data.oMi[jid]
        P = [base.actInv(data.oMf[f]) for f in fids]
    o = 0.5 * (P[0].translation + P[1].translation)
    z = P[0].rotation[:, 2] + P[1].rotation[:, 2]
    if np.linalg.norm(z) < 1e-9:
        raise SpecError(
            "the two cameras of the rigid pair look in opposite directions: no cyclopean axis"
        )
    z = z / np.linalg.norm(z)
    x = P[1].translation - P[0].translation
    x = x - (x @ z) * z
    if np.linalg.norm(x) < 1e-12:
        x = P[0].rotation[:, 0] - (P[0].rotation[:, 0] @ z) * z
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z]), o


def mid_limits(lower: Array, upper: Array) -> Array:
    """The middle of every joint's limits ``lower``..``upper`` [rad]/[m], shape (n,); 0 for a
    joint without finite limits (continuous)."""
    finite = np.isfinite(lower) & np.isfinite(upper)
    return np.where(
        finite, 0.5 * (np.where(finite, lower, 0.0) + np.where(finite, upper, 0.0)), 0.0
    )


def home_readings(robot: PinocchioRobot) -> Array:
    """The home posture: :func:`mid_limits` of the robot's joints."""
    return mid_limits(robot.lower, robot.upper)


def check_joint_names(robot: PinocchioRobot, names: Sequence[str]) -> None:
    """:class:`UnknownNameError` for the first of ``names`` the robot does not have."""
    for name in names:
        if name not in robot.joint_names:
            raise UnknownNameError("joint", name, robot.joint_names)


__all__ = [
    "EYE_WEIGHT",
    "KIND_BINOCULAR",
    "KIND_ONE_CAMERA",
    "KIND_RIGID_STEREO",
    "PRISMATIC",
    "PRISMATIC_WEIGHT",
    "REVOLUTE",
    "RIGID_MODES",
    "Coupling",
    "HeadChain",
    "build_chain",
    "check_joint_names",
    "home_readings",
    "mid_limits",
]
