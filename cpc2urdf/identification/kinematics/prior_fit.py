"""Maximum a posteriori calibration about the user's URDF: what the data barely see stays put.

Real robots give few postures, joints the data barely move and unmodelled error (elastic links,
backlash, marker bodies). A maximum-likelihood fit of every CPC parameter over-fits such data and
turns weakly seen axes freely. Here each calibrated joint's axis frame is perturbed from the
nominal model's, ``E_J = E_J0 P(xi_J)`` with ``P(xi) = Trans(v) Rot(omega)`` (``xi = (v, omega)``,
in the nominal axis frame: ``omega_z`` of a revolute joint, ``v_z`` of a prismatic one, is its
reading's offset), and the perturbation has a Gaussian prior of the stated manufacturing
tolerances (:class:`Tolerances`). The measuring frame (``T_world_base``), each measured frame's
constant (unless it is a link the URDF places: then the same tolerances) and each marker's
position are free. The measurement noise is estimated from the
residuals (position and rotation apart), so nothing needs to be stated.

Three model levels (:data:`LEVELS`): ``frames`` (the URDF as it is: only the measuring frame and
the measured frames or markers are fitted), ``offsets`` (plus one offset per joint) and
``geometry`` (plus every origin's position and orientation). :func:`select_model` chooses among them by
leave-one-record-out cross-validation; :func:`fit_map` fits one.

Jacobians are analytic (the first-order change of a point under a local perturbation of an
upstream frame); ``tests/test_prior_fit.py`` checks them against finite differences.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.measurements import UNKNOWN_MOUNTS, MeasurementSet
from cpc2urdf.model import BASE, CPCModel, CPCParams
from cpc2urdf.registration import transforms_from_point_pairs
from cpc2urdf.transforms import Array, homogeneous, inverse, skew

LEVELS = ("frames", "offsets", "geometry", "compliance")
CV_FOLDS = 5  # [-]: folds of :func:`cross_validate`
# A richer level must predict left-out records this much better (a fraction of the RMS) to be chosen.
SELECTION_MARGIN = 0.05  # [-]
NOISE_ITERATIONS = 20  # [-]: at most this many refits while the noise estimate settles (1 %)
NOISE_FLOOR = 1e-10  # [m] / [rad]: below this a noise estimate is taken as this (noise-free data)


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


@dataclass(frozen=True, eq=False)
class MapFit:
    """One maximum a posteriori fit.

    Attributes:
        model: The calibrated model (joints, measuring frame and measured frames).
        level: One of :data:`LEVELS`.
        joints: The calibrated joints (CPC names).
        perturbations: Joint -> ``xi = (v [m], omega [rad])``, shape (6,).
        markers: Marker -> position in its frame [m], shape (3,) (identified or given).
        noise: The noise estimated from the residuals (or as given when ``estimate_noise`` is off).
        covariance: Posterior covariance of the free parameters (:attr:`names` order).
        names: One label per free parameter.
        rms_m: RMS distance of the measured points (or frame origins) to the fit [m].
        dof: Effective number of parameters the data determined (trace of the hat matrix).
        dof_position: The part of ``dof`` the position rows used (the rest: orientations).
        loo_sq_m2: Per record, the squared distances of its points to the fit made without it,
            summed [m^2], shape (N,).
        loo_points: Per record, how many points (markers, frame origins) it measured, shape (N,).
        loo_rot_sq: Per record, its frames' squared orientation residuals left out, summed
            [rad^2], shape (N,) (zeros for marker points).
        loo_stat: Per record, ``r_i^T (I - H_ii)^-1 r_i`` over its position rows, in noise units:
            chi-square with ``3 loo_points`` degrees of freedom for a good record, shape (N,).
        loo_stat_rot: The same over its orientation rows (3 a measured frame), shape (N,).
        loo_frames: Per record, how many frame poses it measured, shape (N,).
        residual_noise: The noise the residuals show (equal to ``noise`` when it was estimated).
        data_share: Joint -> how much the data narrowed its perturbation: ``1 - posterior
            variance / prior variance``, mean over its free components (1: the data alone fix it,
            0: the prior alone, as for a joint whose effect the measuring frame absorbs).
    """

    model: CPCModel
    level: str
    joints: tuple[str, ...]
    perturbations: dict[str, Array]
    markers: dict[str, Array]
    noise: Noise
    covariance: Array
    names: tuple[str, ...]
    rms_m: float
    dof: float
    dof_position: float
    loo_sq_m2: Array
    loo_points: Array
    loo_rot_sq: Array
    loo_stat: Array
    loo_stat_rot: Array
    loo_frames: Array
    residual_noise: Noise
    data_share: dict[str, float] = field(default_factory=dict)
    compliance: dict[str, float] = field(default_factory=dict)

    @property
    def loo_rms_m(self) -> float:
        """RMS distance of the measured points to fits made without their record [m]: the error
        this fit predicts for new postures (leave-one-record-out cross-validation)."""
        return math.sqrt(float(self.loo_sq_m2.sum()) / max(float(self.loo_points.sum()), 1.0))

    def deflected(self, q: Array, loads: Array | None) -> Array:
        """Readings ``q`` (N, n) deflected by ``loads`` (N, n) through the fitted compliances."""
        if not self.compliance:
            return q
        assert loads is not None
        out = np.array(q, dtype=float)
        for j, c in self.compliance.items():
            k = self.model.structure.joint_index(j)
            out[:, k] += c * loads[:, k]
        return out


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


def _skews(v: Array) -> Array:
    """``[v]_x`` of each row of ``v`` (N, 3), shape (N, 3, 3)."""
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    out[:, 1, 0], out[:, 2, 0], out[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return out


def _left_jacobian_inverse(r: Array) -> Array:
    """``Jl(r)^-1`` of each rotation vector ``r`` (N, 3): ``log(exp(d) exp(r)) ~ r + Jl^-1 d``, shape (N, 3, 3)."""
    t = np.linalg.norm(r, axis=1)
    K = _skews(r)
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


def _upstream(model: CPCModel, frame: str) -> list[int]:
    """Indices of the joints on the path from the base to ``frame``."""
    s = model.structure
    out, parent = [], s.frame(frame).parent
    while parent != BASE:
        i = s.joint_index(parent)
        out.append(i)
        parent = s.joints[i].parent
    return out


def default_joints(ms: MeasurementSet) -> tuple[str, ...]:
    """The joints the data move, on the paths to the measured frames and markers."""
    frames = set(ms.frames) | {ms.markers[m].frame for m in ms.marker_points if ms.has_marker(m).any()}
    on_paths: set[int] = set()
    for f in frames:
        parent = ms.structure.frame(f).parent
        while parent != BASE:
            i = ms.structure.joint_index(parent)
            on_paths.add(i)
            parent = ms.structure.joints[i].parent
    span = np.ptp(ms.q, axis=0)
    return tuple(ms.structure.joint_names[i] for i in sorted(on_paths) if span[i] > 0)


class _Problem:
    """The residuals and their Jacobian for one level, joint set, prior and noise."""

    def __init__(self, nominal: CPCModel, ms: MeasurementSet, level: str, joints: Sequence[str],
                 tol: Tolerances, noise: Noise, loads: Array | None = None) -> None:
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
        self.unknown_mounts = [f for f in self.pose_frames if f in ms.metadata.get(UNKNOWN_MOUNTS, ())]
        for f in self.pose_frames:
            self.slots["frame:" + f] = (len(names), list(range(6)))
            names += [f"{f}.{k}" for k in ("x", "y", "z", "rx", "ry", "rz")]
            prior += [0.0] * 6 if f in self.unknown_mounts else [tol.translation_m] * 3 + [tol.rotation_rad] * 3
        self.compliance: dict[str, int] = {}
        if level == "compliance":
            if loads is None:
                raise DegenerateDataError(f"{ms.source}: the compliance level needs the joints' gravity loads "
                                          "(the URDF has no inertials on the measured paths)")
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
        self.upstream = {f: _upstream(nominal, f) for f in {*self.pose_frames, *(ms.markers[m].frame for m in self.markers)}}

    # ---- the model at a parameter vector --------------------------------------------------------

    def xi(self, x: Array, block: str) -> Array:
        first, comps = self.slots[block]
        out = np.zeros(6)
        out[comps] = x[first:first + len(comps)]
        return out

    def model(self, x: Array) -> CPCModel:
        nom = self.nominal
        joints = {j: CPCParams.from_matrix(nom.joints[j].matrix() @ perturbation(self.xi(x, j)))
                  for j in self.joints if j in self.slots}
        frames = {f: CPCParams.from_matrix(nom.frames[f].matrix() @ perturbation(self.xi(x, "frame:" + f)))
                  for f in self.pose_frames}
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
            return x[i:i + 3]
        return np.asarray(self.ms.markers[m].position, dtype=float)

    # ---- residuals and Jacobian -----------------------------------------------------------------

    def _local(self, J: Array, cols: int, A: Array, R_omega: Array, Jr: Array, y: Array, comps: list[int],
               rot: bool = False) -> None:
        """Add the effect of a local perturbation of frame ``A`` (N, 4, 4) on points ``y`` (N, 3)
        (or, with ``rot``, on orientations) to ``J[:, :, cols:]``."""
        R = A[:, :3, :3]
        full = np.zeros((A.shape[0], 3, 6))
        if rot:
            full[:, :, 3:] = R @ Jr
        else:
            x_local = np.einsum("nji,nj->ni", R, y - A[:, :3, 3])
            full[:, :, :3] = R @ R_omega.T
            full[:, :, 3:] = -R @ (_skews(x_local) @ Jr)
        J[:, :, cols:cols + len(comps)] += full[:, :, comps]

    def _block_local(self, J: Array, block: str, A: Array, x: Array, y: Array, rot: bool = False) -> None:
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
            for i in self.upstream[frame]:
                name = model.structure.joint_names[i]
                self._block_local(J, name, axis[rows, i], x, y, rot)
            if ("frame:" + frame) in self.slots:
                self._block_local(J, "frame:" + frame, T_rows, x, y, rot)
            for i in self.upstream[frame]:
                name = model.structure.joint_names[i]
                if name in self.compliance:
                    A = axis[rows, i]
                    z = A[:, :3, 2]
                    if rot:
                        d = z if model.structure.joints[i].type == "revolute" else np.zeros_like(z)
                    else:
                        d = np.cross(z, y - link[rows, i][:, :3, 3]) if model.structure.joints[i].type == "revolute" else z
                    assert self.loads is not None
                    J[:, :, self.compliance[name]] += d * self.loads[rows, i][:, None]
            return J

        s = model.structure
        for m in self.markers:
            mk = ms.markers[m]
            rows = np.flatnonzero(ms.has_marker(m))
            p = s.frame(mk.frame).parent
            T = (link[rows, s.joint_index(p)] if p != BASE else np.broadcast_to(W, (len(rows), 4, 4))) \
                @ model.frames[mk.frame].matrix()
            pos = self.marker_position(x, m)
            y = T[:, :3, :3] @ pos + T[:, :3, 3]
            res.append(((y - ms.marker_points[m][rows]) / self.noise.position_m).ravel())
            if jacobian:
                J = chain(T, y, mk.frame, rows, False)
                if m in self.marker_slot:
                    i = self.marker_slot[m]
                    J[:, :, i:i + 3] += T[:, :3, :3]
                jac.append(J.reshape(-1, n) / self.noise.position_m)
        for f in self.pose_frames:
            rows = np.flatnonzero(ms.has_pose(f))
            T = model.fk(q[rows], [f])[f]
            Tm = ms.poses[f][rows]
            y = T[:, :3, 3]
            res.append(((y - Tm[:, :3, 3]) / self.noise.position_m).ravel())
            dr = Rotation.from_matrix(T[:, :3, :3] @ np.transpose(Tm[:, :3, :3], (0, 2, 1))).as_rotvec()
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

    def rows_of_kind(self) -> tuple[int, int]:
        """How many residual rows are position and rotation measurements."""
        pos = 3 * sum(int(self.ms.has_marker(m).sum()) for m in self.markers)
        pos += 3 * sum(int(self.ms.has_pose(f).sum()) for f in self.pose_frames)
        rot = 3 * sum(int(self.ms.has_pose(f).sum()) for f in self.pose_frames)
        return pos, rot


def _initial(problem: _Problem) -> Array:
    """A start: the measuring frame, measured frames and markers placed on the nominal model by
    alternating a rigid registration with their own least-squares placement."""
    ms, nom = problem.ms, problem.nominal
    x = np.zeros(len(problem.names))
    base = {f: nom.fk(ms.q, [f])[f] for f in problem.upstream}
    W_inv = inverse(nom.T_world_base())
    base = {f: W_inv @ T for f, T in base.items()}  # T_base_frame
    C = {f: np.eye(4) for f in problem.pose_frames}  # measured frame correction on its link
    p = {m: (np.zeros(3) if m in problem.marker_slot else problem.marker_position(x, m)) for m in problem.markers}
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
        W = transforms_from_point_pairs(np.vstack(P), np.vstack(Y), what=f"{ms.source}: measured points")
        Wi = inverse(W)
        for m in problem.unknown:
            rows = ms.has_marker(m)
            T = base[ms.markers[m].frame][rows]
            y_b = ms.marker_points[m][rows] @ Wi[:3, :3].T + Wi[:3, 3]
            p[m] = np.einsum("nji,nj->ni", T[:, :3, :3], y_b - T[:, :3, 3]).mean(0)
        for f in problem.unknown_mounts:
            rows = ms.has_pose(f)
            D = np.linalg.solve(base[f][rows], Wi @ ms.poses[f][rows])  # T_frame_measured, per record
            R = Rotation.from_matrix(D[:, :3, :3]).mean().as_matrix()
            C[f] = homogeneous(R, D[:, :3, 3].mean(0))
    x[:6] = _xi_of(W_inv @ W)
    for f in problem.pose_frames:
        first, _ = problem.slots["frame:" + f]
        x[first:first + 6] = _xi_of(C[f])
    for m in problem.unknown:
        i = problem.marker_slot[m]
        x[i:i + 3] = p[m]
    return x


def _xi_of(P: Array) -> Array:
    """The inverse of :func:`perturbation`."""
    return np.concatenate([P[:3, 3], Rotation.from_matrix(P[:3, :3]).as_rotvec()])


def _solve(problem: _Problem, x0: Array) -> Array:
    sol = least_squares(lambda x: problem.evaluate(x, False)[0], x0,
                        jac=lambda x: problem.evaluate(x, True)[1], method="lm", xtol=1e-12, ftol=1e-12)
    return np.asarray(sol.x)


def fit_map(nominal: CPCModel, ms: MeasurementSet, level: str = "geometry", joints: Sequence[str] | None = None,
            tolerances: Tolerances | None = None, noise: Noise | None = None, *,
            estimate_noise: bool = True, loads: Array | None = None) -> MapFit:
    """Fit one level about ``nominal`` (module docstring).

    Args:
        nominal: The user's model (a URDF robot's nominal model): the prior's centre.
        ms: Marker points and/or measured frame poses with joint readings.
        level: One of :data:`LEVELS`.
        joints: Joints to calibrate (default :func:`default_joints`); every other joint keeps the
            nominal constants exactly.
        tolerances: The prior (default :class:`Tolerances`).
        noise: The measurement noise; with ``estimate_noise`` only its start.
        estimate_noise: Re-estimate the noise from the residuals (degrees of freedom counted by
            the hat matrix) and refit until it settles.

    Raises:
        DegenerateDataError: No measured point or frame.
    """
    if level not in LEVELS:
        raise ValueError(f"unknown level {level!r}; known: {', '.join(LEVELS)}")
    tol = tolerances or Tolerances()
    nz = noise or Noise()
    js = tuple(joints) if joints is not None else default_joints(ms)
    problem = _Problem(nominal, ms, level, js, tol, nz, loads)
    if not problem.markers and not problem.pose_frames:
        raise DegenerateDataError(f"{ms.source}: no measured point or frame pose to calibrate from")
    x = _solve(problem, _initial(problem))
    for _ in range(NOISE_ITERATIONS if estimate_noise else 0):
        new = _estimate_noise(problem, x)
        if abs(new.position_m / problem.noise.position_m - 1) < 0.01 and \
                abs(new.rotation_rad / problem.noise.rotation_rad - 1) < 0.01:
            problem.noise = new
            break
        problem.noise = new
        x = _solve(problem, x)
    return _result(problem, x)


def _hat_traces(problem: _Problem, J: Array) -> tuple[Array, float, float]:
    """Posterior covariance, and the hat matrix's trace over the position and the rotation rows
    (the parameters each kind of measurement used up)."""
    cov = np.linalg.pinv(J.T @ J)
    _, point = problem.row_records()
    Jm = J[:len(point)]
    Jp, Jr = Jm[point], Jm[~point]
    return cov, float(np.sum(cov * (Jp.T @ Jp))), float(np.sum(cov * (Jr.T @ Jr)))


def _estimate_noise(problem: _Problem, x: Array) -> Noise:
    r, J = problem.evaluate(x)
    assert J is not None
    _, hp, hr = _hat_traces(problem, J)
    _, point = problem.row_records()
    rm = r[:len(point)]
    rp, rr = rm[point] * problem.noise.position_m, rm[~point] * problem.noise.rotation_rad
    sp = math.sqrt(float(rp @ rp) / max(len(rp) - hp, 1.0))
    sr = math.sqrt(float(rr @ rr) / max(len(rr) - hr, 1.0)) if len(rr) else problem.noise.rotation_rad
    return Noise(max(sp, NOISE_FLOOR), max(sr, NOISE_FLOOR))


def _result(problem: _Problem, x: Array) -> MapFit:
    r, J = problem.evaluate(x)
    assert J is not None
    cov, hp, hr = _hat_traces(problem, J)
    loo_sq, loo_count, loo_rot, loo_stat, loo_stat_rot, loo_frames = _leave_one_out(problem, r, J, cov)
    model = problem.model(x)
    share: dict[str, float] = {}  # 1 - posterior / prior variance, mean over the joint's free components
    for j in problem.joints:
        if j not in problem.slots:
            continue
        first, comps = problem.slots[j]
        idx = np.arange(first, first + len(comps))
        share[j] = float(np.mean(np.clip(1.0 - np.diag(cov)[idx] / problem.prior[idx] ** 2, 0.0, 1.0)))
    return MapFit(
        model=model,
        level=problem.level,
        joints=problem.joints,
        perturbations={j: problem.xi(x, j) for j in problem.joints if j in problem.slots},
        markers={m: problem.marker_position(x, m).copy() for m in problem.markers},
        noise=problem.noise,
        covariance=cov,
        names=problem.names,
        rms_m=float(np.sqrt(np.mean(np.concatenate(list(point_errors(
            model, problem.ms, {m: problem.marker_position(x, m) for m in problem.markers}, problem.q(x)).values())) ** 2))),
        dof=hp + hr,
        dof_position=hp,
        loo_sq_m2=loo_sq,
        loo_points=loo_count,
        loo_rot_sq=loo_rot,
        loo_stat=loo_stat,
        loo_stat_rot=loo_stat_rot,
        loo_frames=loo_frames,
        residual_noise=_estimate_noise(problem, x),
        data_share=share,
        compliance={j: float(x[i]) for j, i in problem.compliance.items()},
    )


def _leave_one_out(problem: _Problem, r: Array, J: Array, cov: Array) -> tuple[Array, ...]:
    """Per record: the squared distances of its points to the fit made without it, summed [m^2],
    how many points it has, the squared orientation residuals of its frames, summed [rad^2], and
    its studentized statistic ``r_i^T (I - H_ii)^-1 r_i`` over its position rows and over its
    orientation rows (chi-square with as many degrees of freedom as rows, for a good record and
    the right noise), and how many frame poses it has.
    For the linearised problem the left-out residual is exactly ``(I - H_ii)^-1 r_i``, with
    ``H_ii`` the record's block of the hat matrix (the PRESS residuals of a record)."""
    rec, point = problem.row_records()
    scale = np.where(point, problem.noise.position_m, problem.noise.rotation_rad)
    n_rec = problem.ms.n_records
    sq, count, rot = np.zeros(n_rec), np.zeros(n_rec), np.zeros(n_rec)
    stat, stat_rot, frames = np.zeros(n_rec), np.zeros(n_rec), np.zeros(n_rec)
    order = np.argsort(rec, kind="stable")
    sizes = np.bincount(rec, minlength=n_rec)
    k = int(sizes.max())
    if np.all(sizes[sizes > 0] == k):  # every record has the same rows: one batched solve
        full = np.flatnonzero(sizes == k)
        rows = order.reshape(-1, k)
        Jb = J[rows]
        H = Jb @ cov @ np.transpose(Jb, (0, 2, 1))
        e_w = np.linalg.solve(np.eye(k) - H, r[rows][..., None])[..., 0]
        pt = point[rows]
        stat[full] = np.sum(np.where(pt, e_w * r[rows], 0.0), axis=1)
        stat_rot[full] = np.sum(np.where(pt, 0.0, e_w * r[rows]), axis=1)
        frames[full] = (~pt).sum(axis=1) / 3
        e = e_w * scale[rows]
        sq[full] = np.sum(np.where(pt, e, 0.0) ** 2, axis=1)
        rot[full] = np.sum(np.where(pt, 0.0, e) ** 2, axis=1)
        count[full] = pt.sum(axis=1) / 3
        return sq, count, rot, stat, stat_rot, frames
    for i in np.flatnonzero(sizes):
        ri = np.flatnonzero(rec == i)
        Ji = J[ri]
        e_w = np.linalg.solve(np.eye(len(ri)) - Ji @ cov @ Ji.T, r[ri])
        stat[i] = float(e_w[point[ri]] @ r[ri][point[ri]])
        stat_rot[i] = float(e_w[~point[ri]] @ r[ri][~point[ri]])
        frames[i] = (~point[ri]).sum() / 3
        e = e_w * scale[ri]
        sq[i] = float(np.sum(e[point[ri]] ** 2))
        rot[i] = float(np.sum(e[~point[ri]] ** 2))
        count[i] = point[ri].sum() / 3
    return sq, count, rot, stat, stat_rot, frames


