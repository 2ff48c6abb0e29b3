"""One-stage calibration: maximum likelihood of the whole head on the board's corners in pixels.

:func:`fit_pixels` is a bundle adjustment over the joints' geometry, the camera mounts and the
board's pose (its placement on the robot when held), optionally the intrinsics, of
:class:`~cpc2urdf.identification.selfcal.pixel_problem.PixelProblem`:

1. **Undetermined directions** (a joint that never moved, joints shared by the camera's and a held
   board's paths, the rigid motion of everything when only relative poses are seen) are found
   from the column-scaled Jacobian's singular values at the start (the stage-1 rank rule,
   :data:`~cpc2urdf.identification.kinematics.identifiability.RANK_TOL`). Per direction, the
   parameter it moves most (pivoted QR) stays at the start's value (the user's URDF) and is
   named; the fit moves the others, which absorb what it would have changed.
2. **Levenberg-Marquardt** (:func:`~cpc2urdf.identification.kinematics.refine.solve_least_squares`)
   on the corners weighted by each image's corner noise.
3. **Noise**: each image has its own corner noise (blur, distance and angle change it): its
   residuals' scale, shrunk towards its camera's median by :data:`PRIOR_COORDINATES`
   coordinates' weight; the corners are weighted by it. Robust (MAD) in the rounds, maximum
   likelihood with the fit's degrees of freedom at the end.
4. **Outliers**: an image whose corners are :data:`IMAGE_NOISE_FACTOR` times noisier than its
   camera's typical image (blurred, moving), or with more than a third of its corners off (the
   board misdetected), is dropped whole; a corner is dropped beyond the chi-square(2) quantile
   of its image's noise at which a clean data set loses one with probability
   :data:`CORNER_ALPHA`. The chart is re-centred and the fit repeated until nothing more is
   dropped. Each is named.
5. **Covariance**: ``(J^T J)^+`` in the determined subspace, the Cramér-Rao bound of the pixel
   model at the estimate.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import qr

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.kinematics.identifiability import (
    RANK_TOL,
    ZERO_COLUMN,
    scaled_svd,
    triangular_factor,
)
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.refine import solve_least_squares
from cpc2urdf.identification.selfcal.pixel_problem import (
    CameraModel,
    PixelData,
    PixelProblem,
)
from cpc2urdf.model import BASE, CPCModel
from cpc2urdf.transforms import Array

CORNER_ALPHA = 1e-3  # a clean data set loses a good corner with this probability
IMAGE_NOISE_FACTOR = 4.0  # an image whose corners are this much noisier than its camera's goes
PRIOR_COORDINATES = 10.0  # an image's noise is its own, shrunk towards its camera's by this weight
IMAGE_DROPPED_SHARE = 1.0 / 3.0  # above this share of dropped corners the whole image goes
MAX_ROUNDS = 5
MIN_SIGMA = 1e-3  # [px] no detector is better; keeps noise-free data well-conditioned
MAX_NFEV = 100


@dataclass
class PixelFit:
    """What :func:`fit_pixels` found.

    Attributes:
        model: The calibrated model (world = the board when fixed, else the start's world).
        cameras: Camera -> intrinsics (refined when asked, else as given).
        sigma: Camera -> corner noise per pixel coordinate [px] (RMS over its images).
        view_sigma: Per view, its corner noise [px] (ML, shrunk towards its camera's), shape
            (n_views,); NaN for views not used.
        chart: Chart centred on ``model``; ``x`` below are its coordinates then the intrinsics'.
        names: Parameter names, chart first.
        covariance: Of all parameters, shape (P, P) [m, rad, px]; zero for ``undetermined``.
        null_space: Directions the images do not determine, shape (P, k), unit columns.
        undetermined: One parameter per such direction, kept at the start's value (the one the
            direction moves most); the others absorb what it would have changed.
        outliers: Dropped images and corners, each a sentence.
        use: Per view, the corners used, shape (k,) booleans.
        view_rms: Per view name (``camera/record``), the RMS residual of its used corners [px].
        corners: Corners used.
        rounds: Outlier rounds.
        seconds: Time of the fit [s].
        board_scale: The board's scale the images say (1 unless refined).
    """

    model: CPCModel
    cameras: dict[str, CameraModel]
    sigma: dict[str, float]
    view_sigma: Array
    chart: Parametrization
    names: list[str]
    covariance: Array
    null_space: Array
    undetermined: list[str]
    outliers: list[str]
    use: list[NDArray[np.bool_]]
    view_rms: dict[str, float]
    corners: int
    rounds: int
    seconds: float
    board_scale: float = 1.0
    notes: list[str] = field(default_factory=list)

    def chart_covariance(self) -> Array:
        """Covariance of the chart's parameters alone, shape (chart.n_params,) * 2."""
        P = self.chart.n_params
        return self.covariance[:P, :P]


class _Reduced:
    """A problem in its free parameters (the others stay 0)."""

    def __init__(self, problem: PixelProblem, free: NDArray[np.intp]) -> None:
        self.problem, self.free = problem, free

    def full(self, z: Array) -> Array:
        x = np.zeros(self.problem.n_params)
        x[self.free] = z
        return x

    def residuals(self, z: Array) -> Array:
        return self.problem.residuals(self.full(z))

    def jacobian(self, z: Array) -> Array:
        return self.problem.jacobian(self.full(z))[:, self.free]


def subspace(J: Array, prefer: Array | None = None) -> tuple[NDArray[np.intp], Array, Array]:
    """What ``J`` determines: the parameters to keep fixed (one per undetermined direction, the
    one each direction moves most, weighted by ``prefer`` (P,), by pivoted QR), the undetermined
    directions (P, k) (unit columns) and the covariance ``(J_free^T J_free)^-1`` embedded in
    (P, P), zero for the fixed.

    Directions by the column-scaled SVD and stage 1's rank rule (:func:`scaled_svd`, which
    zeroes a column at rounding level: a joint on both the camera's and a held board's paths).
    """
    d, s, Vt = scaled_svd(J)
    null = ~(s / (s[0] if s[0] > 0 else 1.0) >= RANK_TOL)
    fixed = np.zeros(0, dtype=np.intp)
    if null.any():
        w = np.ones(J.shape[1]) if prefer is None else prefer
        _, _, piv = qr(Vt[null] * w, pivoting=True, mode="economic")
        fixed = np.sort(piv[: int(null.sum())])
    free = np.setdiff1d(np.arange(J.shape[1]), fixed)
    R = triangular_factor(J[:, free] / d[free])
    Ri = np.linalg.inv(R) / d[free, None]
    cov = np.zeros((J.shape[1], J.shape[1]))
    cov[np.ix_(free, free)] = Ri @ Ri.T
    N = Vt[null].T / d[:, None]
    return fixed, N / np.maximum(np.linalg.norm(N, axis=0), 1e-300), cov


def _solve_round(problem: PixelProblem, prefer: Array) -> tuple[Array, Array, Array]:
    """Levenberg-Marquardt from ``x = 0`` with one parameter per undetermined direction held:
    the solution, those directions and the Jacobian's column norms at the start."""
    J = problem.jacobian(np.zeros(problem.n_params))
    fixed, N, _ = subspace(J, prefer)
    reduced = _Reduced(problem, np.setdiff1d(np.arange(problem.n_params), fixed))
    sol = solve_least_squares(reduced, np.zeros(len(reduced.free)), MAX_NFEV)
    return reduced.full(sol.x), N, np.linalg.norm(J, axis=0)


def _closest_to_start(
    model: CPCModel,
    scale: float,
    chart: Parametrization,
    N: Array,
    norms: Array,
    prefer: Array,
    scaled: bool,
) -> tuple[CPCModel, float]:
    """``model`` (and the board's ``scale`` when ``scaled``) moved along the start's undetermined
    directions ``N`` to the point closest to the start (the user's model) in the column-scaled
    metric weighted by ``prefer``: what the images cannot tell changes as little as the fit
    allows (to first order the fit is the same). A free board scale is so settled by the
    user's lengths. Directions that move the intrinsics are left as they are."""
    P = chart.n_params
    rows = np.r_[np.arange(P), [N.shape[0] - 1] if scaled else []].astype(int)
    other = np.setdiff1d(np.arange(N.shape[0]), rows)
    N = N[:, np.abs(N[other]).max(axis=0, initial=0.0) < 1e-12][rows] if N.size else N[rows]
    if not N.size:
        return model, scale
    try:
        x = np.r_[chart.vector_from_model(model), [scale - 1.0] if scaled else []]
    except DegenerateDataError:  # the fit went far from the start: the gate will say so
        return model, scale
    n = norms[rows]
    w = np.where(n > ZERO_COLUMN * norms.max(), n, norms.max()) * prefer[rows]
    c, *_ = np.linalg.lstsq(w[:, None] * N, w * x, rcond=None)
    x = x - N @ c
    return chart.model_from_vector(x[:P]), (1.0 + x[-1]) if scaled else scale


def _keep_first(problem: PixelProblem, data: PixelData) -> Array:
    """Which parameter an undetermined direction keeps at the user's value: a joint the records
    never move first; last, what is not the user's: a held board's placement, the board's
    scale, and (a fixed board) the first joints' lines, which place the robot in the board's
    world."""
    s = problem.chart.reference.structure
    still = {j for i, j in enumerate(s.joint_names) if np.ptp(data.q[:, i]) == 0.0}
    placing = {j.name for j in s.joints if j.parent == BASE and data.board_frame is None}
    owner = [n.rsplit(".", 1)[0] for n in problem.names()]
    cheap = {data.board_frame, *placing}
    w = [1e6 if o in still else 0.01 if o in cheap else 1.0 for o in owner]
    return np.array(w[:-1] + [0.01] if problem.scaled else w)


def _view_sigma(r: dict[int, Array], data: PixelData, dof_share: float) -> Array:
    """Per view, its corner noise [px]: the view's own scale (MAD in rounds, ML with the fit's
    degrees of freedom shared, ``dof_share`` of each coordinate, at the end) shrunk towards its
    camera's median by :data:`PRIOR_COORDINATES` coordinates' weight; NaN for unused views."""
    own = np.full(len(data.views), np.nan)
    n = np.zeros(len(data.views))
    for k, rk in r.items():
        v = rk.ravel()
        n[k] = v.size
        if dof_share < 0:
            own[k] = 1.4826 * float(np.median(np.abs(v)))
        else:
            own[k] = float(np.sqrt(v @ v / max(v.size * (1.0 - dof_share), 1.0)))
    out = np.full(len(data.views), np.nan)
    for c in data.cameras:
        ks = [k for k in r if data.views[k].camera == c]
        if ks:
            m = float(np.median(own[ks]))
            out[ks] = np.sqrt(
                (n[ks] * own[ks] ** 2 + PRIOR_COORDINATES * m**2) / (n[ks] + PRIOR_COORDINATES)
            )
    return np.maximum(out, MIN_SIGMA)


def camera_sigma(data: PixelData, sigma: Array, use: list[NDArray[np.bool_]]) -> dict[str, float]:
    """Per camera, the RMS of its used views' corner noise [px]."""
    out = {}
    for c in data.cameras:
        ks = [k for k, v in enumerate(data.views) if v.camera == c and use[k].any()]
        if ks:
            out[c] = float(np.sqrt(np.mean(sigma[ks] ** 2)))
    return out


def _new_outliers(
    data: PixelData, use: list[NDArray[np.bool_]], r: dict[int, Array], sigma: Array
) -> list[str]:
    """Drop (in ``use``) the corners and images the tests reject; their descriptions."""
    from scipy.special import chdtri

    corner_limit = float(chdtri(2, CORNER_ALPHA / max(sum(len(rk) for rk in r.values()), 1)))
    own = {k: 1.4826 * float(np.median(np.abs(rk))) for k, rk in r.items()}
    typical = {
        c: float(np.median([s for k, s in own.items() if data.views[k].camera == c] or [np.nan]))
        for c in data.cameras
    }
    out = []
    for k, rk in r.items():
        v = data.views[k]
        name = data.view_name(k)
        if own[k] > IMAGE_NOISE_FACTOR * max(typical[v.camera], MIN_SIGMA):
            use[k][:] = False
            out.append(
                f"image {name}: corners {own[k]:.2g} px off (typical {typical[v.camera]:.2g} px for "
                "this camera): blurred, moving, or the board misdetected; dropped"
            )
            continue
        idx = np.flatnonzero(use[k])
        d2 = (rk**2).sum(1) / sigma[k] ** 2
        bad = d2 > corner_limit
        if bad.sum() + (len(v.ids) - len(idx)) > IMAGE_DROPPED_SHARE * len(v.ids):
            use[k][:] = False
            out.append(
                f"image {name}: {int(bad.sum())} of {len(idx)} corners off by more than "
                f"{np.sqrt(corner_limit) * sigma[k]:.2g} px: the board misdetected; dropped"
            )
            continue
        for i in np.flatnonzero(bad):
            use[k][idx[i]] = False
            out.append(
                f"corner {int(v.ids[idx[i]])} of image {name}: off by "
                f"{np.sqrt(d2[i]) * sigma[k]:.2g} px (noise {sigma[k]:.2g} px); dropped"
            )
    return out


def fit_pixels(
    start: CPCModel,
    data: PixelData,
    *,
    intrinsics: bool = False,
    board_scale: bool = False,
    sigma: dict[str, float] | None = None,
) -> PixelFit:
    """The one-stage fit of ``data`` from ``start`` (module docstring).

    Args:
        start: A model with every camera frame of ``data`` (and the board's frame when held),
            placed in the board's world when the board is fixed.
        data: The images' corners.
        intrinsics: Refine each camera's ``fx, fy, cx, cy, k1, k2`` too.
        board_scale: Refine the board's scale too (a wrong square size).
        sigma: Starting corner noise per camera [px] (default 0.5).

    Every round's outliers are judged on a robust noise scale; the result's noise is the ML one.
    """
    t0 = time.perf_counter()
    frames = list(data.cameras) + ([data.board_frame] if data.board_frame else [])
    use = [np.ones(len(v.ids), dtype=bool) for v in data.views]
    sig = np.array([(sigma or {}).get(v.camera, 0.5) for v in data.views])
    model, cur = start, data
    prefer = _keep_first(
        PixelProblem(Parametrization(model, frames), cur, use, sig, intrinsics, board_scale), data
    )
    outliers: list[str] = []
    rounds, scale = 0, 1.0

    def problem_at(model: CPCModel, sig: Array) -> PixelProblem:
        return PixelProblem(Parametrization(model, frames), cur, use, sig, intrinsics, board_scale)

    first: tuple[Parametrization, Array, Array] | None = None
    while rounds < MAX_ROUNDS:
        rounds += 1
        problem = problem_at(model, sig)
        x, N, norms = _solve_round(problem, prefer)
        first = first or (problem.chart, N, norms)
        model = problem.chart.model_from_vector(x[: problem.chart.n_params])
        r = problem.pixel_residuals(x)
        if board_scale:
            scale *= 1.0 + x[-1]
        cur = replace(
            data, cameras=problem.camera_models(x), board_points=data.board_points * scale
        )
        sig = _view_sigma(r, data, -1.0)
        more = _new_outliers(data, use, r, sig)
        outliers += more
        if not more:
            break
    assert first is not None
    # What the images cannot tell: closest to the start; then the rest refitted (also after the
    # last round's outliers).
    model, scale = _closest_to_start(model, scale, *first, prefer, board_scale)
    cur = replace(cur, board_points=data.board_points * scale)
    problem = problem_at(model, sig)
    x, N, _ = _solve_round(problem, prefer)
    model = problem.chart.model_from_vector(x[: problem.chart.n_params])
    scale *= 1.0 + x[-1] if board_scale else 1.0
    cur = replace(cur, cameras=problem.camera_models(x), board_points=data.board_points * scale)
    r = problem.pixel_residuals(x)  # the refitted model's: its chart's x = 0 below
    rank = problem.n_params - N.shape[1]
    problem = problem_at(
        model, _view_sigma(r, data, rank / (2.0 * sum(len(v) for v in r.values())))
    )
    x0 = np.zeros(problem.n_params)
    fixed, N, cov = subspace(problem.jacobian(x0), prefer)
    names = problem.names()
    undetermined = [names[i] for i in fixed]
    r = problem.pixel_residuals(x0)
    sig = problem.sigma
    cams = cur.cameras
    return PixelFit(
        model=model,
        cameras=cams,
        sigma=camera_sigma(data, sig, use),
        view_sigma=sig,
        chart=problem.chart,
        names=names,
        covariance=cov,
        null_space=N,
        undetermined=undetermined,
        outliers=outliers,
        use=use,
        view_rms={data.view_name(k): float(np.sqrt((rk**2).sum(1).mean())) for k, rk in r.items()},
        corners=sum(len(v) for v in r.values()),
        rounds=rounds,
        seconds=time.perf_counter() - t0,
        board_scale=scale,
    )


__all__ = [
    "CORNER_ALPHA",
    "IMAGE_NOISE_FACTOR",
    "PixelFit",
    "camera_sigma",
    "fit_pixels",
    "subspace",
]
