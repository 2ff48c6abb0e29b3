"""The default hand-eye solver: joint maximum likelihood of X and Z, outliers dropped.

Conventions of :mod:`cpc2urdf.identification.handeye.axxb`: ``H_k = T_base_hand[k]``,
``C_k = T_camera_target[k]``, unknowns ``X = T_hand_camera`` and ``Z = T_base_target``.

Model. Pose k closes the loop ``H_k X C_k = Z``. The residual ``e_k = log((H_k X)^-1 Z C_k^-1)``
(rotation vector [rad], translation [m], camera frame) has, to first order, the covariance
``S_k = Ad(X^-1) diag(hand) Ad(X^-1)^T + G_k diag(target) G_k^T``: a hand twist (hand frame) and
a target error made of a rotation about the target's origin (target axes) and a shift (camera
axes), ``G_k`` mapping the latter to the camera frame (:data:`NOISE_GROUPS`: 8 levels; below
:data:`MIN_POSES_PER_NOISE` poses per level, 2). X, Z and the noise levels are estimated
together: Gauss-Newton on the whitened residuals alternates with the noise's maximum likelihood.

Start. Each closed form (Kronecker in metres and in millimetres, Park & Martin, the dual
quaternions) and, from 8 poses on, Kronecker on random triples of poses are scored by a low
quantile of the camera-pose mismatch (position plus angle times the camera-target distance): a
least-quantile-of-squares start that ignores up to half the poses.

Outliers. When the start leaves a heavy tail, the fit starts on the half of the poses it explains
best (its covariance corrected for that selection); then every pose whose leverage-corrected
Mahalanobis distance is below the chi-square 99.9 % point (6 dof) is kept and the fit repeated,
until the set stops changing. The dropped poses are returned, so that the report can name them.

Drift. Time-ordered residuals correlated from one pose to the next (:data:`DRIFT_CORRELATION`: a
visual-odometry trajectory drifting) bias the absolute poses' rotation; X's rotation then comes
from consecutive motions ``A X = X B``, its translation from the poses.

Unknown scale (a monocular visual-odometry or structure-from-motion camera trajectory): with
``estimate_scale`` the target-pose translations are ``s`` times the metric ones, ``s`` is a
parameter of the fit (started from the translation least squares given the start's rotations).

Undetermined directions (hand rotations about parallel axes only) keep the start's values: the
Gauss-Newton steps are minimum-norm, and :attr:`LikelihoodFit.undetermined` lists them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares, minimize
from scipy.stats import chi2

from cpc2urdf.identification.handeye.axxb import (
    mean_pose,
    relative_motions,
    solve_park_martin,
    target_from_x,
)
from cpc2urdf.identification.handeye.axzb import solve_dual_quaternion, solve_kronecker
from cpc2urdf.transforms import (
    Array,
    homogeneous,
    inverse,
    matrix_from_rotvec,
    rotvec_from_matrix,
    skew,
)

#: A pose is an outlier when its squared Mahalanobis distance exceeds this chi-square point (6 dof).
OUTLIER_PROBABILITY = 0.999
#: The least-quantile start scores a candidate by this quantile of the poses' mismatch.
START_QUANTILE = 0.4
#: Kronecker on this many random triples of poses, from :data:`MIN_POSES_FOR_TRIPLES` poses on
#: (with half the poses outliers, none of them clean has probability 1.6e-6).
TRIPLES = 100
MIN_POSES_FOR_TRIPLES = 8
TAIL_RATIO = 4.0
#: ... or a single pose's mismatch this many robust deviations (MAD) above the median.
GROSS_MADS = 10.0
#: The noise model's standard deviations (log) per noise column: hand rotation and translation
#: (isotropic, hand axes), target rotation about its origin (target axes) and target translation
#: (camera axes: depth is usually the worst), 8 parameters.
NOISE_GROUPS = np.array([0, 0, 0, 1, 1, 1, 2, 3, 4, 5, 6, 7])
#: Fewer poses than this per noise parameter: :data:`FEW_POSES_TIES` (a rotation and a
#: translation level shared by the hand and the target).
MIN_POSES_PER_NOISE = 2
FEW_POSES_TIES = np.array([0, 1, 0, 0, 0, 1, 1, 1])
#: A direction of the fit is undetermined when its information is below this fraction of the best.
UNDETERMINED = 1e-9
#: Residuals this correlated from one pose to the next (time order) are a drift: X is then
#: fitted to consecutive motions.
DRIFT_CORRELATION = 0.5
_MOTION_ROUNDS = 4  # weight / solve rounds of the consecutive motions
_MAX_ROUNDS = 8  # outlier rounds
_MAX_GLS = 20  # weight / solve rounds per set
_MAX_STEPS = 20  # Gauss-Newton steps per weight
_MAX_STEP = 0.3  # [rad], [m], log scale: the largest Gauss-Newton step per unknown


@dataclass(frozen=True)
class LikelihoodFit:
    """The maximum-likelihood solution.

    Attributes:
        X: ``T_hand_camera``, shape (4, 4) [m].
        Z: ``T_base_target``, shape (4, 4) [m].
        scale: Target translations measured / metric (1.0 unless estimated).
        inliers: Poses the fit keeps, bool shape (N,).
        noise: Standard deviations of :data:`NOISE_GROUPS`: hand rotation [rad] and translation
            [m], target rotation per target axis [rad] and translation per camera axis [m], (8,).
        covariance: Covariance of the solution's perturbation ``(X exp(dx), Z exp(dz)[, log s])``
            (rotation vector, translation per unknown), shape (12, 12) or (13, 13).
        start: Which start the fit began from.
        undetermined: Directions of the perturbation the poses do not determine (the fit kept
            its start along them), one per row; none for data that determine X and Z.
    """

    X: Array
    Z: Array
    scale: float
    inliers: NDArray[np.bool_]
    noise: Array
    covariance: Array
    start: str
    undetermined: Array = field(default_factory=lambda: np.zeros((0, 12)))

    def undetermined_words(self) -> list[str]:
        """The directions the poses do not determine, in words (X's in the hand frame, Z's in
        the base frame); the solution keeps its start there. Empty when X and Z are determined."""
        parts = []
        for name, k, R in (
            ("X's rotation about", 0, self.X[:3, :3]),
            ("X's translation along", 3, self.X[:3, :3]),
            ("Z's rotation about", 6, self.Z[:3, :3]),
            ("Z's translation along", 9, self.Z[:3, :3]),
        ):
            if len(self.undetermined):
                _, sv, Vt = np.linalg.svd(self.undetermined[:, k : k + 3], full_matrices=False)
                parts += [
                    f"{name} {np.round(R @ d, 3).tolist()}"
                    for g, d in zip(sv, Vt, strict=True)
                    if g > 0.1
                ]
        if self.undetermined.shape[1] > 12 and np.any(np.abs(self.undetermined[:, 12]) > 0.1):
            parts.append("the scale of the target translations")
        if not parts:
            return []
        return [
            "undetermined by these poses, kept at the closed form's values (X in the hand "
            "frame, Z in the base frame): " + "; ".join(parts)
        ]


def pose_residuals(H: Array, C: Array, X: Array, Z: Array, scale: float = 1.0) -> Array:
    """``e_k = log((H_k X)^-1 Z C_k^-1)`` as (rotation vector [rad], translation [m]), shape (N, 6);
    ``C_k``'s translation divided by ``scale`` first."""
    Ci = inverse(C)
    if scale != 1.0:
        Ci[:, :3, 3] /= scale
    E = inverse(H @ X) @ Z @ Ci
    return np.hstack([rotvec_from_matrix(E[:, :3, :3]), E[:, :3, 3]])