def point_errors(model: CPCModel, ms: MeasurementSet, markers: dict[str, Array],
                 q: Array | None = None) -> dict[str, Array]:
    """Distance [m] from each measured point (marker, or measured frame's origin) to the model's
    prediction at readings ``q`` (default ``ms.q``), per marker / frame, over the records that
    measured it."""
    q = ms.q if q is None else q
    out: dict[str, Array] = {}
    for m, p in markers.items():
        if m not in ms.marker_points:
            continue
        rows = ms.has_marker(m)
        T = model.fk(q[rows], [ms.markers[m].frame])[ms.markers[m].frame]
        out[m] = np.linalg.norm(T[:, :3, :3] @ p + T[:, :3, 3] - ms.marker_points[m][rows], axis=1)
    for f in ms.frames:
        rows = ms.has_pose(f)
        T = model.fk(q[rows], [f])[f]
        out[f] = np.linalg.norm(T[:, :3, 3] - ms.poses[f][rows][:, :3, 3], axis=1)
    return out


def first_point(fit: MapFit, ms: MeasurementSet, q: Array) -> Array:
    """World prediction [m] of the first measured point (marker, else frame origin) of ``ms`` at
    readings ``q`` (N, n) with the geometry alone (no deflection), shape (N, 3)."""
    if fit.markers:
        m = next(iter(fit.markers))
        frame = ms.markers[m].frame
        T = fit.model.fk(q, [frame])[frame]
        return T[:, :3, :3] @ fit.markers[m] + T[:, :3, 3]
    return fit.model.fk(q, [ms.frames[0]])[ms.frames[0]][:, :3, 3]


