"""Gaze control: joint values that point both cameras' optical axes at a 3D target.

A target ``p_world`` [m] is *fixated* when the optical (z) axis of each camera frame passes
through it, in front of the camera. The solver works on the Pinocchio model of a URDF (nominal
or calibrated head alike): it never assumes orthogonal axes or cameras on their axes.

Method (one :meth:`GazeSolver.solve` call):

1. **Initial guess.** The table (prismatic joints shared by both cameras) stays at its reading.
   Neck (revolute joints shared by both cameras) from a grid computed once from the model: the
   entry whose cyclopean ray (midpoint of the camera centres, along the sum of the optical axes)
   best faces the target, refined to first order in pan and tilt (2 x 2 normal equations on
   precomputed ray derivatives; cyclopean policy on a redundant head only); the eyes converge
   symmetrically by ``asin(baseline / 2 / distance)``.
   ``min-motion`` and ``eyes-only`` start from ``q_current``; :meth:`GazeSolver.track` from the
   previous solution.
2. **Task-priority Gauss-Newton with joint limits as constraints.** Priority 1 is fixation: per
   eye the residual ``u - e_z`` with ``u`` the unit target direction in the camera frame (zero only
   when the camera looks *at*, not away from, the target; its norm is ``2 sin(err/2)``). Its
   Jacobian comes from Pinocchio's LOCAL frame Jacobians: ``dp_cam = -v - w x p_cam`` (computed
   only for configurations a step starts from). Steps are
   Levenberg-Marquardt damped with ``mu = |r|^2`` and halved while they increase the residual.
   Priority 2, the redundancy policy (below), moves only in the null space of priority 1.
   Joint limits: a joint that a step would push past its limit is first kept still by trading
   its motion for null-space motion; if fixation itself needs it beyond, it is held at the limit
   (active set) and the step is re-solved over the others; it is released when the gradient pulls
   it back inside.
3. **Fixation alone.** If that does not fixate (the policy held a weak direction fixation
   needed, or a limit blocked the preferred configuration), the same iteration runs on priority 1
   alone, with a watchdog that accepts a long step followed by one correction when the pair
   lowers the residual. If it ends in a local minimum, up to :data:`RETRIES` further starts with
   the eyes already turned are tried, and the best result is kept.
4. **Answer.** ``reachable`` is True when both eyes point at the target to within
   :data:`cpc2urdf.tolerances.GAZE_POINTING_TOL` (which implies in front of the cameras), inside
   the limits. Otherwise the readings are the best in-limit configuration found (least sum of the
   squared residuals of the two eyes), with the residuals, and ``status`` says why.

Redundancy policies (the secondary task):

- ``"cyclopean"`` (default): the table stays where it is; neck and eyes move; among the
  fixating configurations the one with zero *version* (the eyes turned equally and oppositely
  from their home readings, the middle of their limits), so the cyclopean axis faces the target
  and the eyes converge symmetrically on it.
- ``"min-motion"``: the table stays; the fixating configuration nearest ``q_current`` (Euclidean
  in the readings of neck and eyes, [rad]).
- ``"eyes-only"``: only the eye joints move (head and table still); reachable only if the target
  happens to lie where the eyes alone can converge.
- ``"use-table"``: every joint may move; zero version, the cyclopean point (midpoint of the camera
  centres) at ``viewing_distance`` [m] from the target, and the least table motion.

On a head whose two eyes turn about one common axis (the IIS-head), the nominal model fixates a
target with one degree of freedom to spare (pan vs version). A calibrated model whose eyes do not
sweep exactly the same plane has none: binocular fixation with the table fixed is then a square
problem with isolated solutions (or none), and the policy only chooses the starting point. The
solver reports that honestly through ``reachable``/``status`` instead of clamping.

Frames: ``T_world_x`` is the pose of ``x`` in ``world``; points carry their frame (``p_world``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError, SpecError, UnknownNameError
from cpc2urdf.tolerances import GAZE_POINTING_TOL

if TYPE_CHECKING:
    from cpc2urdf.model import CPCModel

Array = NDArray[np.float64]
Index = NDArray[np.intp]  # joint indices into q

POLICIES: tuple[str, ...] = ("cyclopean", "min-motion", "eyes-only", "use-table")
DEFAULT_CAMERAS = ("camera_left_optical", "camera_right_optical")
DEFAULT_VIEWING_DISTANCE = 0.6  # [m]: use-table policy, cyclopean point to target

# Solver settings.
MAX_ITERATIONS = 60
MAX_STEP = 0.5  # [rad] or [m]: the largest joint change of one Gauss-Newton step
NULL_EIGENVALUE = 1e-14  # [-]: eigenvalues of J1^T J1 below this span the fixation null space
BACKTRACKS = 8  # step halvings allowed per iteration
TABLE_TIE_WEIGHT = 1e-4  # [1/m]: use-table, least table motion vs the viewing distance
GUESS_MAX_CORRECTION = 0.2  # [rad]: largest first-order correction of the grid's neck readings
RETRIES = 2  # further starts tried when the first one ends in a local minimum
MIN_TARGET_DISTANCE = 1e-9  # [m]: a target this close to a camera centre cannot be pointed at
STALL_RESIDUAL = 1e-12  # [-]: fixation alone stops when |r1|^2 above this falls < 5 % in 3 steps
PHASE2_DAMPING = 1e-4  # [-]: Levenberg-Marquardt damping factor (x |r1|^2) when solving fixation alone
CONVERGED_RESIDUAL = 1e-30  # [-]: |u_L - e_z|^2 + |u_R - e_z|^2 below which fixation is exact
FLOOR_RESIDUAL = 1e-22  # [-]: ... or below this once steps stop (pointing error ~1e-11 rad)
CONVERGED_STEP = 1e-11  # [rad] or [m]: ... and the policy step is this small
_PRISMATIC = ("PX", "PY", "PZ", "PrismaticUnaligned")
_REVOLUTE = ("RX", "RY", "RZ", "RevoluteUnaligned")

STATUS_FIXATED = "fixated"
STATUS_LIMITS = "joint_limits"  # the best in-limit configuration does not fixate; a joint is at a limit
STATUS_BEHIND = "behind"  # an eye would have to look away from the target
STATUS_TOO_CLOSE = "too_close"  # the target is closer to the cameras than their baseline
STATUS_NO_SOLUTION = "no_solution"  # no limit active, yet the two eyes cannot both fixate
STATUSES = (STATUS_FIXATED, STATUS_LIMITS, STATUS_BEHIND, STATUS_TOO_CLOSE, STATUS_NO_SOLUTION)


@dataclass(frozen=True)
class GazeSolution:
    """The answer of :meth:`GazeSolver.solve`. Nothing is moved.

    Attributes:
        q: Joint readings [rad]/[m], shape (n,), in ``joint_names`` order; always inside the limits.
        joint_names: Names of the joints, in the order of ``q``.
        reachable: True if both eyes fixate the target (see module docstring).
        status: One of :data:`STATUSES`: ``"fixated"`` or why not.
        pointing_error: Angle between each optical axis and the direction to the target [rad],
            shape (2,) (left, right).
        miss_distance: Distance from the target to each optical ray (half-line in front of the
            camera) [m], shape (2,).
        fixation_point: Midpoint of the closest points of the two optical axes (world) [m],
            shape (3,), or None when the axes are parallel.
        vergence: Angle between the two optical axes [rad].
        at_limit: Names of the joints at one of their limits.
        iterations: Gauss-Newton iterations used.
        policy: The redundancy policy used.
        target: The target (world) [m], shape (3,).
    """

    q: Array
    joint_names: tuple[str, ...]
    reachable: bool
    status: str
    pointing_error: Array
    miss_distance: Array
    fixation_point: Array | None
    vergence: float
    at_limit: tuple[str, ...]
    iterations: int
    policy: str
    target: Array

    @property
    def joints(self) -> dict[str, float]:
        """``{joint name: reading}`` [rad]/[m]."""
        return {n: float(v) for n, v in zip(self.joint_names, self.q, strict=True)}

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (SI units)."""
        return {
            "target": self.target.tolist(),
            "policy": self.policy,
            "reachable": self.reachable,
            "status": self.status,
            "joints": self.joints,
            "pointing_error_rad": {"left": float(self.pointing_error[0]), "right": float(self.pointing_error[1])},
            "miss_distance_m": {"left": float(self.miss_distance[0]), "right": float(self.miss_distance[1])},
            "fixation_point": None if self.fixation_point is None else self.fixation_point.tolist(),
            "vergence_rad": self.vergence,
            "at_limit": list(self.at_limit),
            "iterations": self.iterations,
        }