def _mismatch(H: Array, C: Array, X: Array, Z: Array, scale: float = 1.0) -> Array:
    """Camera-pose mismatch per pose [m]: position plus angle times the camera-target distance."""
    e = pose_residuals(H, C, X, Z, scale)
    reach = float(np.median(np.linalg.norm(C[:, :3, 3], axis=1))) / scale
    return np.linalg.norm(e[:, 3:], axis=1) + reach * np.linalg.norm(e[:, :3], axis=1)


def _translations_and_scale(
    H: Array, C: Array, R_X: Array, R_Z: Array
) -> tuple[Array, Array, float]:
    """Least squares of ``R_H t_X - t_Z - lam R_Z t_B = -t_H`` (``B = C^-1``, ``lam = 1/s``)."""
    B = inverse(C)
    n = len(H)
    M = np.zeros((n, 3, 7))
    M[:, :, :3] = H[:, :3, :3]
    M[:, :, 3:6] = -np.eye(3)
    M[:, :, 6] = -B[:, :3, 3] @ R_Z.T
    w = np.linalg.lstsq(M.reshape(-1, 7), -H[:, :3, 3].reshape(-1), rcond=None)[0]
    lam = float(w[6]) if abs(w[6]) > 1e-12 else 1.0
    return np.asarray(w[:3], float), np.asarray(w[3:6], float), 1.0 / lam


