"""Planning a one-stage calibration: where the head's cameras see the board, and how well.

For a head calibrated by its own cameras (:mod:`~cpc2urdf.identification.selfcal`), which joint
configurations should be recorded? Those where every camera sees the whole board, chosen to
minimise the predicted error of the camera poses relative to the board.

- **Candidates**: configurations uniform in the calibration ranges, kept where every camera sees
  the whole board on the nominal model with planning margins (:mod:`pixel_setup`).
- **Information**: per candidate, ``J_i^T J_i`` of :class:`~cpc2urdf.identification.selfcal.
  pixel_problem.PixelProblem` at the nominal model with the exact corners (``cv2.projectPoints``)
  and ``sigma`` px per coordinate, kept as a square-root factor of ``6 x cameras`` rows (a view's
  pixels depend on the parameters only through the camera's pose relative to the board).
- **Prediction**: ``C`` = the inverse of the summed information in its determined subspace
  (:func:`~cpc2urdf.identification.selfcal.bundle.subspace`, the fit's own covariance; what the
  images cannot tell is held, and the camera poses' variance does not depend on how, as long as
  they are determined); at held-out configurations, each camera's pose in the board frame (for
  a held board: relative to the board) moves by ``G x``
  (:meth:`Parametrization.pose_jacobian`), so its predicted RMS position error is
  ``sqrt(mean_q trace(G_p C G_p^T))`` [m] and rotation error ``sqrt(mean_q trace(G_r C G_r^T))``
  [rad] (:func:`predicted_camera_pose_error`); ``inf`` where the pose moves along an undetermined
  direction.
- **Selection**: I-optimal, ``trace(A C)`` with ``A = mean_q sum_cameras (G_p^T G_p + L^2 G_r^T G_r)``
  (``L`` = :data:`ROTATION_LENGTH` m/rad), by :func:`~cpc2urdf.identification.planning.optimal.select`
  (greedy, then Fedorov exchange) in the candidates' determined subspace.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError, DegenerateDataError
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.planning.optimal import select
from cpc2urdf.identification.planning.pixel_setup import (
    PixelSetup,
    board_seen,
    draw_configurations,
)
from cpc2urdf.identification.selfcal.bundle import subspace
from cpc2urdf.identification.selfcal.pixel_problem import BoardView, PixelData, PixelProblem
from cpc2urdf.transforms import Array

ROTATION_LENGTH = 0.1  # [m/rad] weight of the rotation error in the I-criterion
UNDETERMINED_TOL = 1e-6  # [-] a pose moving along a free direction by this share of its scale


@dataclass
class CameraPoseError:
    """Predicted RMS error of each camera's pose in the board's frame over held-out configurations.

    Attributes:
        position: Camera -> RMS position error [m] (``inf``: undetermined).
        rotation: Camera -> RMS rotation error [rad].
        rank: Determined parameters.
        n_params: Parameters of the chart.
    """

    position: dict[str, float]
    rotation: dict[str, float]
    rank: int
    n_params: int

    @property
    def position_rms(self) -> float:
        """Over the cameras [m]."""
        return float(np.sqrt(np.mean(np.square(list(self.position.values())))))

    @property
    def rotation_rms(self) -> float:
        """Over the cameras [rad]."""
        return float(np.sqrt(np.mean(np.square(list(self.rotation.values())))))

    def to_json(self) -> dict[str, Any]:
        def fin(v: float, s: float) -> float | None:
            return v * s if math.isfinite(v) else None

        deg = math.degrees(1.0)
        return {
            "camera_position_rms_mm": {c: fin(v, 1e3) for c, v in self.position.items()},
            "camera_rotation_rms_deg": {c: fin(v, deg) for c, v in self.rotation.items()},
            "position_rms_mm": fin(self.position_rms, 1e3),
            "orientation_rms_deg": fin(self.rotation_rms, deg),
            "rank": self.rank,
            "n_params": self.n_params,
        }


def pixel_data(setup: PixelSetup, q: ArrayLike, seen: NDArray[np.bool_]) -> PixelData:
    """The exact corners of the views ``seen`` (N, cameras) at configurations ``q`` (N, n)."""
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    X = setup.board.object_points()
    T = setup.camera_board(qq)
    views = []
    for i, (c, cam) in enumerate(setup.cameras.items()):
        for r in np.flatnonzero(seen[:, i]):
            rvec, _ = cv2.Rodrigues(T[c][r][:3, :3])
            uv, _ = cv2.projectPoints(X, rvec, T[c][r][:3, 3], cam.K, cam.D)
            views.append(
                BoardView(c, int(r), np.arange(len(X)), np.asarray(uv, float).reshape(-1, 2))
            )
    labels = [f"config {r}" for r in range(len(qq))]
    return PixelData(qq, labels, views, dict(setup.cameras), X, setup.board_frame, "plan")


def _jacobian(setup: PixelSetup, q: Array, seen: NDArray[np.bool_]) -> tuple[Array, Array]:
    """Weighted pixel Jacobian of the views ``seen`` and each row's record."""
    data = pixel_data(setup, q, seen)
    use = [np.ones(len(v.ids), dtype=bool) for v in data.views]
    chart = Parametrization(setup.nominal, setup.frames)
    problem = PixelProblem(chart, data, use, np.full(len(data.views), setup.sigma))
    J = problem.jacobian(np.zeros(chart.n_params))
    rec = np.concatenate(
        [np.full(2 * len(data.views[k].ids), data.views[k].record) for k in problem.views]
    )
    return J, rec


