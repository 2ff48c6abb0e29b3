"""The residuals of a calibration about the URDF and their analytic Jacobian (:mod:`prior_fit`).

Each calibrated joint's axis frame is perturbed from the nominal model's, ``E_J = E_J0 P(xi_J)``
with ``P(xi) = Trans(v) Rot(omega)`` (:func:`perturbation`), and the perturbation has a Gaussian
prior of the stated manufacturing tolerances (:class:`Tolerances`). The measuring frame
(``T_world_base``), each measured frame's constant (unless it is a link the URDF places: then the
same tolerances) and each marker's position are free. Rows: measured points (or frame origins)
and frame orientations in noise units, then the prior's. The Jacobian of a point under a local
perturbation ``(v, omega)`` of an upstream frame ``A`` is ``R_A R(omega)^T`` and
``-R_A [x_A]_x Jr(omega)``; an orientation residual's goes through ``Jl^-1`` of the residual;
``tests/test_prior_fit.py`` checks them against finite differences.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import UNKNOWN_MOUNTS, MeasurementSet
from cpc2urdf.model import BASE, CPCModel, CPCParams, RobotStructure
from cpc2urdf.registration import transforms_from_point_pairs
from cpc2urdf.transforms import Array, homogeneous, inverse, skew


@dataclass(frozen=True)
class Tolerances:
    """The prior: one standard deviation of each joint origin's deviation from the URDF.

    Attributes:
        offset_rad: A revolute joint's reading offset [rad].
        offset_m: A prismatic joint's reading offset [m].
        translation_m: Each coordinate of a joint origin's position [m].
        rotation_rad: Each tilt of a joint's axis [rad].
    """

    offset_rad: float = math.radians(1.0)
    offset_m: float = 1e-3
    translation_m: float = 3e-3
    rotation_rad: float = math.radians(0.25)
    compliance: float = 1e-3
    compliance_m: float = 1e-6


@dataclass(frozen=True)
class Noise:
    """Measurement noise: one standard deviation per coordinate.

    Attributes:
        position_m: Of a measured point or a frame's origin [m].
        rotation_rad: Of a measured frame's orientation, per axis [rad].
    """

    position_m: float = 1e-3
    rotation_rad: float = math.radians(0.1)


def perturbation(xi: Array) -> Array:
    """``P(xi) = Trans(v) Rot(omega)``, shape (4, 4), for ``xi = (v, omega)`` shape (6,)."""
    return homogeneous(Rotation.from_rotvec(xi[3:]).as_matrix(), xi[:3])


def _right_jacobian(w: Array) -> Array:
    """SO(3) right Jacobian of the rotation vector ``w``: ``Rot(w + dw) ~ Rot(w) Rot(Jr dw)``."""
    t = float(np.linalg.norm(w))
    K = skew(w)
    if t < 1e-8:
        return np.eye(3) - 0.5 * K
    return np.eye(3) - (1 - math.cos(t)) / t**2 * K + (t - math.sin(t)) / t**3 * K @ K


def _left_jacobian_inverse(r: Array) -> Array:
    """``Jl(r)^-1`` of each rotation vector ``r`` (N, 3): ``log(exp(d) exp(r)) ~ r + Jl^-1 d``, shape (N, 3, 3)."""
    t = np.linalg.norm(r, axis=1)
    K = skew(r)
    small = t < 1e-6
    ts = np.where(small, 1.0, t)
    c = np.where(small, 1.0 / 12.0, (1.0 / ts**2 - (1 + np.cos(ts)) / (2 * ts * np.sin(ts))))
    return np.eye(3) - 0.5 * K + c[:, None, None] * (K @ K)


def _components(model: CPCModel, joint: str, level: str) -> list[int]:
    """Which of ``xi``'s six entries a level frees for ``joint``."""
    if level == "frames":
        return []
    if level == "compliance":
        level = "geometry"
    if level == "offsets":
        return [5] if model.structure.joint(joint).type == "revolute" else [2]
    return list(range(6))


def _upstream(s: RobotStructure, frame: str) -> list[int]:
    """Indices of the joints on the path from the base to ``frame``."""
    out, parent = [], s.frame(frame).parent
    while parent != BASE:
        i = s.joint_index(parent)
        out.append(i)
        parent = s.joints[i].parent
    return out


def default_joints(ms: MeasurementSet) -> tuple[str, ...]:
    """The joints the data move, on the paths to the measured frames and markers."""
    frames = set(ms.frames) | {
        ms.markers[m].frame for m in ms.marker_points if ms.has_marker(m).any()
    }
    on_paths = {i for f in frames for i in _upstream(ms.structure, f)}
    span = np.ptp(ms.q, axis=0)
    return tuple(ms.structure.joint_names[i] for i in sorted(on_paths) if span[i] > 0)