@dataclass(frozen=True)
class Trajectory:
    """The result of :meth:`GazeSolver.track`.

    Attributes:
        t: Sample times [s], shape (T,).
        q: Commanded joint readings [rad]/[m], shape (T, n): velocity-limited steps towards
            ``q_goal``.
        q_goal: The solved (warm-started) fixating readings per sample, shape (T, n).
        reachable: Whether each target could be fixated, shape (T,).
        pointing_error: Per-sample pointing error of the *commanded* ``q``, shape (T, 2) [rad].
        locked: Per-sample flag: the commanded ``q`` equals the goal (not velocity-limited), shape (T,).
        joint_names: Names of the joints, in the order of the columns of ``q``.
    """

    t: Array
    q: Array
    q_goal: Array
    reachable: NDArray[np.bool_]
    pointing_error: Array
    locked: NDArray[np.bool_]
    joint_names: tuple[str, ...]


@dataclass
class _Eye:
    frame_id: int
    name: str


@dataclass(slots=True)
class _State:
    """Per-configuration quantities of both eyes (computed by :meth:`GazeSolver._evaluate`).

    The 3-vectors are plain float lists: the solver's hot path does its 3-vector algebra in
    Python floats, which is several times cheaper than numpy calls on arrays this small. The
    Jacobian is computed when first asked for: the last configuration of a solve (and every
    backtracking trial) only needs the residual.
    """

    solver: GazeSolver
    q: Array  # (n,) the readings [rad]/[m]
    r: Array  # (6,) fixation residual, [u_L - e_z, u_R - e_z]
    rr: float  # |r|^2
    origins: list[list[float]]  # 2 x 3: camera centres (world) [m]
    axes: list[list[float]]  # 2 x 3: optical axes (world)
    p_cam: list[tuple[float, float, float]]  # 2 x 3: target in each camera frame [m]
    u: list[tuple[float, float, float, float]]  # 2 x 4: unit target direction (camera) and 1 / |p_cam|
    jacobian: Array | None = None
    Jo: list[Array] | None = None  # use-table: the (3, n) world Jacobians of the camera centres

    @property
    def J(self) -> Array:
        """(6, n) Jacobian of ``r`` by the readings."""
        if self.jacobian is None:
            self.jacobian = self.solver._jacobian(self)
        return self.jacobian