def candidate_information(setup: PixelSetup, q: ArrayLike) -> Array:
    """Per configuration (every camera seeing the board), a square-root factor ``F_i`` of its
    information, ``F_i^T F_i = J_i^T J_i``, shape (N, m, P), ``m = min(P, 6 * cameras)``."""
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    P = Parametrization(setup.nominal, setup.frames).n_params
    m = min(P, 6 * len(setup.cameras))
    out = np.zeros((len(qq), m, P))
    for s in range(0, len(qq), 200):  # bounded memory
        chunk = qq[s : s + 200]
        J, rec = _jacobian(setup, chunk, np.ones((len(chunk), len(setup.cameras)), dtype=bool))
        for i in range(len(chunk)):
            _, sv, Vt = np.linalg.svd(J[rec == i], full_matrices=False)
            out[s + i] = sv[:m, None] * Vt[:m]
    return out


def relative_pose_jacobians(setup: PixelSetup, q: ArrayLike) -> dict[str, Array]:
    """Camera -> derivative of its pose in the board's frame w.r.t. the chart at configurations
    ``q``, shape (N, 6, P): rows 0-2 its origin [m], rows 3-5 its rotation vector [rad], both
    in the board's frame."""
    chart = Parametrization(setup.nominal, setup.frames)
    T, D = chart.pose_jacobian(np.zeros(chart.n_params), np.atleast_2d(np.asarray(q, dtype=float)))
    out = {}
    for c in setup.cameras:
        G = D[c].copy()
        if setup.board_frame is not None:
            Tb, Db = T[setup.board_frame], D[setup.board_frame]
            r = T[c][:, :3, 3] - Tb[:, :3, 3]  # dp_rel = dp_c - dp_b - w_b x r
            G[:, :3] -= Db[:, :3] - np.cross(r[:, :, None], Db[:, 3:], axis=1)
            G[:, 3:] -= Db[:, 3:]
            G[:, :3] = np.einsum("nji,njp->nip", Tb[:, :3, :3], G[:, :3])
            G[:, 3:] = np.einsum("nji,njp->nip", Tb[:, :3, :3], G[:, 3:])
        out[c] = G
    return out


def camera_pose_error(
    setup: PixelSetup, covariance: Array, q_heldout: ArrayLike, null_space: Array | None = None
) -> CameraPoseError:
    """RMS over ``q_heldout`` of each camera's predicted pose error for a chart ``covariance``
    (P, P), e.g. a plan's or a fit's (:meth:`PixelFit.chart_covariance`); ``inf`` where the pose
    moves along ``null_space`` (P, k)."""
    return _pose_error(relative_pose_jacobians(setup, q_heldout), covariance, null_space)


def _pose_error(
    G: dict[str, Array], covariance: Array, null_space: Array | None
) -> CameraPoseError:
    """:func:`camera_pose_error` from the held-out configurations' pose Jacobians ``G``."""
    pos, rot = {}, {}
    for c, Gc in G.items():
        v = np.einsum("nip,pq,niq->ni", Gc, covariance, Gc).mean(axis=0)
        p, r = float(np.sqrt(max(v[:3].sum(), 0.0))), float(np.sqrt(max(v[3:].sum(), 0.0)))
        if null_space is not None and null_space.size:
            moved = np.abs(Gc @ null_space).max(axis=(0, 2))
            scale = np.abs(Gc).max(axis=(0, 2)) + 1e-300
            if (moved[:3] > UNDETERMINED_TOL * scale[:3]).any():
                p = math.inf
            if (moved[3:] > UNDETERMINED_TOL * scale[3:]).any():
                r = math.inf
        pos[c], rot[c] = p, r
    P = covariance.shape[0]
    rank = P - (0 if null_space is None else null_space.shape[1])
    return CameraPoseError(pos, rot, rank, P)


def determined(J: Array) -> tuple[NDArray[np.intp], Array, Array]:
    """What the rows ``J`` (N, P) determine (:func:`~cpc2urdf.identification.selfcal.bundle.subspace`):
    the free parameters (the others held, one per undetermined direction), the undetermined
    directions (P, k) and the covariance (P, P), zero for the held parameters."""
    fixed, N, C = subspace(J)
    return np.setdiff1d(np.arange(J.shape[1]), fixed), N, C


def _error_of_factors(F: Array, G: dict[str, Array]) -> CameraPoseError:
    _, N, C = determined(F.reshape(-1, F.shape[-1]))
    return _pose_error(G, C, N)