def _closed_forms(H: Array, C: Array, estimate_scale: bool):  # type: ignore[no-untyped-def]
    """Starts ``(name, X, Z, scale)`` of the closed forms."""
    B = inverse(C)
    closed: list[tuple[str, Callable[[], tuple[Array, Array]]]] = [
        ("kronecker", lambda: solve_kronecker(H, B)),
        ("kronecker_mm", lambda: solve_kronecker(H, B, length_unit=1e-3)),
        ("dual_quaternion", lambda: solve_dual_quaternion(H, B)),
        ("park_martin", lambda: _park_martin(H, C)),
    ]
    for name, solve in closed:
        try:
            X, Z = solve()
        except (np.linalg.LinAlgError, ValueError, ArithmeticError):
            continue
        if np.all(np.isfinite(X)) and np.all(np.isfinite(Z)):
            yield _with_scale(name, H, C, X, Z, estimate_scale)


def _triples(H: Array, C: Array, estimate_scale: bool, rng: np.random.Generator):  # type: ignore[no-untyped-def]
    """Starts ``(name, X, Z, scale)`` of Kronecker on :data:`TRIPLES` random triples of poses."""
    B = inverse(C)
    for _ in range(TRIPLES):
        k = rng.choice(len(H), size=3, replace=False)
        try:
            X, Z = solve_kronecker(H[k], B[k])
        except np.linalg.LinAlgError:
            continue
        if np.all(np.isfinite(X)) and np.all(np.isfinite(Z)):
            yield _with_scale("triple", H, C, X, Z, estimate_scale)


def _park_martin(H: Array, C: Array) -> tuple[Array, Array]:
    A, Bm = relative_motions(H, C)
    X = solve_park_martin(A, Bm)
    return X, target_from_x(H, C, X)


def _with_scale(
    name: str, H: Array, C: Array, X: Array, Z: Array, estimate_scale: bool
) -> tuple[str, Array, Array, float]:
    if not estimate_scale:
        return name, X, Z, 1.0
    t_X, t_Z, s = _translations_and_scale(H, C, X[:3, :3], Z[:3, :3])
    return name, homogeneous(X[:3, :3], t_X), homogeneous(Z[:3, :3], t_Z), s if s > 0 else 1.0


def _best_start(
    H: Array, C: Array, estimate_scale: bool, rng: np.random.Generator
) -> tuple[str, Array, Array, float, Array]:
    """The start with the lowest :data:`START_QUANTILE` of the mismatch, and its mismatch: the
    closed forms and Kronecker on pose triples."""
    best: tuple[str, Array, Array, float, Array] | None = None
    best_score = np.inf

    def consider(starts) -> None:  # type: ignore[no-untyped-def]
        nonlocal best, best_score
        for name, X, Z, s in starts:
            m = _mismatch(H, C, X, Z, s)
            score = float(np.quantile(m, START_QUANTILE))
            if score < best_score:
                best, best_score = (name, X, Z, s, m), score

    consider(_closed_forms(H, C, estimate_scale))
    if len(H) >= MIN_POSES_FOR_TRIPLES:
        consider(_triples(H, C, estimate_scale, rng))
    if best is None:
        raise np.linalg.LinAlgError("no closed form solved these poses")
    return best