class MapProblem:
    """The residuals and their Jacobian for one level, joint set, prior and noise."""

    def __init__(
        self,
        nominal: CPCModel,
        ms: MeasurementSet,
        level: str,
        joints: Sequence[str],
        tol: Tolerances,
        noise: Noise,
        loads: Array | None = None,
    ) -> None:
        self.nominal, self.ms, self.level, self.tol, self.noise = nominal, ms, level, tol, noise
        self.loads = loads
        self._cache: tuple[bytes, tuple[CPCModel, Array, Array, Array]] | None = None
        s = nominal.structure
        self.joints = tuple(joints)
        self.pose_frames = [f for f in ms.frames if ms.has_pose(f).any()]
        self.markers = [m for m in ms.marker_points if ms.has_marker(m).any()]
        self.unknown = [m for m in self.markers if not ms.markers[m].known]
        names: list[str] = [f"world.{k}" for k in ("x", "y", "z", "rx", "ry", "rz")]
        self.slots: dict[str, tuple[int, list[int]]] = {}  # block -> (first index, xi components)
        self.slots["world"] = (0, list(range(6)))
        prior: list[float] = [0.0] * 6
        for j in self.joints:
            comps = _components(nominal, j, level)
            if not comps:
                continue
            self.slots[j] = (len(names), comps)
            revolute = s.joint(j).type == "revolute"
            for c in comps:
                names.append(f"{j}.{('x', 'y', 'z', 'rx', 'ry', 'rz')[c]}")
                if c == 5 and revolute:
                    prior.append(tol.offset_rad)
                elif c == 2 and not revolute:
                    prior.append(tol.offset_m)
                else:
                    prior.append(tol.translation_m if c < 3 else tol.rotation_rad)
        # A measured frame is a link of the URDF, placed within the tolerances, unless the set says
        # its mount is unknown (a tool or camera whose pose on the link nobody measured).
        self.unknown_mounts = [
            f for f in self.pose_frames if f in ms.metadata.get(UNKNOWN_MOUNTS, ())
        ]
        for f in self.pose_frames:
            self.slots["frame:" + f] = (len(names), list(range(6)))
            names += [f"{f}.{k}" for k in ("x", "y", "z", "rx", "ry", "rz")]
            prior += (
                [0.0] * 6
                if f in self.unknown_mounts
                else [tol.translation_m] * 3 + [tol.rotation_rad] * 3
            )
        self.compliance: dict[str, int] = {}
        if level == "compliance":
            if loads is None:
                raise DegenerateDataError(
                    f"{ms.source}: the compliance level needs the joints' gravity loads "
                    "(the URDF has no inertials on the measured paths)"
                )
            for j in self.joints:
                self.compliance[j] = len(names)
                names.append(f"{j}.compliance")
                prior.append(tol.compliance if s.joint(j).type == "revolute" else tol.compliance_m)
        self.marker_slot: dict[str, int] = {}
        for m in self.unknown:
            self.marker_slot[m] = len(names)
            names += [f"{m}.{k}" for k in ("x", "y", "z")]
            prior += [0.0] * 3
        self.names = tuple(names)
        self.prior = np.array(prior)
        self.has_prior = self.prior > 0
        self.upstream = {
            f: _upstream(s, f)
            for f in {*self.pose_frames, *(ms.markers[m].frame for m in self.markers)}
        }

    # ---- the model at a parameter vector --------------------------------------------------------

    def xi(self, x: Array, block: str) -> Array:
        first, comps = self.slots[block]
        out = np.zeros(6)
        out[comps] = x[first : first + len(comps)]
        return out

    def model(self, x: Array) -> CPCModel:
        nom = self.nominal
        joints = {
            j: CPCParams.from_matrix(nom.joints[j].matrix() @ perturbation(self.xi(x, j)))
            for j in self.joints
            if j in self.slots
        }
        frames = {
            f: CPCParams.from_matrix(
                nom.frames[f].matrix() @ perturbation(self.xi(x, "frame:" + f))
            )
            for f in self.pose_frames
        }
        W = nom.T_world_base() @ perturbation(self.xi(x, "world"))
        return nom.with_params(world_to_base=CPCParams.from_matrix(W), joints=joints, frames=frames)

    def q(self, x: Array) -> Array:
        """The readings deflected by the loads: ``q + c tau``."""
        q = self.ms.q.copy()
        s = self.nominal.structure
        for j, i in self.compliance.items():
            assert self.loads is not None
            k = s.joint_index(j)
            q[:, k] += x[i] * self.loads[:, k]
        return q

    def marker_position(self, x: Array, m: str) -> Array:
        if m in self.marker_slot:
            i = self.marker_slot[m]
            return x[i : i + 3]
        return np.asarray(self.ms.markers[m].position, dtype=float)

    # ---- residuals and Jacobian -----------------------------------------------------------------

    def _local(
        self,
        J: Array,
        cols: int,
        A: Array,
        R_omega: Array,
        Jr: Array,
        y: Array,
        comps: list[int],
        rot: bool = False,
    ) -> None:
        """Add the effect of a local perturbation of frame ``A`` (N, 4, 4) on points ``y`` (N, 3)
        (or, with ``rot``, on orientations) to ``J[:, :, cols:]``."""
        R = A[:, :3, :3]
        full = np.zeros((A.shape[0], 3, 6))
        if rot:
            full[:, :, 3:] = R @ Jr
        else:
            x_local = np.einsum("nji,nj->ni", R, y - A[:, :3, 3])
            full[:, :, :3] = R @ R_omega.T
            full[:, :, 3:] = -R @ (skew(x_local) @ Jr)
        J[:, :, cols : cols + len(comps)] += full[:, :, comps]

    def _block_local(
        self, J: Array, block: str, A: Array, x: Array, y: Array, rot: bool = False
    ) -> None:
        if block not in self.slots:
            return
        first, comps = self.slots[block]
        xi = self.xi(x, block)
        Rw = Rotation.from_rotvec(xi[3:]).as_matrix()
        self._local(J, first, A, Rw, _right_jacobian(xi[3:]), y, comps, rot)

    def _kinematics(self, x: Array) -> tuple[CPCModel, Array, Array, Array]:
        """The model at ``x``, the deflected readings and every axis and link frame (the last one
        kept: the optimiser asks for the residuals and then the Jacobian at the same point)."""
        key = x.tobytes()
        if self._cache is None or self._cache[0] != key:
            model = self.model(x)
            q = self.q(x)
            self._cache = (key, (model, q, *model.link_poses(q)))
        return self._cache[1]

    def evaluate(self, x: Array, jacobian: bool = True) -> tuple[Array, Array | None]:
        """Weighted residuals (measurements, then prior) and their Jacobian."""
        model, q, axis, link = self._kinematics(x)
        ms, n = self.ms, len(x)
        W = model.T_world_base()
        res: list[Array] = []
        jac: list[Array] = []

        def chain(T_rows: Array, y: Array, frame: str, rows: np.ndarray, rot: bool) -> Array:
            N = len(rows)
            J = np.zeros((N, 3, n))
            self._block_local(J, "world", np.broadcast_to(W, (N, 4, 4)), x, y, rot)
            if ("frame:" + frame) in self.slots:
                self._block_local(J, "frame:" + frame, T_rows, x, y, rot)
            for i in self.upstream[frame]:
                name = model.structure.joint_names[i]
                self._block_local(J, name, axis[rows, i], x, y, rot)
                if name in self.compliance:  # d(point)/dq of the joint, times its load
                    assert self.loads is not None
                    z = axis[rows, i][:, :3, 2]
                    if model.structure.joints[i].type == "revolute":
                        d = z if rot else np.cross(z, y - link[rows, i][:, :3, 3])
                    else:
                        d = np.zeros_like(z) if rot else z
                    J[:, :, self.compliance[name]] += d * self.loads[rows, i][:, None]
            return J

        s = model.structure
        for m in self.markers:
            mk = ms.markers[m]
            rows = np.flatnonzero(ms.has_marker(m))
            p = s.frame(mk.frame).parent
            T = (
                link[rows, s.joint_index(p)] if p != BASE else np.broadcast_to(W, (len(rows), 4, 4))
            ) @ model.frames[mk.frame].matrix()
            pos = self.marker_position(x, m)
            y = T[:, :3, :3] @ pos + T[:, :3, 3]
            res.append(((y - ms.marker_points[m][rows]) / self.noise.position_m).ravel())
            if jacobian:
                J = chain(T, y, mk.frame, rows, False)
                if m in self.marker_slot:
                    i = self.marker_slot[m]
                    J[:, :, i : i + 3] += T[:, :3, :3]
                jac.append(J.reshape(-1, n) / self.noise.position_m)
        for f in self.pose_frames:
            rows = np.flatnonzero(ms.has_pose(f))
            T = model.fk(q[rows], [f])[f]
            Tm = ms.poses[f][rows]
            y = T[:, :3, 3]
            res.append(((y - Tm[:, :3, 3]) / self.noise.position_m).ravel())
            dr = Rotation.from_matrix(
                T[:, :3, :3] @ np.transpose(Tm[:, :3, :3], (0, 2, 1))
            ).as_rotvec()
            res.append((dr / self.noise.rotation_rad).ravel())
            if jacobian:
                jac.append(chain(T, y, f, rows, False).reshape(-1, n) / self.noise.position_m)
                Jrot = _left_jacobian_inverse(dr) @ chain(T, y, f, rows, True)
                jac.append(Jrot.reshape(-1, n) / self.noise.rotation_rad)
        idx = np.flatnonzero(self.has_prior)
        prior_res = x[idx] / self.prior[idx]
        Jp = np.zeros((len(idx), n))
        Jp[np.arange(len(idx)), idx] = 1.0 / self.prior[idx]
        res.append(prior_res)
        jac.append(Jp)
        return np.concatenate(res), (np.vstack(jac) if jacobian else None)

    def row_records(self) -> tuple[np.ndarray, np.ndarray]:
        """Per measurement row: its record, and whether it is a point's (or origin's) coordinate."""
        rec: list[np.ndarray] = []
        point: list[np.ndarray] = []
        for m in self.markers:
            r = np.repeat(np.flatnonzero(self.ms.has_marker(m)), 3)
            rec.append(r)
            point.append(np.ones(len(r), bool))
        for f in self.pose_frames:
            r = np.repeat(np.flatnonzero(self.ms.has_pose(f)), 3)
            rec += [r, r]
            point += [np.ones(len(r), bool), np.zeros(len(r), bool)]
        return np.concatenate(rec), np.concatenate(point)