def folds(n: int, k: int = CV_FOLDS, seed: int = 0) -> list[Array]:
    """The records of each fold: ``array_split`` of a seeded permutation."""
    return list(np.array_split(np.random.default_rng(seed).permutation(n), k))


def cross_validate(ms: MeasurementSet, fit: Callable[[MeasurementSet, Array | None], MapFit],
                   loads: Array | None = None, k: int = CV_FOLDS) -> Array:
    """Every held-out distance [m] of ``k``-fold cross-validation: each fold's records predicted by
    ``fit(training records, their loads)``."""
    errs: list[Array] = []
    for test in folds(ms.n_records, k):
        train = np.setdiff1d(np.arange(ms.n_records), test)
        f = fit(ms.subset(train), None if loads is None else loads[train])
        held = ms.subset(test)
        q = f.deflected(held.q, None if loads is None else loads[test])
        errs += list(point_errors(f.model, held, f.markers, q).values())
    return np.concatenate(errs)


@dataclass(frozen=True, eq=False)
class Selection:
    """The model chosen among the levels, and why.

    Attributes:
        fit: The chosen level's fit on every record.
        fits: Every level's fit, by level (``compliance`` only with loads).
        chosen: The chosen level.
    """

    fit: MapFit
    fits: dict[str, MapFit]

    @property
    def chosen(self) -> str:
        return self.fit.level

    @property
    def beats_urdf(self) -> bool:
        """False when the URDF as it is (``frames``) predicts held-out records at least as well."""
        return self.chosen != "frames"