def _exp(xi: Array) -> Array:
    """``exp`` of a twist (rotation vector, translation) to first order in the translation."""
    return homogeneous(matrix_from_rotvec(xi[:3]), xi[3:6])


def _adjoint(T: Array) -> Array:
    """Adjoint of poses (N, 4, 4) for twists ordered (rotation, translation), shape (N, 6, 6)."""
    R, p = T[:, :3, :3], T[:, :3, 3]
    out = np.zeros((len(T), 6, 6))
    out[:, :3, :3] = R
    out[:, 3:, 3:] = R
    out[:, 3:, :3] = skew(p) @ R
    return out


def _jacobian(H: Array, C: Array, X: Array, Z: Array, s: float, with_scale: bool) -> Array:
    """d e_k / d(dx, dz[, log s]) for ``X exp(dx)``, ``Z exp(dz)``, ``s exp(ds)``: (N, 6, 12|13).

    ``E_k = (H_k X)^-1 Z C_k^-1`` moves by ``-Ad(E_k^-1) dx + Ad(C_k) dz`` (right perturbation);
    near the solution ``e_k = log E_k`` moves by the same, to first order in the residual.
    """
    Ci = inverse(C)
    if s != 1.0:
        Ci[:, :3, 3] /= s
    E = inverse(H @ X) @ Z @ Ci
    J = np.zeros((len(H), 6, 13 if with_scale else 12))
    J[:, :, :6] = -_adjoint(inverse(E))
    J[:, :, 6:12] = _adjoint(inverse(Ci))
    if with_scale:  # t(C^-1) / s: the right perturbation (0, -R^T t / s) per unit of log s
        J[:, 3:, 12] = -np.einsum("kji,kj->ki", Ci[:, :3, :3], Ci[:, :3, 3])
    return J


def _camera_map(C: Array, s: float) -> Array:
    """Per pose, the camera-frame twist (rotation, translation) of a target-pose error made of a
    rotation ``dr`` about the target's origin (target axes) and a shift ``dt`` (camera axes):
    ``(R dr, dt + t x R dr)``, shape (N, 6, 6)."""
    R, t = C[:, :3, :3], C[:, :3, 3] / s
    G = np.zeros((len(C), 6, 6))
    G[:, :3, :3] = R
    G[:, 3:, :3] = skew(t) @ R
    G[:, 3:, 3:] = np.eye(3)
    return G


def _pose_covariances(theta: Array, A: Array, G: Array) -> Array:
    """``S_k = A diag(hand) A^T + G_k diag(camera) G_k^T``, shape (N, 6, 6); ``theta`` holds the
    log standard deviations of :data:`NOISE_GROUPS`."""
    v = np.exp(2.0 * theta[NOISE_GROUPS])
    hand = (A * v[:6]) @ A.T
    S = hand + np.einsum("kij,j,klj->kil", G, v[6:], G)
    return S + (1e-30 + 1e-12 * np.trace(S, axis1=1, axis2=2))[:, None, None] * np.eye(6)