def _register(P: Array, Y: Array, source: str) -> Array:
    """The rigid transform taking the predicted points ``P`` (K, 3) onto the measured ``Y``. Points
    that span only a line (a ball seated in two sockets) leave the turn about it free: the start
    takes the smallest rotation that aligns the lines, and the fit keeps that turn as it keeps any
    freedom the data cannot see."""
    try:
        return transforms_from_point_pairs(P, Y, what=f"{source}: measured points")
    except DegenerateDataError:
        cP, cY = P.mean(0), Y.mean(0)
        dP, dY = np.linalg.svd(P - cP)[2][0], np.linalg.svd(Y - cY)[2][0]
        if float(((P - cP) @ dP) @ ((Y - cY) @ dY)) < 0:
            dY = -dY
        R = Rotation.align_vectors(dY[None], dP[None])[0].as_matrix()
        return homogeneous(R, cY - R @ cP)


def start_point(problem: MapProblem) -> Array:
    """A start: the measuring frame, measured frames and markers placed on the nominal model by
    alternating a rigid registration with their own least-squares placement."""
    ms, nom = problem.ms, problem.nominal
    x = np.zeros(len(problem.names))
    base = {f: nom.fk(ms.q, [f])[f] for f in problem.upstream}
    W_inv = inverse(nom.T_world_base())
    base = {f: W_inv @ T for f, T in base.items()}  # T_base_frame
    C = {f: np.eye(4) for f in problem.pose_frames}  # measured frame correction on its link
    p = {
        m: (np.zeros(3) if m in problem.marker_slot else problem.marker_position(x, m))
        for m in problem.markers
    }
    W = np.eye(4)
    for _ in range(30):
        P, Y = [], []
        for m in problem.markers:
            rows = ms.has_marker(m)
            T = base[ms.markers[m].frame][rows]
            P.append(T[:, :3, :3] @ p[m] + T[:, :3, 3])
            Y.append(ms.marker_points[m][rows])
        for f in problem.pose_frames:
            rows = ms.has_pose(f)
            T = base[f][rows] @ C[f]
            P.append(T[:, :3, 3])
            Y.append(ms.poses[f][rows][:, :3, 3])
        W = _register(np.vstack(P), np.vstack(Y), ms.source)
        Wi = inverse(W)
        for m in problem.unknown:
            rows = ms.has_marker(m)
            T = base[ms.markers[m].frame][rows]
            y_b = ms.marker_points[m][rows] @ Wi[:3, :3].T + Wi[:3, 3]
            p[m] = np.einsum("nji,nj->ni", T[:, :3, :3], y_b - T[:, :3, 3]).mean(0)
        for f in problem.unknown_mounts:
            rows = ms.has_pose(f)
            D = np.linalg.solve(
                base[f][rows], Wi @ ms.poses[f][rows]
            )  # T_frame_measured, per record
            R = Rotation.from_matrix(D[:, :3, :3]).mean().as_matrix()
            C[f] = homogeneous(R, D[:, :3, 3].mean(0))
    x[:6] = _xi_of(W_inv @ W)
    for f in problem.pose_frames:
        first, _ = problem.slots["frame:" + f]
        x[first : first + 6] = _xi_of(C[f])
    for m in problem.unknown:
        i = problem.marker_slot[m]
        x[i : i + 3] = p[m]
    return x


def _xi_of(P: Array) -> Array:
    """The inverse of :func:`perturbation`."""
    return np.concatenate([P[:3, 3], Rotation.from_matrix(P[:3, :3]).as_rotvec()])


__all__ = ["MapProblem", "Noise", "Tolerances", "default_joints", "perturbation", "start_point"]