def select_model(nominal: CPCModel, ms: MeasurementSet, joints: Sequence[str] | None = None,
                 tolerances: Tolerances | None = None, loads: Array | None = None,
                 margin: float = SELECTION_MARGIN, noise: Noise | None = None) -> Selection:
    """Fit every level and keep the one that predicts left-out records best.

    Each level is scored by its leave-one-record-out residuals (:attr:`MapFit.loo_sq_m2`, and for
    frame poses their orientations too, :attr:`MapFit.loo_rot_sq`, weighed by the URDF-as-is
    fit's position / orientation noise so that both count on one scale). The default is
    ``geometry``: its prior already keeps what the data barely see at the URDF's values. A level
    that departs from it (compliance added, or offsets alone) must lower the RMS of that score by
    more than ``margin`` (a fraction; few records cannot tell small differences apart), and the
    URDF as it is (``frames``) is kept whenever it scores no worse than the level chosen. A stated
    ``noise`` is used as it is; without one the noise is estimated.
    """
    levels = [lv for lv in LEVELS if lv != "compliance" or loads is not None]
    fits = {lv: fit_map(nominal, ms, lv, joints, tolerances, noise, estimate_noise=noise is None, loads=loads)
            for lv in levels}
    base = fits["frames"].noise
    weight = (base.position_m / base.rotation_rad) ** 2 if ms.frames else 0.0  # [m^2 / rad^2]

    def score(f: MapFit) -> float:
        return float(f.loo_sq_m2.sum() + weight * f.loo_rot_sq.sum())

    best = fits["geometry"]
    for lv in ("compliance", "offsets"):
        if lv in fits and score(fits[lv]) < (1.0 - margin) ** 2 * score(best):
            best = fits[lv]
    if score(fits["frames"]) <= score(best):
        best = fits["frames"]
    return Selection(best, fits)


__all__ = [
    "LEVELS",
    "MapFit",
    "Noise",
    "Tolerances",
    "cross_validate",
    "default_joints",
    "fit_map",
    "folds",
    "perturbation",
    "first_point",
    "point_errors",
    "select_model",
    "Selection",
]
