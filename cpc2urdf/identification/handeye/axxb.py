"""Hand-eye calibration ``A X = X B`` (Tsai-Lenz, Park-Martin, Daniilidis) and what all solvers share.

Conventions (every solver here and in :mod:`cpc2urdf.identification.handeye.axzb`; run any of
them by name with :func:`cpc2urdf.identification.handeye.solvers.calibrate`):

- Input: absolute poses per robot configuration k,
  ``T_base_hand[k]`` (hand = the end effector carrying the camera, from the robot kinematics) and
  ``T_camera_target[k]`` (pose of the calibration target in the camera frame: what
  ``cv2.solvePnP`` returns as ``rvec, tvec``). Shape (N, 4, 4), metres.
- Unknowns: ``X = T_hand_camera`` (camera pose in the hand frame) and
  ``Z = T_base_target`` (target pose in the robot base frame). Closing the loop gives
  ``T_base_target = T_base_hand[k] @ X @ T_camera_target[k]`` for every k.
- ``A X = Z B`` (Li et al. 2010) with ``A_k = T_base_hand[k]``, ``B_k = T_target_camera[k]``
  ``= inv(T_camera_target[k])``.
- ``A X = X B`` (Tsai-Lenz, Shih et al. eqs. (69)-(71)) with relative motions over pairs
  ``(i, j)``: ``A_ij = inv(T_base_hand[j]) @ T_base_hand[i]`` (hand i in hand j) and
  ``B_ij = T_camera_target[j] @ inv(T_camera_target[i])`` (camera i in camera j). Up to
  ``2 * MAX_PAIRS_PER_POSE + 1`` poses these are all pairs ``i < j`` (the pairs
  ``cv2.calibrateHandEye`` uses); beyond, each pose is paired with ``MAX_PAIRS_PER_POSE`` others
  spread over the sequence (:func:`motion_pairs`), so time and memory grow linearly with the
  poses. ``Z`` is then the chordal mean of ``T_base_hand[k] @ X @ T_camera_target[k]``.

Degenerate data is refused with :class:`~cpc2urdf.errors.DegenerateDataError` naming the reason
(fewer than 3 poses; rotations too small or all about parallel axes; hand and camera motions
whose rotation angles only agree if one pose list is inverted), and weak data is reported in
:attr:`HandEyeResult.warnings`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye.gate.gate_report import ConsistencyReport
from cpc2urdf.transforms import (
    Array,
    dual_quat_from_transform,
    homogeneous,
    inverse,
    project_to_rotation,
    quat_left_matrix,
    quat_right_matrix,
    quat_wxyz_from_matrix,
    rotation_error,
    skew,
    transform_from_dual_quat,
)

MIN_POSES = 3
# RMS rotation [rad] (over pose pairs) about the best / second-best excited direction below which
# the data cannot determine the rotation of X (refused) or determines it poorly (a warning).
DEGENERATE_ROTATION = math.radians(0.1)
WEAK_ROTATION = math.radians(5.0)
# Each pose is paired with at most this many others for the relative motions of A X = X B: up to
# 2 * 15 + 1 = 31 poses that is every pair (as OpenCV); beyond, 15 N pairs instead of N(N-1)/2
# (1,000 poses: 15,000 instead of 499,500). On Li et al.'s noise (40-200 poses, 20 seeds,
# cpc2urdf.studies.handeye_pairs) X's rotation error is that of all pairs to 1e-4, its translation
# error within -13 % .. +21 % of all pairs' (docs/handeye.md, "Many poses").
MAX_PAIRS_PER_POSE = 15
# A pose whose residual exceeds this many times the median (and 1 mm / 0.1 deg) is flagged.
OUTLIER_FACTOR = 5.0


# ---- input checks ------------------------------------------------------------------------------


def as_pose_stack(poses: ArrayLike | Sequence[ArrayLike], name: str) -> Array:
    """Validate a list of rigid transforms into shape (N, 4, 4).

    Raises:
        ValueError: Wrong shape, NaN, or a rotation part that is not a rotation (max entry of
            ``|R^T R - I|`` above 1e-6 or det < 0), naming ``name[k]``.
    """
    T = np.asarray(poses, dtype=float)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise ValueError(f"{name} must be a list of 4x4 transforms, got shape {T.shape}")
    finite = np.all(np.isfinite(T), axis=(1, 2))
    R = np.where(finite[:, None, None], T, 0.0)[:, :3, :3]
    not_rotation = (np.max(np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)), axis=(1, 2)) > 1e-6) | (
        np.linalg.det(R) < 0
    )
    bad_row = np.max(np.abs(T[:, 3] - [0.0, 0.0, 0.0, 1.0]), axis=1) > 1e-12
    for k in np.flatnonzero(~finite | not_rotation | bad_row)[
        :1
    ]:  # the first bad pose, as a loop would
        if not finite[k]:
            raise ValueError(f"{name}[{k}] contains NaN or inf")
        if not_rotation[k]:
            raise ValueError(f"{name}[{k}] rotation part is not a rotation matrix")
        raise ValueError(f"{name}[{k}] last row must be [0, 0, 0, 1]")
    return T


def motion_pairs(
    n: int, per_pose: int = MAX_PAIRS_PER_POSE
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Index arrays ``(i, j)`` of the pose pairs whose relative motions an ``A X = X B`` solve uses.

    Up to ``2 per_pose + 1`` poses: every pair ``i < j`` (``np.triu_indices`` order). Beyond: pose
    i is paired with ``j = (i + d) mod n`` for ``per_pose`` offsets ``d`` spread evenly over
    ``1 .. (n - 1) // 2`` -- consecutive poses (d = 1) as OpenCV-style tools pair a recorded
    sequence, and poses half a sequence apart, whose relative rotations are large even when the
    poses come from a slowly moving stream. Each unordered pair appears once; every pose is in
    ``2 per_pose`` pairs; ``per_pose * n`` pairs in all, O(n) time and memory. The choice depends
    only on n (never on the noisy poses themselves), so it cannot bias an estimate.
    """
    if n <= 2 * per_pose + 1:
        i, j = np.triu_indices(n, k=1)
        return i, j
    offsets = np.unique(np.round(np.linspace(1, (n - 1) // 2, per_pose)).astype(np.intp))
    i = np.repeat(np.arange(n, dtype=np.intp), len(offsets))
    j = (i + np.tile(offsets, n)) % n
    return i, j


def rotation_spread(T_base_hand: Array) -> tuple[Array, Array]:
    """How well the hand rotations excite the rotation of X: principal RMS rotations.

    The rotation vectors ``r_ij = log(R_i R_j^T)`` of the pairs of hand poses the solvers use
    (:func:`motion_pairs`; base frame) form ``M = sum r r^T / n_pairs``. X's rotation is
    determined iff two directions are excited, i.e. the second singular value is non-zero (Tsai-Lenz: two motions with non-parallel axes).

    Returns:
        ``(rms, axes)``: RMS rotation [rad] about each principal direction, shape (3,),
        decreasing; ``axes`` the directions (columns) in the base frame, shape (3, 3).
    """
    i, j = motion_pairs(len(T_base_hand))
    R = T_base_hand[:, :3, :3]
    r = Rotation.from_matrix(R[i] @ np.swapaxes(R[j], -1, -2)).as_rotvec()
    M = r.T @ r / max(len(r), 1)
    w, V = np.linalg.eigh(M)
    order = np.argsort(w)[::-1]
    return np.sqrt(np.clip(w[order], 0.0, None)), V[:, order]


def _fit_cost(T_base_hand: Array, T_camera_target: Array) -> float:
    """Residual level of a quick Park-Martin fit, in units of 1 mm / 0.1 deg (the larger)."""
    A, B = relative_motions(T_base_hand, T_camera_target)
    X = solve_park_martin(A, B)
    dt, dr = residuals(
        T_base_hand, T_camera_target, X, target_from_x(T_base_hand, T_camera_target, X)
    )
    return max(
        float(np.sqrt(np.mean(dt**2))) / 1e-3, float(np.sqrt(np.mean(dr**2))) / math.radians(0.1)
    )


def check_directions(T_base_hand: Array, T_camera_target: Array) -> list[str]:
    """Detect a pose list given in the wrong direction from the residuals of a quick fit.

    The screw invariants of the motions cannot tell (inverting every pose keeps the angle and
    pitch of ``T_j^-1 T_i``, which is conjugate to the inverse of ``T_j T_i^-1``), but the loop
    ``T_base_hand[k] X T_camera_target[k] = Z`` only closes for the right directions. A quick
    Park-Martin fit is tried as given and with ``T_camera_target`` inverted; if as given the
    residuals are above 1 mm / 0.1 deg and the inversion shrinks them tenfold, the data is refused.

    Limits: inverting one list fits exactly as well as inverting the other (inverting *both* lists
    is an exact symmetry of ``A X = Z B``: it swaps X and Z), so the message names both
    possibilities, and both lists inverted at once cannot be detected from the residuals at all.
    The consistency gate (:mod:`~cpc2urdf.identification.handeye.gate.handeye_gate`) replaces this check
    in ``calibrate(..., gate=True)`` and tells the cases apart by plausibility.

    Returns:
        A warning if the residuals are large (over 10 mm or 1 deg RMS) and inversion does not help.

    Raises:
        DegenerateDataError: One of the lists is evidently inverted.
    """
    given = _fit_cost(T_base_hand, T_camera_target)
    if given <= 1.0:
        return []
    inverted = _fit_cost(T_base_hand, inverse(T_camera_target))
    if inverted < 0.1 * given:
        raise DegenerateDataError(
            f"inconsistent directions: a quick fit leaves residuals of {given:.3g} units "
            f"(1 mm / 0.1 deg RMS) as given but {inverted:.3g} with one list inverted: pass "
            "T_camera_target (target pose in the camera frame, solvePnP's rvec/tvec), not "
            "T_target_camera, and T_base_hand (hand pose in the base frame), not T_hand_base "
            "(an eye-to-hand setup, camera fixed and target on the hand, also looks like this)"
        )
    if given > 10.0:
        return [
            f"large residuals ({given:.3g} x 1 mm / 0.1 deg RMS in a quick fit) that no inversion "
            "explains: poses out of sync, mixed units, outliers or a wrong kinematic model?"
        ]
    return []


def check_degenerate(T_base_hand: Array, T_camera_target: Array) -> list[str]:
    """Refuse data that cannot determine X and Z; return warnings for weak data.

    Raises:
        DegenerateDataError: Fewer than 3 poses, different list lengths, rotations too small,
            or rotations about parallel axes only.
    """
    n, m = len(T_base_hand), len(T_camera_target)
    if n != m:
        raise DegenerateDataError(f"{n} hand poses but {m} camera poses; they must pair up")
    if n < MIN_POSES:
        raise DegenerateDataError(
            f"{n} poses; hand-eye calibration needs at least {MIN_POSES} (two motions about "
            "non-parallel axes)"
        )
    problem = rotation_degeneracy(T_base_hand)
    if problem:
        raise DegenerateDataError(problem)
    rms, _ = rotation_spread(T_base_hand)
    if rms[1] < WEAK_ROTATION:
        return [
            f"weak data: the hand rotations excite a second axis by only {math.degrees(rms[1]):.3g} "
            f"deg RMS (< {math.degrees(WEAK_ROTATION):g} deg); expect noise to be amplified"
        ]
    return []


def rotation_degeneracy(T_base_hand: Array) -> str:
    """Why the hand rotations cannot determine X's rotation ("" if they can): tiny rotations, or
    rotations about parallel axes only."""
    rms, axes = rotation_spread(T_base_hand)
    if rms[0] < DEGENERATE_ROTATION:
        return (
            f"tiny rotations: the hand rotates by {math.degrees(rms[0]):.3g} deg RMS between poses "
            f"(< {math.degrees(DEGENERATE_ROTATION):g} deg); the rotation of X is undetermined"
        )
    if rms[1] < DEGENERATE_ROTATION:
        ax = np.round(axes[:, 0], 3).tolist()
        return (
            f"rotations about parallel axes only (all about {ax} in the base frame, "
            f"{math.degrees(rms[1]):.3g} deg RMS about any other direction): X's rotation about "
            "that axis is undetermined; move a second joint with a non-parallel axis"
        )
    return ""


def diagnose(T_base_hand: Array, T_camera_target: Array) -> list[str]:
    """:func:`check_degenerate`, then :func:`check_directions`; returns their warnings.

    Raises:
        DegenerateDataError: Fewer than 3 poses, different list lengths, rotations too small,
            rotations about parallel axes only, or pose lists in the wrong direction.
    """
    weak = check_degenerate(T_base_hand, T_camera_target)
    return check_directions(T_base_hand, T_camera_target) + weak


# ---- the result --------------------------------------------------------------------------------


@dataclass(frozen=True)
class HandEyeResult:
    """A hand-eye / robot-world solution with its residuals.

    Attributes:
        method: Solver name.
        X: ``T_hand_camera``, the camera pose in the hand frame, shape (4, 4) [m].
        Z: ``T_base_target``, the target pose in the robot base frame, shape (4, 4) [m].
        residual_translation: Per pose k, ``|p(A_k X) - p(Z B_k)|``: distance [m] between the
            camera position predicted by the hand pose and by the target observation (base
            frame), shape (N,).
        residual_rotation: Per pose k, angle [rad] of ``(A_k X)^-1 Z B_k``, shape (N,).
        warnings: Weak or suspicious data, in words.
        consistency: The consistency gate's verdict on the data (``calibrate(..., gate=True)``),
            or None if the gate did not run.
    """

    method: str
    X: Array
    Z: Array
    residual_translation: Array
    residual_rotation: Array
    warnings: tuple[str, ...] = field(default=())
    consistency: ConsistencyReport | None = None

    @property
    def T_hand_camera(self) -> Array:
        return self.X

    @property
    def T_base_target(self) -> Array:
        return self.Z

    def rms_translation(self) -> float:
        """RMS of the per-pose translation residuals [m]."""
        return float(np.sqrt(np.mean(self.residual_translation**2)))

    def rms_rotation(self) -> float:
        """RMS of the per-pose rotation residuals [rad]."""
        return float(np.sqrt(np.mean(self.residual_rotation**2)))

    def to_json(self) -> dict[str, Any]:
        """Plain JSON (metres, radians, plus mm/deg residuals for reading)."""
        return {
            "method": self.method,
            "X": {
                "direction": "T_hand_camera (camera pose in the hand frame)",
                "matrix": self.X.tolist(),
            },
            "Z": {
                "direction": "T_base_target (target pose in the robot base frame)",
                "matrix": self.Z.tolist(),
            },
            "residual_translation_mm": (self.residual_translation * 1e3).tolist(),
            "residual_rotation_deg": np.degrees(self.residual_rotation).tolist(),
            "rms_translation_mm": self.rms_translation() * 1e3,
            "rms_rotation_deg": math.degrees(self.rms_rotation()),
            "warnings": list(self.warnings),
            **({"consistency": self.consistency.to_json()} if self.consistency is not None else {}),
        }


def residuals(
    T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array
) -> tuple[Array, Array]:
    """Per-pose residuals of ``A_k X = Z B_k``: (translation [m], rotation [rad]), each (N,)."""
    AX = T_base_hand @ X
    ZB = Z @ inverse(T_camera_target)
    dt = np.linalg.norm(AX[:, :3, 3] - ZB[:, :3, 3], axis=-1)
    dr = rotation_error(AX[:, :3, :3], ZB[:, :3, :3])
    return dt, dr


def outlier_warnings(dt: Array, dr: Array) -> list[str]:
    """Name poses whose residual is far above the median (a bad detection, a desync)."""
    out = []
    mt, mr = float(np.median(dt)), float(np.median(dr))
    for k in range(len(dt)):
        if (dt[k] > OUTLIER_FACTOR * mt and dt[k] > 1e-3) or (
            dr[k] > OUTLIER_FACTOR * mr and dr[k] > math.radians(0.1)
        ):
            out.append(
                f"pose {k} is an outlier: residual {dt[k] * 1e3:.3g} mm, {math.degrees(dr[k]):.3g} deg "
                f"(median {mt * 1e3:.3g} mm, {math.degrees(mr):.3g} deg)"
            )
    return out


def make_result(
    method: str, T_base_hand: Array, T_camera_target: Array, X: Array, Z: Array, warnings: list[str]
) -> HandEyeResult:
    """Assemble a :class:`HandEyeResult` with residuals and outlier warnings."""
    dt, dr = residuals(T_base_hand, T_camera_target, X, Z)
    return HandEyeResult(method, X, Z, dt, dr, tuple(warnings + outlier_warnings(dt, dr)))


def mean_pose(T: Array) -> Array:
    """Chordal mean of rigid transforms (N, 4, 4): polar-projected mean rotation, mean translation."""
    return homogeneous(project_to_rotation(T[:, :3, :3].mean(axis=0)), T[:, :3, 3].mean(axis=0))


def target_from_x(T_base_hand: Array, T_camera_target: Array, X: Array) -> Array:
    """``Z = T_base_target`` given X: the chordal mean of ``T_base_hand[k] X T_camera_target[k]``."""
    return mean_pose(T_base_hand @ X @ T_camera_target)


# ---- AX = XB ----------------------------------------------------------------------------------


def relative_motions(
    T_base_hand: Array,
    T_camera_target: Array,
    pairs: tuple[NDArray[np.intp], NDArray[np.intp]] | None = None,
) -> tuple[Array, Array]:
    """Relative motions ``(A_ij, B_ij)`` with ``A_ij X = X B_ij`` (Shih et al. eq. (71)) over
    ``pairs`` (default :func:`motion_pairs`: all pairs up to 31 poses, 15 per pose beyond), each
    of shape (P, 4, 4)."""
    i, j = motion_pairs(len(T_base_hand)) if pairs is None else pairs
    A = inverse(T_base_hand[j]) @ T_base_hand[i]
    B = T_camera_target[j] @ inverse(T_camera_target[i])
    return A, B


def _translation_given_rotation(A: Array, B: Array, R_X: Array) -> Array:
    """Least squares for ``(R_A - I) t_X = R_X t_B - t_A`` over all motions (Tsai-Lenz step 2)."""
    M = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (np.einsum("ij,kj->ki", R_X, B[:, :3, 3]) - A[:, :3, 3]).reshape(-1)
    return np.linalg.lstsq(M, rhs, rcond=None)[0]


# Relative rotations closer than this to 180 deg have an ambiguous axis sign (R(n, pi) = R(-n, pi)):
# noise can flip it between a hand motion and its camera motion. They are left out of a first
# estimate and then sign-aligned with it (below).
AMBIGUOUS_AXIS_ANGLE = math.radians(170.0)


def _align_axis_signs(VA: Array, VB: Array, solve: Callable[[Array, Array], Array]) -> Array:
    """Solve a rotation from axis vectors ``VA ~ R_X VB`` (N, 3) robustly near 180 deg.

    First ``solve`` on the motions whose angle is below :data:`AMBIGUOUS_AXIS_ANGLE` (if two
    or more), then flip the ``VB`` whose direction disagrees with that estimate, and solve again
    on all motions. Returns the rotation (3, 3).
    """
    th = np.linalg.norm(VA, axis=-1)
    ok = (
        th < 2.0 * math.sin(AMBIGUOUS_AXIS_ANGLE / 2.0)
        if solve is _tsai_rotation
        else th < AMBIGUOUS_AXIS_ANGLE
    )
    if ok.all() or ok.sum() < 2:
        return solve(VA, VB)
    R1 = solve(VA[ok], VB[ok])
    VB = np.where((np.einsum("ki,ki->k", VB @ R1.T, VA) < 0)[:, None], -VB, VB)
    return solve(VA, VB)


def _modified_rodrigues(R: Array) -> Array:
    """Tsai-Lenz's ``P = 2 sin(theta/2) n`` of rotations (N, 3, 3) -> (N, 3)."""
    r = Rotation.from_matrix(R).as_rotvec()
    th = np.linalg.norm(r, axis=-1, keepdims=True)
    safe = np.where(th > 1e-300, th, 1.0)
    return np.where(th > 1e-300, 2.0 * np.sin(th / 2.0) * r / safe, r)


def _tsai_rotation(PA: Array, PB: Array) -> Array:
    """Tsai-Lenz rotation step (``P_A = R_X P_B``): ``skew(P_A + P_B) P'_X = P_B - P_A``, then
    ``P_X = 2 P'_X / sqrt(1 + |P'_X|^2)`` and ``R_X`` from ``P_X``."""
    M = skew(PA + PB).reshape(-1, 3)
    Pp = np.linalg.lstsq(M, (PB - PA).reshape(-1), rcond=None)[0]
    P = 2.0 * Pp / math.sqrt(1.0 + Pp @ Pp)
    n2 = float(P @ P)
    R = (1.0 - n2 / 2.0) * np.eye(3) + 0.5 * (
        np.outer(P, P) + math.sqrt(max(4.0 - n2, 0.0)) * skew(P)
    )
    return project_to_rotation(R)


def solve_tsai(A: Array, B: Array) -> Array:
    """Tsai & Lenz (1989) for ``A_i X = X B_i`` from relative motions (N, 4, 4) each.

    Rotation from the modified Rodrigues vectors ``P = 2 sin(theta/2) n`` (:func:`_tsai_rotation`),
    with axis signs of near-180-deg motions aligned (:func:`_align_axis_signs`); then the
    translation by least squares. Returns X, shape (4, 4).
    """
    R = _align_axis_signs(
        _modified_rodrigues(A[:, :3, :3]), _modified_rodrigues(B[:, :3, :3]), _tsai_rotation
    )
    return homogeneous(R, _translation_given_rotation(A, B, R))


def _park_martin_rotation(alpha: Array, beta: Array) -> Array:
    return project_to_rotation((beta.T @ alpha).T)


def solve_park_martin(A: Array, B: Array) -> Array:
    """Park & Martin (1994): ``R_X = (M^T M)^(-1/2) M^T`` with ``M = sum beta_i alpha_i^T``,
    ``alpha = log R_A``, ``beta = log R_B`` (the polar factor of ``M^T``, computed by SVD), axis
    signs of near-180-deg motions aligned; then the translation by least squares. Relative
    motions (N, 4, 4) each; returns X, shape (4, 4)."""
    alpha = Rotation.from_matrix(A[:, :3, :3]).as_rotvec()
    beta = Rotation.from_matrix(B[:, :3, :3]).as_rotvec()
    R = _align_axis_signs(alpha, beta, _park_martin_rotation)
    return homogeneous(R, _translation_given_rotation(A, B, R))


# ---- Daniilidis: dual quaternions -------------------------------------------------------------


def _daniilidis_null_space(a: Array, ad: Array, b: Array, bd: Array) -> Array:
    """X from sign-matched dual quaternions of the motions (each (N, 4)): thin SVD of the stacked
    ``[L(a) - R(b), 0; L(a') - R(b'), L(a) - R(b)]``, then the null-space combination."""
    La = quat_left_matrix(a)
    Lad = quat_left_matrix(ad)
    Rb = quat_right_matrix(b)
    Rbd = quat_right_matrix(bd)
    S = np.zeros((len(a), 8, 8))
    S[:, :4, :4] = S[:, 4:, 4:] = La - Rb
    S[:, 4:, :4] = Lad - Rbd
    _, _, Vt = np.linalg.svd(S.reshape(-1, 8), full_matrices=False)
    v1, v2 = Vt[-1], Vt[-2]
    lam = null_space_combination([(v1[:4], v2[:4], v1[4:], v2[4:])])
    v = lam[0] * v1 + lam[1] * v2
    return transform_from_dual_quat(v[:4], v[4:])


def solve_daniilidis(A: Array, B: Array) -> Array:
    """Daniilidis (1999): ``a x = x b`` in dual quaternions, from relative motions (N, 4, 4).

    Per motion, ``[L(a) - R(b), 0; L(a') - R(b'), L(a) - R(b)] [x; x'] = 0``; the null space
    of the stacked matrix is two-dimensional, ``x = l1 u1 + l2 u2`` with ``|x| = 1`` and
    ``x . x' = 0``. The signs of a and b must agree: Daniilidis matches them by their scalar parts
    (equal screw angles), which noise makes a coin toss for motions near 180 deg (scalar part
    ~ 0; one mismatched motion corrupts the translation). So, as for Tsai and Park-Martin
    (:data:`AMBIGUOUS_AXIS_ANGLE`), a first solution without those motions (if two or more
    remain) sets every motion's sign by ``a . (x b x*) > 0``, and the solve is repeated on all
    (Li et al. 2010's setup, 100 poses: X translation error 0.30 mm instead of 0.60). Built for all
    motions at once and solved by a thin SVD: time and memory linear in N.
    """
    a, ad = dual_quat_from_transform(A)
    b, bd = dual_quat_from_transform(B)
    sign = np.where(a[:, 0] * b[:, 0] < 0, -1.0, 1.0)[:, None]  # equal angles: scalar parts agree
    ok = a[:, 0] > math.cos(AMBIGUOUS_AXIS_ANGLE / 2.0)  # a[:, 0] = cos(angle / 2) >= 0
    if ok.all() or ok.sum() < 2:
        return _daniilidis_null_space(a, ad, sign * b, sign * bd)
    X1 = _daniilidis_null_space(a[ok], ad[ok], sign[ok] * b[ok], sign[ok] * bd[ok])
    qx = quat_wxyz_from_matrix(X1[None, :3, :3])
    Lx, Rx = quat_left_matrix(qx), quat_right_matrix(qx)
    xbx = np.einsum("ij,kj->ki", Lx[0] @ Rx[0].T, b)  # x b x* (R(x*) = R(x)^T for a unit x)
    sign = np.where(np.einsum("ki,ki->k", a, xbx) < 0, -1.0, 1.0)[:, None]
    return _daniilidis_null_space(a, ad, sign * b, sign * bd)


def null_space_combination(blocks: list[tuple[Array, Array, Array, Array]]) -> Array:
    """``(l1, l2)`` so that ``v = l1 v1 + l2 v2`` has unit real parts orthogonal to their duals.

    ``blocks`` lists ``(real1, real2, dual1, dual2)`` per unknown dual quaternion. The constraint
    ``sum real . dual = 0`` is a quadratic form ``Q`` in ``(l1, l2)``; of its two isotropic
    directions one has zero real part (the ``eps`` multiple of the solution), so the one with the
    larger real norm is taken (Daniilidis 1999; Li et al. eqs. (14a)-(14d)).
    """
    Q = np.zeros((2, 2))
    N = np.zeros((2, 2))
    for r1, r2, d1, d2 in blocks:
        R_, D_ = (r1, r2), (d1, d2)
        for p in range(2):
            for q in range(2):
                Q[p, q] += 0.5 * (R_[p] @ D_[q] + R_[q] @ D_[p])
                N[p, q] += R_[p] @ R_[q]
    e, V = np.linalg.eigh(Q)
    if e[0] * e[1] < 0:
        cands = [
            V @ np.array([math.sqrt(abs(e[1])), s * math.sqrt(abs(e[0]))]) for s in (1.0, -1.0)
        ]
    else:  # noise made Q definite: the direction of least violation
        cands = [V[:, int(np.argmin(np.abs(e)))]]
    u = max(cands, key=lambda c: float(c @ N @ c))
    return u * math.sqrt(len(blocks) / float(u @ N @ u))


__all__ = [
    "AMBIGUOUS_AXIS_ANGLE",
    "DEGENERATE_ROTATION",
    "MIN_POSES",
    "OUTLIER_FACTOR",
    "MAX_PAIRS_PER_POSE",
    "WEAK_ROTATION",
    "HandEyeResult",
    "as_pose_stack",
    "check_degenerate",
    "check_directions",
    "diagnose",
    "make_result",
    "mean_pose",
    "motion_pairs",
    "null_space_combination",
    "outlier_warnings",
    "relative_motions",
    "rotation_degeneracy",
    "residuals",
    "rotation_spread",
    "solve_daniilidis",
    "solve_park_martin",
    "solve_tsai",
    "target_from_x",
]