def target_point(p_world: ArrayLike) -> Array:
    """A gaze target as a finite point of shape (3,) [m], or :class:`ConfigurationError` saying
    what is wrong (the solver and the view check targets the same way)."""
    try:
        p = np.asarray(p_world, dtype=float)
    except (TypeError, ValueError) as e:
        raise ConfigurationError(f"target must be three numbers x y z [m], got {p_world!r}") from e
    if p.shape != (3,):
        raise ConfigurationError(f"target must be three numbers x y z [m], got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ConfigurationError(f"target must be finite, got {p.tolist()}")
    return p


class GazeSolver:
    """Gaze inverse kinematics on the Pinocchio model of a URDF.

    Args:
        urdf: URDF text or the path of a ``.urdf`` file.
        cameras: Names of the left and right camera optical frames (z along the optical axis).
        viewing_distance: Preferred distance [m] from the cyclopean point to the target for the
            ``"use-table"`` policy.

    Raises:
        UnknownNameError: a camera frame the URDF does not have.
        SpecError: the URDF has joints with more than one degree of freedom (continuous,
            floating, planar), or the two cameras share every joint (no eye joints).
    """

    def __init__(
        self,
        urdf: str | Path,
        cameras: Sequence[str] = DEFAULT_CAMERAS,
        *,
        viewing_distance: float = DEFAULT_VIEWING_DISTANCE,
    ) -> None:
        import pinocchio as pin

        self._pin = pin
        from scipy.linalg.lapack import dsyevd

        self._syevd = dsyevd
        text = str(urdf)
        if isinstance(urdf, Path) or not text.lstrip().startswith("<"):  # a path, not XML text
            from cpc2urdf.fileio import read_text_file

            text = read_text_file(Path(text), "a URDF file")
        try:
            model = pin.buildModelFromXML(text)
        except Exception as e:  # Pinocchio raises ValueError/RuntimeError on bad XML
            raise SpecError(f"cannot build a Pinocchio model from the URDF: {e}") from e
        self.model = model
        self.data = model.createData()
        if len(cameras) != 2:
            raise ConfigurationError(f"need exactly two camera frames (left, right), got {list(cameras)}")
        known = [f.name for f in model.frames]
        eyes = []
        for name in cameras:
            if not model.existFrame(name):
                raise UnknownNameError("frame", name, known)
            eyes.append(_Eye(model.getFrameId(name), name))
        self._eyes = eyes
        self._frame_ids = [e.frame_id for e in eyes]
        self.cameras: tuple[str, str] = (cameras[0], cameras[1])

        names: list[str] = []
        kinds: list[str] = []
        for jid in range(1, model.njoints):
            joint = model.joints[jid]
            short = joint.shortname().replace("JointModel", "")
            if joint.nq != 1 or joint.nv != 1 or short not in _PRISMATIC + _REVOLUTE:
                raise SpecError(
                    f"joint {model.names[jid]!r} is {short}; the gaze solver handles only revolute "
                    "and prismatic joints with limits (no continuous, floating or planar joints)"
                )
            if joint.idx_q != jid - 1:
                raise SpecError("unexpected Pinocchio joint ordering")
            names.append(str(model.names[jid]))
            kinds.append("prismatic" if short in _PRISMATIC else "revolute")
        self.joint_names: tuple[str, ...] = tuple(names)
        self.joint_kinds: dict[str, str] = dict(zip(names, kinds, strict=True))
        self.n = len(names)
        self.lower: Array = np.array(model.lowerPositionLimit, dtype=float)
        self.upper: Array = np.array(model.upperPositionLimit, dtype=float)
        self.velocity_limit: Array = np.array(model.velocityLimit, dtype=float)
        if not (np.all(np.isfinite(self.lower)) and np.all(np.isfinite(self.upper))):
            raise SpecError("every joint needs finite <limit lower/upper> for gaze control")
        self.home: Array = 0.5 * (self.lower + self.upper)
        self._lower_list: list[float] = self.lower.tolist()
        self._home_list: list[float] = self.home.tolist()
        self._upper_list: list[float] = self.upper.tolist()

        # Joints on each camera's path: shared ones move the head, the others are the eyes.
        paths: list[set[int]] = []
        for eye in eyes:
            jid = model.frames[eye.frame_id].parentJoint
            chain: set[int] = set()
            while jid > 0:
                chain.add(jid - 1)
                jid = model.parents[jid]
            paths.append(chain)
        shared = paths[0] & paths[1]
        self._table = np.array(sorted(i for i in shared if kinds[i] == "prismatic"), dtype=int)
        self._neck = np.array(sorted(i for i in shared if kinds[i] == "revolute"), dtype=int)
        self._eye_joints = [np.array(sorted(p - shared), dtype=int) for p in paths]
        if any(len(e) == 0 for e in self._eye_joints):
            raise SpecError(f"cameras {list(self.cameras)} share all their joints: nothing can verge")
        self._eyes_all = np.concatenate(self._eye_joints)
        self.viewing_distance = float(viewing_distance)
        self._version_sign = self._eye_version_sign()
        # version = (eye_L - home_L) + s (eye_R - home_R), first eye joint of each side
        self._version_row = np.zeros(self.n)
        self._version_row[self._eye_joints[0][0]] = 1.0
        self._version_row[self._eye_joints[1][0]] = self._version_sign
        self._version_row_list: list[float] = self._version_row.tolist()
        self._build_guess_table()
        self.redundant = self._fixation_is_redundant()
        self._free_joints = {policy: self._free(policy) for policy in POLICIES}
        self._fixed_joints = {policy: np.setdiff1d(np.arange(self.n), free) for policy, free in self._free_joints.items()}

    # ---- construction helpers -------------------------------------------------------------------

    @classmethod
    def from_model(cls, model: CPCModel, cameras: Sequence[str] = DEFAULT_CAMERAS, **kwargs: Any) -> GazeSolver:
        """A solver for a :class:`cpc2urdf.model.CPCModel` (via its URDF)."""
        from cpc2urdf.urdf import urdf_from_model

        for name in cameras:
            model.structure.frame(name)  # UnknownNameError with the model's frame names
        return cls(urdf_from_model(model), cameras, **kwargs)

    def _eye_version_sign(self) -> float:
        """+1 if the first eye joints of both eyes turn about (nearly) the same world direction."""
        pin = self._pin
        pin.computeJointJacobians(self.model, self.data, self.home)
        # The world Jacobian's angular column of a revolute joint is its axis direction.
        J = pin.getJointJacobian(self.model, self.data, int(self._eye_joints[0][0]) + 1, pin.WORLD)
        a0 = J[3:, self._eye_joints[0][0]]
        J = pin.getJointJacobian(self.model, self.data, int(self._eye_joints[1][0]) + 1, pin.WORLD)
        a1 = J[3:, self._eye_joints[1][0]]
        return 1.0 if float(a0 @ a1) >= 0.0 else -1.0

    def _fixation_is_redundant(self) -> bool:
        """Whether fixation by neck and eyes leaves an exact null space (e.g. the nominal IIS-head).

        Tested at a converging home posture on the closest point of the two optical axes.
        A calibrated head whose eyes do not sweep one plane has none: the redundancy policy
        then has no freedom, and :meth:`solve` goes straight to solving fixation alone.
        """
        q = self.home.copy()
        e0, e1 = int(self._eye_joints[0][0]), int(self._eye_joints[1][0])
        self._converge_sign = 1.0
        for delta in (0.1, -0.1):
            q[e0] = np.clip(self.home[e0] - delta, self.lower[e0], self.upper[e0])
            q[e1] = np.clip(self.home[e1] + self._version_sign * delta, self.lower[e1], self.upper[e1])
            self._pin.framesForwardKinematics(self.model, self.data, q)
            o = np.array([self.data.oMf[e.frame_id].translation for e in self._eyes])
            z = np.array([self.data.oMf[e.frame_id].rotation[:, 2] for e in self._eyes])
            p = _closest_point(o.tolist(), z.tolist())
            if p is None:
                continue
            st = self._evaluate(q, p)
            free = self._free("cyclopean")
            J = st.J[:, free]
            if np.all((p - o[0]) @ z[0] > 0) and (p - o[1]) @ z[1] > 0:
                self._converge_sign = 1.0 if delta > 0 else -1.0  # eyes converge for +delta
                return bool(np.linalg.eigvalsh(J.T @ J)[0] <= NULL_EIGENVALUE)
        return False

    def _build_guess_table(self) -> None:
        """Cyclopean rays over a grid of neck readings, in the frame of the last table link.

        The table only translates the head, so rays expressed in the table link frame do not
        depend on the table readings.
        """
        pin = self._pin
        # interior grid points only: a start on a limit would hold that joint from the outset
        grids = [
            np.linspace(self.lower[i], self.upper[i], (37 if k == 0 else 13) + 2)[1:-1] for k, i in enumerate(self._neck)
        ]
        if grids:
            mesh = np.stack(np.meshgrid(*grids, indexing="ij"), -1).reshape(-1, len(grids))
        else:
            mesh = np.zeros((1, 0))
        self._table_link = int(max(self._table)) + 1 if len(self._table) else 0
        origins, dirs, qs = [], [], []
        e0, e1 = int(self._eye_joints[0][0]), int(self._eye_joints[1][0])
        # version 0 first (the default starts), then turned eyes (retries near the neck limits)
        versions = [0.0, -0.3, 0.3, -0.6, 0.6]
        rows = [(row, v) for v in versions for row in mesh]
        self._n_version0 = len(mesh)
        for row, v in rows:
            q = self.home.copy()
            q[self._neck] = row
            q[e0] = np.clip(self.home[e0] + v, self.lower[e0], self.upper[e0])
            q[e1] = np.clip(self.home[e1] + self._version_sign * v, self.lower[e1], self.upper[e1])
            c, d = self._cyclopean_ray(q)
            origins.append(c)
            dirs.append(d)
            qs.append(q)
        # Derivatives of the version-0 rays by the neck readings (central differences), for the
        # first-order refinement of the best grid entry in _guess: columns per neck joint.
        h = 1e-6
        dc_rows, dd_rows = [], []
        for q in qs[: self._n_version0]:
            dc, dd = [], []
            for i in self._neck:
                qp, qm = q.copy(), q.copy()
                qp[i] += h
                qm[i] -= h
                (cp, dp), (cm, dm) = self._cyclopean_ray(qp), self._cyclopean_ray(qm)
                dc.append(((cp - cm) / (2 * h)).tolist())
                dd.append(((dp - dm) / (2 * h)).tolist())
            dc_rows.append(dc)
            dd_rows.append(dd)
        self._guess_dc: list[list[list[float]]] = dc_rows
        self._guess_dd: list[list[list[float]]] = dd_rows
        self._guess_dir_list: list[list[float]] = [d.tolist() for d in dirs]
        self._guess_origin = np.array(origins)
        self._guess_dir = np.array(dirs)
        self._guess_q = np.array(qs)
        # per-grid constants of _guess
        self._guess_od = np.einsum("ij,ij->i", self._guess_origin, self._guess_dir)
        self._guess_oo = np.einsum("ij,ij->i", self._guess_origin, self._guess_origin)
        self._guess_origin_list: list[list[float]] = self._guess_origin.tolist()
        m = self._n_version0
        self._guess_affine = np.ascontiguousarray(
            np.vstack([
                np.hstack([self._guess_dir[:m], -self._guess_od[:m, None]]),  # v.d
                np.hstack([-2.0 * self._guess_origin[:m], self._guess_oo[:m, None]]),  # |v|^2 - |p_t|^2
            ])
        )
        self._e0, self._e1 = e0, e1
        self._table_key: bytes | None = None
        chain, jid = [], self._table_link
        while jid > 0:
            chain.append(jid - 1)
            jid = self.model.parents[jid]
        self._table_chain = np.array(sorted(chain), dtype=int)
        self._table_pose: Any = None
        q = self.home
        pin.framesForwardKinematics(self.model, self.data, q)
        o0 = self.data.oMf[self._eyes[0].frame_id].translation
        o1 = self.data.oMf[self._eyes[1].frame_id].translation
        self.baseline = float(np.linalg.norm(o0 - o1))

    def _cyclopean_ray(self, q: Array) -> tuple[Array, Array]:
        """Cyclopean point (midpoint of the camera centres) and unit direction (sum of the optical
        axes) at readings ``q``, in the frame of the last table link, each (3,)."""
        self._pin.framesForwardKinematics(self.model, self.data, q)
        T_world_table = self.data.oMi[self._table_link]
        o = [T_world_table.actInv(self.data.oMf[e.frame_id].translation) for e in self._eyes]
        z = [T_world_table.rotation.T @ self.data.oMf[e.frame_id].rotation[:, 2] for e in self._eyes]
        d = z[0] + z[1]
        return 0.5 * (o[0] + o[1]), d / np.linalg.norm(d)

    # ---- evaluation ---------------------------------------------------------------------------

    def _evaluate(self, q: Array, p: Array, jacobian: bool = True) -> _State:
        """Residual state at readings ``q`` for target ``p``; its Jacobian now or when first used."""
        self._pin.framesForwardKinematics(self.model, self.data, q)
        px, py, pz = p.tolist()
        oMf = self.data.oMf
        res: list[float] = []
        origins, axes, p_cam, us = [], [], [], []
        rr = 0.0
        for fid in self._frame_ids:
            (r00, r01, r02, ox), (r10, r11, r12, oy), (r20, r21, r22, oz), _ = oMf[fid].homogeneous.tolist()
            # the target in the camera frame: R^T (p - o)
            dx, dy, dz = px - ox, py - oy, pz - oz
            x = r00 * dx + r10 * dy + r20 * dz
            y = r01 * dx + r11 * dy + r21 * dz
            z = r02 * dx + r12 * dy + r22 * dz
            nrm = math.sqrt(x * x + y * y + z * z) or 1e-300  # target on a camera centre: see _answer
            inv = 1.0 / nrm
            ux, uy, uz = x * inv, y * inv, z * inv
            res += (ux, uy, uz - 1.0)
            rr += ux * ux + uy * uy + (uz - 1.0) * (uz - 1.0)
            origins.append([ox, oy, oz])
            axes.append([r02, r12, r22])
            p_cam.append((x, y, z))
            us.append((ux, uy, uz, inv))
        st = _State(self, q.copy(), np.array(res), rr, origins, axes, p_cam, us)
        if jacobian:
            st.J  # noqa: B018 (computed now, while q is the caller's)
        return st

    def _jacobian(self, st: _State) -> Array:
        """(6, n) Jacobian of the fixation residual at ``st.q``, from Pinocchio's LOCAL frame Jacobians."""
        pin = self._pin
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, st.q)
        pin.updateFramePlacements(model, data)
        blocks = []
        for fid, (ux, uy, uz, inv) in zip(self._frame_ids, st.u, strict=True):
            # d p_cam = -v - w x p_cam = [-I | [p_cam]x] (v; w), the LOCAL twist of the camera;
            # d u = P d p_cam with P = (I - u u^T) / |p_cam|: one (3, 6) matrix times the frame
            # Jacobian, [-P | P [p_cam]x], where P [p_cam]x = [u]x (as u^T [u]x = 0).
            wx, wy, wz = ux * inv, uy * inv, uz * inv
            M = [
                [ux * wx - inv, ux * wy, ux * wz, 0.0, -uz, uy],
                [uy * wx, uy * wy - inv, uy * wz, uz, 0.0, -ux],
                [uz * wx, uz * wy, uz * wz - inv, -uy, ux, 0.0],
            ]
            blocks.append(np.array(M) @ pin.getFrameJacobian(model, data, fid, pin.LOCAL))
        return np.concatenate(blocks)

    # ---- policy (priority 2) --------------------------------------------------------------------

    def _free(self, policy: str) -> Index:
        if policy == "eyes-only":
            return self._eyes_all
        if policy == "use-table":
            return np.arange(self.n)
        return np.sort(np.concatenate([self._neck, self._eyes_all]))

    def _secondary(self, policy: str, q: Array, q_ref: Array, p: Array, st: _State) -> tuple[Array, Array]:
        """Residual (k,) and Jacobian (k, n) of the policy's secondary task."""
        n = self.n
        rows: list[Array] = []
        res: list[float] = []
        if policy in ("cyclopean", "use-table"):
            # version: (eye_L - home_L) + s (eye_R - home_R) = 0, first eye joint of each side
            row = self._version_row
            if policy == "cyclopean":
                return np.array([float(row @ (q - self.home))]), row[None, :]
            rows.append(row)
            res.append(float(row @ (q - self.home)))
        if policy == "use-table":
            # cyclopean point at the viewing distance: d|c - p|/dq through the table's translation
            c = 0.5 * (np.array(st.origins[0]) + np.array(st.origins[1]))
            d = c - p
            dist = float(np.linalg.norm(d))
            row = np.zeros(n)
            assert st.Jo is not None  # set by _iterate for this policy
            Jc = 0.5 * (st.Jo[0] + st.Jo[1])
            row[:] = (d / max(dist, 1e-12)) @ Jc
            rows.append(row)
            res.append(dist - self.viewing_distance)
            for i in self._table:  # then the least table motion: a tie-breaker, tiny weight
                row = np.zeros(n)
                row[i] = TABLE_TIE_WEIGHT
                rows.append(row)
                res.append(TABLE_TIE_WEIGHT * float(q[i] - q_ref[i]))
        if policy == "min-motion":
            for i in self._free(policy):
                row = np.zeros(n)
                row[i] = 1.0
                rows.append(row)
                res.append(float(q[i] - q_ref[i]))
        if not rows:
            return np.zeros(0), np.zeros((0, n))
        return np.array(res), np.array(rows)

    # ---- the solve ----------------------------------------------------------------------------

    def _check_target(self, p_world: ArrayLike) -> Array:
        return target_point(p_world)

    def _check_q(self, q: ArrayLike | Mapping[str, float] | None) -> Array | None:
        if q is None:
            return None
        if isinstance(q, Mapping):
            unknown = set(q) - set(self.joint_names)
            if unknown:
                raise UnknownNameError("joint", sorted(unknown)[0], self.joint_names)
            missing = [n for n in self.joint_names if n not in q]
            if missing:
                raise ConfigurationError(f"q_current lacks joints {missing}")
            q = [q[n] for n in self.joint_names]
        try:
            qa = np.asarray(q, dtype=float)
        except (TypeError, ValueError) as e:
            raise ConfigurationError(f"q_current must be {self.n} numbers, got {q!r}") from e
        if qa.shape != (self.n,):
            raise ConfigurationError(
                f"q_current must have shape ({self.n},) for joints {list(self.joint_names)}, got shape {qa.shape}"
            )
        if not np.all(np.isfinite(qa)):
            raise ConfigurationError(f"q_current must be finite, got {qa.tolist()}")
        tol = 1e-9
        bad = np.flatnonzero((qa < self.lower - tol) | (qa > self.upper + tol))
        if bad.size:
            i = int(bad[0])
            raise ConfigurationError(
                f"q_current: joint {self.joint_names[i]!r} reading {qa[i]:.9g} outside its limits "
                f"[{self.lower[i]:.9g}, {self.upper[i]:.9g}]"
            )
        return np.clip(qa, self.lower, self.upper)

    def initial_guess(self, p_world: ArrayLike, q_current: ArrayLike | None = None) -> Array:
        """The geometric starting point of :meth:`solve` (table from ``q_current`` or home).

        The neck readings of the precomputed grid whose cyclopean ray passes closest to the
        target (angle seen from the cyclopean point), refined to first order, and the eyes
        converged symmetrically on the target's distance (the default policy's start).
        """
        p = self._check_target(p_world)
        qc = self._check_q(q_current)
        q = (self.home if qc is None else qc).copy()
        return self._guess(p, q, refine=self.redundant)

    def _guess(self, p: Array, q: Array, rank: int = 0, *, refine: bool = True) -> Array:
        """Start: ``rank`` 0 is the version-0 grid entry whose cyclopean ray best faces ``p``,
        its neck readings refined to first order (``refine``, two neck joints) and the eyes
        converged on the target; ``rank`` k >= 1 is the k-th best entry of the whole grid (eyes
        turned too)."""
        if self._table_link:
            key = q[self._table_chain].tobytes()
            if key != self._table_key:  # the table link pose depends only on the joints up to it
                self._pin.forwardKinematics(self.model, self.data, q)
                self._table_pose = self.data.oMi[self._table_link].copy()
                self._table_key = key
            p_t = self._table_pose.actInv(p)
        else:
            p_t = p
        # cos of the angle between each ray (origin o, unit direction d) and v = p_t - o, from
        # per-grid constants: v.d = p_t.d - o.d and |v|^2 = |p_t|^2 - 2 o.p_t + |o|^2
        px, py, pz = p_t.tolist()
        pp = px * px + py * py + pz * pz
        if rank == 0:
            # one matrix-vector product gives v.d and |v|^2 - |p_t|^2 for every version-0 entry;
            # the best ray has the largest cos|cos| = (v.d)|v.d| / |v|^2
            y = self._guess_affine @ np.array([px, py, pz, 1.0])
            m = self._n_version0
            vd = y[:m]
            k = int(np.argmax(vd * np.abs(vd) / np.maximum(y[m:] + pp, 1e-24)))
        else:
            vd = self._guess_dir @ p_t - self._guess_od
            vv = self._guess_oo - 2.0 * (self._guess_origin @ p_t) + pp
            k = int(np.argsort(-(vd / np.sqrt(np.maximum(vv, 1e-24))))[rank - 1])
        best = self._guess_q[k]
        out = q.copy()
        out[self._neck] = best[self._neck]
        out[self._eyes_all] = best[self._eyes_all]
        if rank == 0:
            ox, oy, oz = self._guess_origin_list[k]
            vx, vy, vz = px - ox, py - oy, pz - oz
            dist = math.sqrt(vx * vx + vy * vy + vz * vz)
            if refine and len(self._neck) == 2 and dist > 1e-9:
                # First-order refinement of the grid's neck readings: turn the ray (origin c,
                # direction d, both moving with the neck) onto the target direction t. With
                # t' = -(I - t t^T) c' / dist, solve (d' - t') delta = t - d in least squares
                # (2 x 2 normal equations; d - t is nearly perpendicular to d, so 2 conditions).
                tx, ty, tz = vx / dist, vy / dist, vz / dist
                dx, dy, dz = self._guess_dir_list[k]
                cols = []
                for (cx, cy, cz), (ax, ay, az) in zip(self._guess_dc[k], self._guess_dd[k], strict=True):
                    tc = tx * cx + ty * cy + tz * cz
                    cols.append(
                        (ax + (cx - tc * tx) / dist, ay + (cy - tc * ty) / dist, az + (cz - tc * tz) / dist)
                    )
                (a0, a1, a2), (b0, b1, b2) = cols
                ex, ey, ez = tx - dx, ty - dy, tz - dz
                m00 = a0 * a0 + a1 * a1 + a2 * a2
                m01 = a0 * b0 + a1 * b1 + a2 * b2
                m11 = b0 * b0 + b1 * b1 + b2 * b2
                g0 = a0 * ex + a1 * ey + a2 * ez
                g1 = b0 * ex + b1 * ey + b2 * ez
                det = m00 * m11 - m01 * m01
                if det > 1e-12 * m00 * m11:
                    d0 = (m11 * g0 - m01 * g1) / det
                    d1 = (m00 * g1 - m01 * g0) / det
                    i0, i1 = int(self._neck[0]), int(self._neck[1])
                    n0, n1 = float(out[i0]) + d0, float(out[i1]) + d1
                    # only a small correction, strictly inside the limits (a start on a limit
                    # would hold that joint from the outset); else keep the grid entry
                    if (
                        abs(d0) < GUESS_MAX_CORRECTION
                        and abs(d1) < GUESS_MAX_CORRECTION
                        and self._lower_list[i0] < n0 < self._upper_list[i0]
                        and self._lower_list[i1] < n1 < self._upper_list[i1]
                    ):
                        out[i0], out[i1] = n0, n1
                        (c0x, c0y, c0z), (c1x, c1y, c1z) = self._guess_dc[k]
                        vx -= c0x * d0 + c1x * d1
                        vy -= c0y * d0 + c1y * d1
                        vz -= c0z * d0 + c1z * d1
                        dist = math.sqrt(vx * vx + vy * vy + vz * vz)
            # converge the eyes symmetrically on the target's distance along the ray
            h = math.asin(min(1.0, 0.5 * self.baseline / max(dist, 1e-9))) * self._converge_sign
            e0, e1 = self._e0, self._e1
            out[e0] = min(max(out[e0] - h, self._lower_list[e0]), self._upper_list[e0])
            out[e1] = min(max(out[e1] + self._version_sign * h, self._lower_list[e1]), self._upper_list[e1])
        return out

    def solve(
        self,
        p_world: ArrayLike,
        q_current: ArrayLike | Mapping[str, float] | None = None,
        policy: str = "cyclopean",
        *,
        q_start: ArrayLike | None = None,
        max_iterations: int = MAX_ITERATIONS,
    ) -> GazeSolution:
        """Joint readings that fixate ``p_world`` with both cameras. Moves nothing.

        Args:
            p_world: Target in ``world`` [m], shape (3,).
            q_current: Current readings [rad]/[m], shape (n,) or ``{joint: reading}``; the table
                (and for ``"eyes-only"`` the neck) stays here; ``"min-motion"`` moves least from
                here. None: the middle of every joint's limits.
            policy: One of :data:`POLICIES`.
            q_start: Optional starting point of the iteration (e.g. the previous solution when
                tracking), shape (n,); fixed joints are taken from ``q_current`` regardless.
            max_iterations: Gauss-Newton iteration cap.

        Returns:
            A :class:`GazeSolution`; unreachable targets give ``reachable=False`` with the best
            in-limit readings and the residual, never an exception.

        Raises:
            ConfigurationError: a target or ``q_current`` with NaN/inf or the wrong shape, a
                reading outside the limits, or an unknown policy.
        """
        if policy not in POLICIES:
            raise ConfigurationError(f"unknown gaze policy {policy!r}; expected one of {', '.join(POLICIES)}")
        p = self._check_target(p_world)
        qc = self._check_q(q_current)
        return self._solve(p, qc, policy, q_start, max_iterations)

    def _solve(
        self, p: Array, qc: Array | None, policy: str, q_start: ArrayLike | None, max_iterations: int
    ) -> GazeSolution:
        """:meth:`solve` on a checked target ``p`` and checked in-limit readings ``qc`` (or None)."""
        q_ref = self.home.copy() if qc is None else qc
        free = self._free_joints[policy]
        if q_start is not None:
            q0 = np.clip(np.asarray(q_start, dtype=float).reshape(self.n), self.lower, self.upper)
            fixed = self._fixed_joints[policy]
            q0[fixed] = q_ref[fixed]
        elif policy == "eyes-only":
            q0 = q_ref.copy()
        elif policy == "min-motion" and qc is not None:
            q0 = q_ref.copy()
        else:
            # The refined start saves about one iteration. Only for the cyclopean policy on a
            # redundant head: the use-table and min-motion policies stop once fixation stalls,
            # and need the iterations of a coarser start to move the table or the neck where
            # they want; on a calibrated head it saves nothing (the first step along the weak
            # direction dominates) and loses a few near-fold targets (seeds 2 and 4: 0.5 % and
            # 1.1 % of 1,000 targets).
            q0 = self._guess(p, q_ref, refine=policy == "cyclopean" and self.redundant)
        q, it, st = self._solve_from(p, q0, q_ref, policy, free, max_iterations)
        if st.rr > FLOOR_RESIDUAL and policy != "eyes-only" and q_start is None:
            # Local minimum against a limit (e.g. pan at 0 deg while the eyes would have to
            # turn far): retry from the best grid starts with the eyes already turned.
            for rank in range(1, RETRIES + 1):
                q1, it1, st1 = self._solve_from(p, self._guess(p, q_ref, rank), q_ref, policy, free, max_iterations)
                it += it1
                if st1.rr < st.rr:
                    q, st = q1, st1
                if st.rr <= FLOOR_RESIDUAL:
                    break
        return self._answer(p, q, it, policy, st)

    def _solve_from(
        self, p: Array, q0: Array, q_ref: Array, policy: str, free: Index, max_iterations: int
    ) -> tuple[Array, int, _State]:
        if self.redundant or policy == "use-table":
            q, it, st = self._iterate(p, q0, q_ref, policy, free, max_iterations, secondary=True)
        else:  # the policy has no freedom to choose with: see _fixation_is_redundant
            q, it, st = q0, 0, self._evaluate(q0, p, jacobian=False)
        if st.rr > FLOOR_RESIDUAL and it < max_iterations:
            # Phase 2: fixation alone. Reached when the policy's preferred configuration does
            # not fixate: on a calibrated head (fixation has no spare freedom, only a weak
            # direction the policy was holding) or where a limit blocks the preferred one.
            q, it2, st = self._iterate(p, q, q_ref, policy, free, max_iterations - it, secondary=False, st=st)
            it += it2
        return q, it, st

    def _iterate(
        self,
        p: Array,
        q: Array,
        q_ref: Array,
        policy: str,
        free: Index,
        max_iterations: int,
        *,
        secondary: bool,
        st: _State | None = None,
    ) -> tuple[Array, int, _State]:
        """Task-priority Gauss-Newton with an active set of joints held at their limits.

        With ``secondary=False`` only fixation is solved (with light damping), and the loop
        runs until it converges or stalls; with ``secondary=True`` it also stops when the
        fixation residual stops falling (the policy then holds a direction fixation needs).
        ``st`` is the state at ``q`` when the caller has it already.

        The limit tests run on Python floats (``n`` is small): each numpy call on a 6-vector
        costs about as much as the whole float loop.
        """
        slow = 0
        lo, hi = self.lower, self.upper
        lo_l, hi_l = self._lower_list, self._upper_list
        n = self.n
        q = q.copy()
        held = np.zeros(n, dtype=bool)
        any_held = False
        use_table = policy == "use-table"
        sec_policy = policy if secondary else None
        prev = math.inf
        it = 0
        if st is None:
            st = self._evaluate(q, p, jacobian=False)
        for it in range(1, max_iterations + 1):  # noqa: B007
            if use_table:
                # world Jacobians of the camera centres at q (data may hold another configuration)
                self._pin.computeJointJacobians(self.model, self.data, q)
                self._pin.updateFramePlacements(self.model, self.data)
                st.Jo = [
                    self.data.oMf[e.frame_id].rotation
                    @ self._pin.getFrameJacobian(self.model, self.data, e.frame_id, self._pin.LOCAL)[:3]
                    for e in self._eyes
                ]
            rr = st.rr
            if rr < FLOOR_RESIDUAL and (
                not secondary
                or (policy == "cyclopean" and abs(self._version(q)) < CONVERGED_STEP)
            ):
                break  # fixated, and the policy has nothing left to ask: skip the last step
            q_l = q.tolist()
            if any_held:
                # release held joints whose gradient of |r1|^2 pulls them back inside
                g = st.J.T @ st.r
                held &= ((q <= lo) & (g > 0)) | ((q >= hi) & (g < 0))
                any_held = bool(held.any())
            act = free[~held[free]] if any_held else free
            if act.size == 0:
                break
            block_l = [i for i in range(n) if (q_l[i] <= lo_l[i] or q_l[i] >= hi_l[i]) and not held[i]]
            block = np.array(block_l, dtype=int) if block_l else None
            dq = self._step(sec_policy, q, q_ref, p, st, act, block)
            inside = False  # whether q + dq is known to be inside the limits
            for _ in range(4):
                nq_l = (q + dq).tolist()
                out_l = [i for i in range(n) if nq_l[i] < lo_l[i] or nq_l[i] > hi_l[i]]
                if not out_l:
                    inside = True
                    break
                # sorted-set algebra on lists: np.union1d/setdiff1d cost 10-30 us each at this size
                old_block = set() if block is None else set(block.tolist())
                new_block = old_block.union(out_l)
                if len(new_block) == len(old_block):
                    # The null space cannot keep them inside: fixation itself needs them
                    # beyond the limit. Hold those at a limit (active set); others get a
                    # shortened step below.
                    push = ((q <= lo) & (dq < 0)) | ((q >= hi) & (dq > 0))
                    if not push.any():
                        break
                    held |= push
                    any_held = True
                    block = np.array(sorted(old_block.difference(np.flatnonzero(push).tolist())), dtype=int)
                    act = free[~held[free]]
                    if act.size == 0:
                        dq = np.zeros(n)
                        break
                else:
                    block = np.array(sorted(new_block), dtype=int)
                dq = self._step(sec_policy, q, q_ref, p, st, act, block)
            nq = q + dq
            dq_l = dq.tolist()
            if not inside:
                nq_l = nq.tolist()
                inside = not any(nq_l[i] < lo_l[i] or nq_l[i] > hi_l[i] for i in range(n))
            if not inside:
                # shorten the step to the first limit it meets (projected steps would zig-zag)
                t = [
                    (lo_l[i] - q_l[i]) / dq_l[i] if dq_l[i] < 0 else (hi_l[i] - q_l[i]) / dq_l[i]
                    for i in range(n)
                    if dq_l[i] != 0 and lo_l[i] < q_l[i] < hi_l[i]  # joints at a limit are projected instead
                ]
                if t:
                    dq = dq * max(min(min(t), 1.0), 0.0)
                nq = np.clip(q + dq, lo, hi)
            step = max(map(abs, dq.tolist()))
            if rr < CONVERGED_RESIDUAL or (rr < FLOOR_RESIDUAL and step < CONVERGED_STEP):
                break
            if rr >= prev * (1.0 - 1e-6) and step < 1e-8:
                break  # stalled at a least-squares minimum (unreachable target)
            if secondary and rr > CONVERGED_RESIDUAL and rr > 0.5 * prev:
                slow += 1
                if slow >= 2:
                    break
            elif not secondary and rr > STALL_RESIDUAL and rr > 0.95 * prev:
                slow += 1  # linear convergence to a non-zero minimum: an unreachable target
                if slow >= 6:
                    break
            else:
                slow = 0
            prev = rr
            new = self._evaluate(nq, p, jacobian=False)
            if not secondary and new.rr > rr:
                # Watchdog: a long step along a weakly determined direction (the calibrated
                # head's version) lands off the curved solution set; one corrective step from
                # there usually ends below the start. Accept the pair if it does.
                dq2 = self._step(None, nq, q_ref, p, new, act, None)
                nq2 = np.clip(nq + dq2, lo, hi)
                new2 = self._evaluate(nq2, p, jacobian=False)
                if new2.rr < rr:
                    q, st = nq2, new2
                    continue
            for _ in range(BACKTRACKS):  # halve steps that increase the fixation residual
                rn = new.rr
                if rn <= rr or rn < 1e-20:
                    break
                dq *= 0.5
                nq = np.clip(q + dq, lo, hi)
                new = self._evaluate(nq, p, jacobian=False)
            q = nq
            st = new
        return q, it, st

    def _version(self, q: Array) -> float:
        """Version [rad]: ``(eye_L - home_L) + s (eye_R - home_R)``, first eye joint of each side."""
        e0, e1 = self._e0, self._e1
        return (float(q[e0]) - self._home_list[e0]) + self._version_sign * (float(q[e1]) - self._home_list[e1])

    def _eigh(self, A: Array) -> tuple[Array, Array]:
        """Eigenvalues (ascending) and eigenvectors of the small symmetric ``A``.

        LAPACK's ``syevd`` (the routine ``np.linalg.eigh`` uses, lower triangle too) called
        through scipy: a third of the call overhead of ``np.linalg.eigh`` at this size.
        """
        lam, V, info = self._syevd(A, compute_v=1, lower=1)
        if info != 0:
            return np.linalg.eigh(A)  # type: ignore[no-any-return]
        return lam, V

    def _step(
        self, policy: str | None, q: Array, q_ref: Array, p: Array, st: _State, act: Index, block: Index | None = None
    ) -> Array:
        """One task-priority Gauss-Newton step over the joints ``act``, shape (n,).

        Priority 1 (fixation) takes the truncated pseudo-inverse step; priority 2 (policy) moves
        only in the exact null space of priority 1 (eigenvectors of ``J1^T J1`` with eigenvalue
        below :data:`NULL_EIGENVALUE`), and not the joints in ``block`` (held by their limits).
        """
        J1 = st.J[:, act]
        lam, V = self._eigh(J1.T @ J1)
        # Levenberg-Marquardt damping mu = |r1|^2 (Yamashita-Fukushima: quadratic convergence on
        # consistent problems even where J1 is singular). Directions weaker than the damping
        # (or than NULL_EIGENVALUE) belong to the null space: fixation cannot use them now.
        mu = st.rr * (1.0 if policy is not None else PHASE2_DAMPING)
        # eigh sorts lam ascending: the null space is the first k0 columns of V, the range the rest
        lam_l = lam.tolist()
        thr = max(mu, NULL_EIGENVALUE)
        k0 = sum(1 for v in lam_l if v <= thr)
        # d = -V diag(1 / (lam + mu), range only) V^T J1^T r; coefficients as floats (tiny)
        c = (st.r @ J1 @ V).tolist()
        coef = [0.0] * k0 + [-c[j] / (lam_l[j] + mu) for j in range(k0, len(lam_l))]
        d_arr = V @ np.array(coef)
        dl = d_arr.tolist()
        m = len(dl)
        has_block = block is not None and block.size > 0
        if k0 and policy == "cyclopean" and not has_block:
            # Null space of fixation V0 = V[:, :k0]; the policy is one row (version), so
            # A2 = a^T (1, k0) and (a a^T + eps I)^-1 a = a / (|a|^2 + eps).
            act_l = act.tolist()
            i0, i1 = act_l.index(self._e0), act_l.index(self._e1)  # the version row's entries
            vs = self._version_sign
            Vl = V.tolist()
            a = [Vl[i0][j] + vs * Vl[i1][j] for j in range(k0)]
            e2 = self._version(q) + (dl[i0] + vs * dl[i1])
            f = e2 / (sum(x * x for x in a) + (1e-24 if k0 == 1 else 1e-12))
            if k0 == 1:
                fa = f * a[0]
                dl = [dl[i] - fa * Vl[i][0] for i in range(m)]
            else:
                dl = (d_arr - V[:, :k0] @ (f * np.array(a))).tolist()
        elif k0:
            # Null space of fixation (at this damping), in coordinates y: motion V0 @ y.
            d = d_arr
            V0 = V[:, :k0]
            ke = sum(1 for v in lam_l if v <= NULL_EIGENVALUE)  # the exact null space: V[:, :ke]
            blocked = set(block.tolist()) if block is not None else set()
            b = np.array([k for k, j in enumerate(act.tolist()) if j in blocked], dtype=int)  # positions in act
            if b.size:
                # Blocked joints (at a limit) must not move: first trade the fixation step's
                # motion of them for motion in the exact null space (fixation unchanged to
                # first order) as far as possible, then keep the policy off them.
                if ke:
                    Ve = V0[:, :ke]
                    y, *_ = np.linalg.lstsq(Ve[b], -d[b], rcond=1e-9)
                    d = d + Ve @ y
                _, sv, Wt = np.linalg.svd(V0[b], full_matrices=True)
                k = int(np.sum(sv > 1e-9))
                V0 = V0 @ Wt[k:].T  # null space directions that leave the blocked joints still
            if policy is not None and V0.shape[1]:
                r2, J2full = self._secondary(policy, q, q_ref, p, st)
                if r2.size:
                    A2 = J2full[:, act] @ V0
                    e2v = r2 + J2full[:, act] @ d
                    if A2.shape[0] == 1 and A2.shape[1] == 1:
                        a2 = float(A2[0, 0])
                        y = np.array([-float(e2v[0]) * a2 / (a2 * a2 + 1e-24)])
                    else:
                        M = A2.T @ A2
                        M.flat[:: M.shape[0] + 1] += 1e-12
                        y = -np.linalg.solve(M, A2.T @ e2v)
                    d = d + V0 @ y
            dl = d.tolist()
        out = [0.0] * self.n
        for i, v in zip(act.tolist(), dl, strict=True):
            out[i] = v
        big = max(map(abs, dl))
        if big > MAX_STEP:
            s = MAX_STEP / big
            out = [v * s for v in out]
        return np.array(out)

    def _answer(self, p: Array, q: Array, iterations: int, policy: str, st: _State) -> GazeSolution:
        errs, misses = [], []
        for x, y, z in st.p_cam:
            lateral = math.hypot(x, y)
            # a target on the camera centre has no direction: count it as missed by pi
            errs.append(math.atan2(lateral, z) if lateral + abs(z) > MIN_TARGET_DISTANCE else math.pi)
            misses.append(lateral if z >= 0 else math.sqrt(x * x + y * y + z * z))
        err, miss = np.array(errs), np.array(misses)
        fix = _closest_point(st.origins, st.axes)
        (a0, a1, a2), (b0, b1, b2) = st.axes
        vergence = math.acos(max(-1.0, min(1.0, a0 * b0 + a1 * b1 + a2 * b2)))
        tol = 1e-12
        at_limit = tuple(
            n for n, v, lo, hi in zip(self.joint_names, q.tolist(), self._lower_list, self._upper_list, strict=True)
            if v <= lo + tol or v >= hi - tol
        )
        reachable = errs[0] <= GAZE_POINTING_TOL and errs[1] <= GAZE_POINTING_TOL
        if reachable:
            status = STATUS_FIXATED
        elif any(z <= 0 for _, _, z in st.p_cam):
            status = STATUS_BEHIND
        elif min(math.sqrt(x * x + y * y + z * z) for x, y, z in st.p_cam) < self.baseline:
            status = STATUS_TOO_CLOSE
        elif at_limit:
            status = STATUS_LIMITS
        else:
            status = STATUS_NO_SOLUTION
        return GazeSolution(
            q=q,
            joint_names=self.joint_names,
            reachable=reachable,
            status=status,
            pointing_error=err,
            miss_distance=miss,
            fixation_point=fix,
            vergence=vergence,
            at_limit=at_limit,
            iterations=iterations,
            policy=policy,
            target=p.copy(),
        )

    # ---- tracking -----------------------------------------------------------------------------

    def track(
        self,
        targets: ArrayLike,
        dt: float,
        max_velocity: ArrayLike | None = None,
        *,
        q_current: ArrayLike | None = None,
        policy: str = "cyclopean",
    ) -> Trajectory:
        """Follow a moving target: warm-started solves and a velocity-limited joint trajectory.

        Each sample solves for the target from the previous goal (one or two iterations when the
        target moves little), then moves the commanded readings towards the goal by at most
        ``max_velocity * dt`` per joint.

        Args:
            targets: Target positions (world) [m], shape (T, 3), one per sample.
            dt: Sample period [s].
            max_velocity: Per-joint speed limit [rad/s]/[m/s], shape (n,) or a scalar; None: the
                URDF velocity limits.
            q_current: Readings at the first sample, shape (n,); None: the first solution.
            policy: Redundancy policy (see :data:`POLICIES`).

        Returns:
            A :class:`Trajectory`.
        """
        if policy not in POLICIES:
            raise ConfigurationError(f"unknown gaze policy {policy!r}; expected one of {', '.join(POLICIES)}")
        P = np.asarray(targets, dtype=float)
        if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] == 0:
            raise ConfigurationError(f"targets must have shape (T, 3) [m], got shape {P.shape}")
        if not np.all(np.isfinite(P)):
            raise ConfigurationError("targets contain NaN or inf")
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ConfigurationError(f"dt must be a positive number of seconds, got {dt!r}")
        vmax = self.velocity_limit if max_velocity is None else np.broadcast_to(
            np.asarray(max_velocity, dtype=float), (self.n,)
        )
        if not (np.all(np.isfinite(vmax)) and np.all(vmax > 0)):
            raise ConfigurationError(f"max_velocity must be positive and finite, got {np.asarray(vmax).tolist()}")
        qc = self._check_q(q_current)
        T = P.shape[0]
        Q = np.empty((T, self.n))
        G = np.empty((T, self.n))
        ok = np.zeros(T, dtype=bool)
        err = np.empty((T, 2))
        locked = np.zeros(T, dtype=bool)
        step = vmax * dt
        q_cmd = qc
        goal: Array | None = None
        for k in range(T):
            # targets and readings are checked above; q_cmd stays between in-limit readings
            sol = self._solve(P[k], None if q_cmd is None else q_cmd.copy(), policy, goal, MAX_ITERATIONS)
            goal = sol.q
            if q_cmd is None:
                q_cmd = goal.copy()
            delta = np.clip(goal - q_cmd, -step, step)
            q_cmd = q_cmd + delta
            locked[k] = bool(np.all(np.abs(goal - q_cmd) <= 1e-15))
            if locked[k]:
                q_cmd = goal.copy()
            G[k] = goal
            Q[k] = q_cmd
            ok[k] = sol.reachable
            st = self._evaluate(q_cmd, P[k], jacobian=False)
            err[k] = [math.atan2(math.hypot(x, y), z) for x, y, z in st.p_cam]
        return Trajectory(np.arange(T, dtype=float) * float(dt), Q, G, ok, err, locked, self.joint_names)

    # ---- convenience --------------------------------------------------------------------------

    def camera_poses(self, q: ArrayLike) -> tuple[Array, Array]:
        """``T_world_<camera>`` of the left and right camera at readings ``q`` (shape (n,)), each (4, 4)."""
        qa = np.asarray(q, dtype=float)
        if qa.shape != (self.n,) or not np.all(np.isfinite(qa)):
            raise ConfigurationError(f"q must be {self.n} finite readings, got shape {qa.shape}")
        self._pin.framesForwardKinematics(self.model, self.data, qa)
        return tuple(self.data.oMf[e.frame_id].homogeneous.copy() for e in self._eyes)  # type: ignore[return-value]