def predicted_camera_pose_error(
    setup: PixelSetup, q_plan: ArrayLike, q_heldout: ArrayLike
) -> CameraPoseError:
    """The predicted RMS error of each camera's pose in the board's frame at ``q_heldout`` after a
    one-stage fit of the images at ``q_plan`` (module docstring): every view where the whole board
    is in the image (:func:`board_seen` without margins) counts, with exact corners and ``sigma``.

    Raises:
        DegenerateDataError: No camera sees the board at any configuration of the plan.
    """
    qp = np.atleast_2d(np.asarray(q_plan, dtype=float))
    seen = board_seen(setup, qp, margins=False)
    if not seen.any():
        raise DegenerateDataError("no camera sees the whole board at any configuration of the plan")
    J, _ = _jacobian(setup, qp, seen)
    _, N, C = determined(J)
    return camera_pose_error(setup, C, q_heldout, N)


def task_matrix(G_all: dict[str, Array], length: float = ROTATION_LENGTH) -> Array:
    """``A`` of the I-criterion from the held-out pose Jacobians (:func:`relative_pose_jacobians`):
    ``mean_q sum_cameras (G_p^T G_p + length^2 G_r^T G_r)``, (P, P)."""
    A = 0.0
    for G in G_all.values():
        W = np.concatenate([G[:, :3], length * G[:, 3:]], axis=1)
        A = A + np.einsum("nip,niq->pq", W, W) / len(G)
    return np.asarray(A)


@dataclass
class SelfcalPlan:
    """A chosen plan and its prediction.

    Attributes:
        q: The configurations, shape (N, n) [m]/[rad].
        labels: ``candidate <index>`` per configuration.
        prediction: Its predicted camera pose error at ``heldout``.
        random: The same prediction for ``n_random`` plans of N random candidates.
        heldout: The held-out configurations, shape (H, n).
        candidates: Candidates (every camera seeing the board) and configurations drawn for them.
        swaps: Exchanges the Fedorov passes accepted.
        seconds: Time of the planning [s].
    """

    q: Array
    labels: list[str]
    prediction: CameraPoseError
    random: list[CameraPoseError]
    heldout: Array
    candidates: tuple[int, int]
    swaps: int
    seconds: float

    def random_position_rms(self) -> float:
        """Median over the random plans of their RMS camera position error [m]."""
        return float(np.median([r.position_rms for r in self.random])) if self.random else math.nan


def plan_selfcal(
    setup: PixelSetup,
    n: int,
    *,
    n_candidates: int = 500,
    n_heldout: int = 200,
    heldout: ArrayLike | None = None,
    seed: int = 0,
    n_random: int = 20,
    length: float = ROTATION_LENGTH,
) -> SelfcalPlan:
    """Choose ``n`` configurations minimising the predicted camera pose error (module docstring).

    Args:
        setup: Head, cameras, board, noise, margins.
        n: Configurations to choose.
        n_candidates: Candidates to draw (seeded by ``seed``).
        n_heldout: Held-out configurations (drawn like the candidates, another stream) unless
            ``heldout`` gives them.
        n_random: Random plans of ``n`` candidates predicted for comparison.
        length: Weight of the rotation error [m/rad].

    Raises:
        ConfigurationError: ``n`` not in ``1..n_candidates``.
        DegenerateDataError: Too few configurations where every camera sees the board.
    """
    t0 = time.perf_counter()
    if not 1 <= n <= n_candidates:
        raise ConfigurationError(f"cannot choose {n} configurations from {n_candidates} candidates")
    q_c, drawn = draw_configurations(setup, n_candidates, np.random.default_rng([seed, 0]))
    if heldout is None:
        q_h, _ = draw_configurations(setup, n_heldout, np.random.default_rng([seed, 1]))
    else:
        q_h = np.atleast_2d(np.asarray(heldout, dtype=float))
    F = candidate_information(setup, q_c)
    free, _, _ = determined(F.reshape(-1, F.shape[-1]))  # what all the candidates determine
    G = relative_pose_jacobians(setup, q_h)  # once, for every plan predicted below
    A = task_matrix(G, length)[np.ix_(free, free)]
    sel = select(F[:, :, free], n, criterion="I", A=A)
    idx = np.sort(sel.indices)
    rng = np.random.default_rng([seed, 2])
    rand = [_error_of_factors(F[rng.choice(len(F), n, replace=False)], G) for _ in range(n_random)]
    return SelfcalPlan(
        q_c[idx],
        [f"candidate {i}" for i in idx],
        _error_of_factors(F[idx], G),
        rand,
        q_h,
        (len(q_c), drawn),
        sel.swaps,
        time.perf_counter() - t0,
    )


__all__ = [
    "ROTATION_LENGTH",
    "CameraPoseError",
    "SelfcalPlan",
    "camera_pose_error",
    "candidate_information",
    "determined",
    "pixel_data",
    "plan_selfcal",
    "predicted_camera_pose_error",
    "relative_pose_jacobians",
    "task_matrix",
]