def _noise_fit(e: Array, A: Array, G: Array, theta: Array) -> Array:
    """Maximum likelihood of the noise ``theta`` given the residuals ``e`` (N, 6); below
    :data:`MIN_POSES_PER_NOISE` poses per parameter, one rotation and one translation level
    (:data:`FEW_POSES_TIES`) for all eight."""
    M = np.concatenate([np.broadcast_to(A, G.shape), G], axis=2)  # (N, 6, 12): noise columns
    ties = np.arange(8) if len(e) >= MIN_POSES_PER_NOISE * 8 else FEW_POSES_TIES

    def nll(free: Array) -> tuple[float, Array]:
        th = free[ties]
        S = _pose_covariances(th, A, G)
        Si_e = np.linalg.solve(S, e[:, :, None])[:, :, 0]
        Si_M = np.linalg.solve(S, M)
        q = np.einsum("kai,ka->ki", M, Si_e)  # d(e^T S^-1 e)/d v_j = -q_j^2
        trace = np.einsum("kai,kai->ki", M, Si_M)  # d log det S / d v_j
        value = float(np.sum(e * Si_e) + np.linalg.slogdet(S)[1].sum())
        per_column = 2.0 * np.exp(2.0 * th[NOISE_GROUPS]) * (trace - q * q).sum(axis=0)
        per_theta = np.bincount(NOISE_GROUPS, per_column, minlength=8)
        return value, np.bincount(ties, per_theta, minlength=int(ties.max()) + 1).astype(float)

    # each level within [1e-3, 20] times the residuals' robust scale (its kind: rotation or
    # translation): no level collapses to zero for good, none absorbs a gross outlier
    scale = 1.4826 * np.array([np.median(np.abs(e[:, :3])), np.median(np.abs(e[:, 3:]))])
    kind = np.array([0, 1, 0, 0, 0, 1, 1, 1])  # rotation or translation, per level
    free = [int(np.flatnonzero(ties == k)[0]) for k in range(int(ties.max()) + 1)]
    lo = np.log(1e-3 * scale[kind[free]] + 1e-15)
    hi = np.log(20.0 * scale[kind[free]] + 1e-14)
    start = np.array([theta[ties == k].mean() for k in range(len(free))])
    sol = minimize(
        nll,
        np.clip(start, lo, hi),
        jac=True,
        method="L-BFGS-B",
        bounds=list(zip(lo, hi, strict=True)),
    )
    return np.asarray(sol.x)[ties]


def _start_noise(e: Array) -> Array:
    """Half of the residuals' rotation and translation variance to each source: the noise fit's
    start."""
    rot, trans = (np.sqrt(0.5 * np.mean(e[:, k : k + 3] ** 2)) + 1e-12 for k in (0, 3))
    return np.log([rot, trans, rot, rot, rot, trans, trans, trans])


def _gauss_newton(
    H: Array, C: Array, X: Array, Z: Array, s: float, W: Array, with_scale: bool
) -> tuple[Array, Array, float, Array]:
    """Gauss-Newton on ``sum |W_k e_k|^2``: ``(X, Z, s, normal matrix)``. Directions the poses
    do not determine (a singular normal matrix) keep their start (minimum-norm steps)."""
    normal = np.eye(13 if with_scale else 12)
    for _ in range(_MAX_STEPS):
        J = W @ _jacobian(H, C, X, Z, s, with_scale)
        r = np.einsum("kab,kb->ka", W, pose_residuals(H, C, X, Z, s))
        normal = np.einsum("kai,kaj->ij", J, J)
        step = -np.linalg.lstsq(normal, np.einsum("kai,ka->i", J, r), rcond=1e-12)[0]
        step *= min(1.0, _MAX_STEP / np.abs(step).max())  # far from the solution: smaller steps
        X, Z = X @ _exp(step[:6]), Z @ _exp(step[6:12])
        s = s * float(np.exp(step[12])) if with_scale else s
        if np.abs(step).max() < 1e-13:
            break
    return X, Z, s, normal


def _gls(
    H: Array, C: Array, X: Array, Z: Array, s: float, theta: Array, with_scale: bool
) -> tuple[Array, Array, float, Array, Array]:
    """Alternate the noise's and the solution's maximum likelihood on these poses:
    ``(X, Z, s, theta, normal matrix)``."""
    normal = np.eye(13 if with_scale else 12)
    for _ in range(_MAX_GLS):
        A, G = _adjoint(inverse(X)[None])[0], _camera_map(C, s)
        new = _noise_fit(pose_residuals(H, C, X, Z, s), A, G, theta)
        done = np.abs(new - theta).max() < 1e-5
        theta = new
        W = np.linalg.inv(np.linalg.cholesky(_pose_covariances(theta, A, G)))
        X, Z, s, normal = _gauss_newton(H, C, X, Z, s, W, with_scale)
        if done:
            break
    return X, Z, s, theta, normal


def _selection_factor(h: float) -> float:
    """Covariance of a Gaussian sample kept below its ``h`` chi-square quantile (6 dof), times
    this factor, is the whole sample's (the minimum covariance determinant's consistency factor)."""
    return 1.0 if h >= 1.0 else h / float(chi2.cdf(chi2.ppf(h, 6), 8))