def _closest_point(origins: Sequence[Sequence[float]], axes: Sequence[Sequence[float]]) -> Array | None:
    """Midpoint of the closest points of two lines ``origins[k] + t axes[k]``; None if parallel.

    ``origins`` and ``axes`` are 2 x 3 (float lists or an array's rows).
    """
    d0, d1 = axes
    o0, o1 = origins
    w = [o0[i] - o1[i] for i in range(3)]
    a = d0[0] * d0[0] + d0[1] * d0[1] + d0[2] * d0[2]
    b = d0[0] * d1[0] + d0[1] * d1[1] + d0[2] * d1[2]
    c = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    den = a * c - b * b
    if den < 1e-14:
        return None
    dd = d0[0] * w[0] + d0[1] * w[1] + d0[2] * w[2]
    e = d1[0] * w[0] + d1[1] * w[1] + d1[2] * w[2]
    s = (b * e - c * dd) / den
    t = (a * e - b * dd) / den
    return np.array([0.5 * (o0[i] + s * d0[i] + o1[i] + t * d1[i]) for i in range(3)])


def solver_for(name_or_path: str | Path, cameras: Sequence[str] = DEFAULT_CAMERAS, **kwargs: Any) -> GazeSolver:
    """A solver for a ``.urdf`` file, a model file, a robot spec or a shipped robot name."""
    text = str(name_or_path)
    if text.endswith(".urdf"):
        return GazeSolver(Path(text), cameras, **kwargs)
    from cpc2urdf.robot_ref import load_model

    return GazeSolver.from_model(load_model(text), cameras, **kwargs)