def _distances(
    H: Array,
    C: Array,
    X: Array,
    Z: Array,
    s: float,
    theta: Array,
    cov: Array,
    keep: NDArray[np.bool_],
    h: float,
    with_scale: bool,
) -> Array:
    """Squared Mahalanobis distance of every pose's residual, shape (N,): against the noise
    (unbiased: times ``6n / (6n - unknowns)``, and corrected for a selection by
    :func:`_selection_factor`) less what the fit absorbs of a kept pose (its leverage, kept below
    0.95 per direction), or plus the fit's uncertainty for a pose it did not use."""
    n_par = cov.shape[0]
    factor = _selection_factor(h) * 6 * keep.sum() / max(6 * keep.sum() - n_par, 1)
    S = _pose_covariances(theta, _adjoint(inverse(X)[None])[0], _camera_map(C, s)) * factor
    W = np.linalg.inv(np.linalg.cholesky(S))
    WJ = W @ _jacobian(H, C, X, Z, s, with_scale)
    hat = WJ @ (cov * factor) @ np.swapaxes(WJ, 1, 2)  # (N, 6, 6), eigenvalues in [0, 1] if kept
    lam, V = np.linalg.eigh(np.where(keep[:, None, None], -hat, hat))
    lam = np.maximum(1.0 + lam, 0.05)
    u = np.einsum("kji,kj->ki", V, np.einsum("kab,kb->ka", W, pose_residuals(H, C, X, Z, s)))
    return np.sum(u * u / lam, axis=1)


def solve_likelihood(
    T_base_hand: Array, T_camera_target: Array, *, estimate_scale: bool = False, seed: int = 0
) -> LikelihoodFit:
    """Maximum likelihood of ``X = T_hand_camera`` and ``Z = T_base_target`` (module docstring).

    Args:
        T_base_hand: Hand poses in the base frame, shape (N, 4, 4) [m], N >= 3.
        T_camera_target: Target poses in the camera frame, shape (N, 4, 4) [m].
        estimate_scale: The target translations are known up to one unknown factor.
        seed: Seed of the random pose triples of the start.
    """
    H, C = np.asarray(T_base_hand, float), np.asarray(T_camera_target, float)
    n = len(H)
    start, X, Z, s, m = _best_start(H, C, estimate_scale, np.random.default_rng(seed))
    # a heavy tail (the start's 90th percentile mismatch over TAIL_RATIO times its median: poses
    # it cannot explain): the fit starts on the half the start explains best
    med, mad = np.median(m), 1.4826 * np.median(np.abs(m - np.median(m)))
    heavy = n >= MIN_POSES_FOR_TRIPLES and (
        np.quantile(m, 0.9) > TAIL_RATIO * med or m.max() > med + GROSS_MADS * mad
    )
    keep = m <= np.quantile(m, 0.5) if heavy else np.ones(n, bool)
    h = 0.5 if heavy else 1.0
    limit = chi2.ppf(OUTLIER_PROBABILITY, 6)
    cov = np.full((12, 12), np.nan)
    for _ in range(_MAX_ROUNDS):
        theta = _start_noise(pose_residuals(H[keep], C[keep], X, Z, s))  # fresh for each set
        X, Z, s, theta, normal = _gls(H[keep], C[keep], X, Z, s, theta, estimate_scale)
        cov = np.asarray(np.linalg.pinv(normal), dtype=float)
        new = _distances(H, C, X, Z, s, theta, cov, keep, h, estimate_scale) <= limit
        if new.sum() < max(3, n // 2) or np.array_equal(new, keep):
            break
        keep, h = new, OUTLIER_PROBABILITY
    # what the poses leave undetermined, from fixed weights (the noise fit's cannot be trusted
    # there): rotations in metres at the camera-target distance
    J = _jacobian(H[keep], C[keep], X, Z, s, estimate_scale)
    J[:, :3] *= float(np.median(np.linalg.norm(C[keep, :3, 3], axis=1))) / s
    lam, V = np.linalg.eigh(np.einsum("kai,kaj->ij", J, J))
    null = V[:, lam <= UNDETERMINED * lam.max()].T
    e = pose_residuals(H[keep], C[keep], X, Z, s)
    if keep.sum() >= MIN_POSES_FOR_TRIPLES and drift_correlation(e) > DRIFT_CORRELATION:
        # a drifting target trajectory: X's rotation from consecutive motions (nearly free of the
        # drift), its translation and the scale from the poses, Z from both
        X_motions, _, cov_motions = _fit_motions(H[keep], C[keep], X, s, estimate_scale)
        X = homogeneous(X_motions[:3, :3], X[:3, 3])
        Ci = inverse(C[keep])
        Ci[:, :3, 3] /= s
        Z = mean_pose(H[keep] @ X @ inverse(Ci))
        cov[:3, :3] = cov_motions[:3, :3]
        start += "; X's rotation from consecutive motions (drift)"
    return LikelihoodFit(X, Z, s, keep, np.exp(theta), cov, start, null)


def drift_correlation(e: Array) -> float:
    """Lag-one autocorrelation of time-ordered residuals (N, 6), each component centred and
    scaled, averaged over the components: near 0 for independent noise, near 1 for a drift."""
    z = (e - e.mean(axis=0)) / (e.std(axis=0) + 1e-300)
    return float(np.mean(z[1:] * z[:-1]))


def _motion_residuals(A: Array, B: Array, X: Array, s: float) -> Array:
    """``log((A_i X)^-1 X B_i)`` of consecutive motions, ``B``'s translation divided by ``s``."""
    Bm = B.copy()
    Bm[:, :3, 3] /= s
    E = inverse(A @ X) @ X @ Bm
    return np.hstack([rotvec_from_matrix(E[:, :3, :3]), E[:, :3, 3]])


def _fit_motions(
    H: Array, C: Array, X: Array, s: float, with_scale: bool
) -> tuple[Array, float, Array]:
    """X (and the scale) from consecutive motions ``A X = X B``, weighted by their residuals'
    covariance (iterated): a drifting target trajectory (visual odometry) leaves consecutive
    motions nearly unbiased where absolute poses are not. Returns ``(X, s, covariance)``."""
    A = inverse(H[1:]) @ H[:-1]
    B = C[1:] @ inverse(C[:-1])
    W = np.eye(6)
    cov = np.full((7, 7), np.nan)
    for _ in range(_MOTION_ROUNDS):

        def fun(p: Array, X0: Array = X, s0: float = s, W: Array = W) -> Array:
            sp = s0 * float(np.exp(p[6])) if with_scale else s0
            return (_motion_residuals(A, B, X0 @ _exp(p[:6]), sp) @ W.T).ravel()

        sol = least_squares(fun, np.zeros(7 if with_scale else 6), method="lm")
        X = X @ _exp(sol.x[:6])
        s = s * float(np.exp(sol.x[6])) if with_scale else s
        e = _motion_residuals(A, B, X, s)
        S = e.T @ e / len(e) + (1e-30 + 1e-12 * float(np.sum(e * e)) / len(e)) * np.eye(6)
        W = np.linalg.inv(np.linalg.cholesky(S))
        cov = np.asarray(np.linalg.pinv(sol.jac.T @ sol.jac), dtype=float)
    return X, s, cov


def solve_xz(T_base_hand: Array, T_camera_target: Array) -> tuple[Array, Array]:
    """:func:`solve_likelihood`'s ``(X, Z)``, the registry's solver form."""
    fit = solve_likelihood(T_base_hand, T_camera_target)
    return fit.X, fit.Z


__all__ = [
    "MIN_POSES_FOR_TRIPLES",
    "DRIFT_CORRELATION",
    "FEW_POSES_TIES",
    "GROSS_MADS",
    "MIN_POSES_PER_NOISE",
    "NOISE_GROUPS",
    "OUTLIER_PROBABILITY",
    "START_QUANTILE",
    "TAIL_RATIO",
    "TRIPLES",
    "UNDETERMINED",
    "LikelihoodFit",
    "drift_correlation",
    "pose_residuals",
    "solve_likelihood",
    "solve_xz",
]
