"""Fisher information of one configuration, and the task region's sensitivity to the parameters.

Each measured configuration adds ``J_c^T J_c`` to the information matrix of the parameters, where
``J_c`` are its rows of the weighted Jacobian of eq. (23) (:class:`~cpc2urdf.identification.
kinematics.problem.IdentificationProblem`: residuals divided by their noise sigma) at the nominal
model, noise-free, in the nominal model's minimal chart (:mod:`~cpc2urdf.identification.
kinematics.parametrization`). The information of a plan is the sum over its configurations, and
``C = M^-1`` is the Cramér-Rao covariance (:func:`~cpc2urdf.identification.kinematics.uncertainty.
cramer_rao_covariance` computes the same matrix for a whole plan), which the refinement reaches.

A kind of measurement is anything with ``weighted_jacobian(chart, q) -> (N, m, P)``:
:class:`PoseMeasurement` is the rig's plate poses under Fig. 10 noise (6 rows per measured frame);
:class:`StereoPoseMeasurement` the same poses under stereo pixel noise, whose covariance differs
per view (:mod:`stereo`): its rows are whitened by each view's 6 x 6 covariance, ``L^-1 D`` with
``Sigma = L L^T`` and ``D`` the unweighted residual's Jacobian, so that ``sum J_c^T J_c`` is the
information with per-view optimal weights; point or marker observations plug in the same way.
A measurement may also have ``pipeline(chart, q) -> (J, S)``: the Jacobian weighted as the
identification actually weights it (``J``, (m, P)) and the covariance of those weighted residuals
per 6-row block (``S``, (m / 6, 6, 6)), for the sandwich covariance of :mod:`prediction`.

The task region's sensitivity: a parameter error ``x`` moves frame f's origin at q by ``G_p x``
and turns it by ``G_r x`` (rows 0-2 and 3-5 of :meth:`Parametrization.pose_jacobian`), so the
mean squared position error over the task configurations and frames is ``trace(A_p C)`` with
``A_p = mean(G_p^T G_p)``, and the orientation error's ``trace(A_r C)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.problem import (
    DEFAULT_SIGMA_R,
    DEFAULT_SIGMA_T,
    IdentificationProblem,
)
from cpc2urdf.identification.planning.stereo_views import stereo_pose_covariance
from cpc2urdf.identification.vision.stereo import StereoRig

Array = NDArray[np.float64]


def _problem_jacobian(
    chart: Parametrization, qq: Array, frames: Sequence[str], sigma_t: float, sigma_r: float
) -> Array:
    """The :class:`IdentificationProblem`'s Jacobian at the chart's centre on its own noise-free
    poses at ``qq`` (N, n), in its order (frame after frame, 6 rows per pose): shape (6 N F, P)."""
    poses = chart.reference.fk(qq, frames)
    use = {f: np.ones(len(qq), dtype=bool) for f in frames}
    return IdentificationProblem(chart, qq, poses, use, sigma_t, sigma_r).jacobian(
        np.zeros(chart.n_params)
    )


def _pose_weights(sigma_t: float, sigma_r: float) -> Array:
    """The problem's weights of one pose's 6 residuals (position, rotation vector), shape (6,)."""
    return np.array([1.0 / sigma_t] * 3 + [np.sqrt(3.0) / sigma_r] * 3)


class Measurement(Protocol):
    """A kind of measurement: its weighted Jacobian rows per configuration."""

    def weighted_jacobian(self, chart: Parametrization, q: Array) -> Array:
        """Rows of the weighted Jacobian per configuration, shape (N, m, P) [1/m]/[1/rad]."""
        ...


@dataclass(frozen=True)
class PoseMeasurement:
    """The pose of each measured frame in world, Fig. 10 noise (what the rig's plates give).

    Attributes:
        frames: The measured frames.
        sigma_t: Translation noise per entry [m].
        sigma_r: Rotation noise angle [rad].
    """

    frames: tuple[str, ...]
    sigma_t: float
    sigma_r: float

    def weighted_jacobian(self, chart: Parametrization, q: Array) -> Array:
        """The :class:`IdentificationProblem`'s Jacobian at the chart's centre on its own noise-free
        poses, regrouped per configuration: shape (N, 6 * n_frames, P)."""
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        J = _problem_jacobian(chart, qq, self.frames, self.sigma_t, self.sigma_r)
        # The problem stacks frame after frame, 6 rows per pose: regroup per configuration.
        blocks = J.reshape(len(self.frames), len(qq), 6, chart.n_params)
        return np.concatenate(list(blocks), axis=1)


@dataclass(frozen=True)
class StereoPoseMeasurement:
    """The pose of each measured plate through the stereo rig, pixel noise (the simulator's
    ``noise="stereo"``): a 6 x 6 covariance per plate and configuration (:mod:`stereo`).

    Attributes:
        frames: The measured frames (plates).
        layouts: Each frame's circle centres in its frame [m], shape (K, 3).
        rig: The stereo rig (world = its left camera).
        pixel_sigma: Pixel noise per coordinate [px].
        sigma_t: The translation sigma the identification weights with [m]: a stereo file states
            no pose sigma, so :func:`~cpc2urdf.identification.kinematics.methods.noise_from_metadata`
            falls back to the paper's 0.5 mm / 0.5 deg, the defaults here.
        sigma_r: Likewise the rotation angle sigma [rad].
    """

    frames: tuple[str, ...]
    layouts: tuple[Array, ...]
    rig: StereoRig
    pixel_sigma: float
    sigma_t: float = DEFAULT_SIGMA_T
    sigma_r: float = float(DEFAULT_SIGMA_R)

    def covariances(self, chart: Parametrization, q: Array) -> Array:
        """Each view's pose-error covariance at the chart's centre, shape (N, F, 6, 6)."""
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        T = chart.reference.fk(qq, self.frames)
        return np.stack(
            [
                stereo_pose_covariance(T[f], lay, self.rig, self.pixel_sigma)
                for f, lay in zip(self.frames, self.layouts, strict=True)
            ],
            axis=1,
        )

    def _unweighted(self, chart: Parametrization, q: Array) -> Array:
        """Jacobian of the unweighted residuals (dp, dtheta), shape (N, F, 6, P)."""
        J = PoseMeasurement(self.frames, self.sigma_t, self.sigma_r).weighted_jacobian(chart, q)
        n = J.shape[0]
        w = _pose_weights(self.sigma_t, self.sigma_r)
        return J.reshape(n, len(self.frames), 6, chart.n_params) / w[:, None]

    def weighted_jacobian(self, chart: Parametrization, q: Array) -> Array:
        """Rows whitened by each view's covariance, shape (N, 6 * n_frames, P).

        Raises:
            ValueError: A plate shows fewer than 3 circles at some configuration.
        """
        D = self._unweighted(chart, q)
        S = self.covariances(chart, q)
        if not np.all(np.isfinite(S)):
            raise ValueError(
                "stereo measurement: a plate shows fewer than 3 circles at a configuration"
            )
        L = np.linalg.cholesky(S)
        Jw = np.linalg.solve(L, D)  # (N, F, 6, P)
        return Jw.reshape(D.shape[0], -1, chart.n_params)

    def pipeline(self, chart: Parametrization, q: Array) -> tuple[Array, Array]:
        """``(J, S)``: the Jacobian weighted with the scalar ``sigma_t``/``sigma_r`` the
        identification uses, (6 N F, P) in :class:`IdentificationProblem`'s order (frame after
        frame), and each pose's weighted residual covariance ``W Sigma W``, (N F, 6, 6) in that order."""
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        J = _problem_jacobian(chart, qq, self.frames, self.sigma_t, self.sigma_r)
        w = _pose_weights(self.sigma_t, self.sigma_r)
        S = self.covariances(chart, qq) * w[:, None] * w[None, :]  # (N, F, 6, 6)
        return J, np.swapaxes(S, 0, 1).reshape(-1, 6, 6)


@dataclass(frozen=True)
class TaskSensitivity:
    """How the parameters move the measured frames over the task region.

    Attributes:
        A_p: ``mean(G_p^T G_p)`` over task configurations and frames, shape (P, P) [-].
        A_r: ``mean(G_r^T G_r)``, shape (P, P).
        G_p: Position Jacobians, shape (n_task, n_frames, 3, P).
        G_r: Rotation Jacobians, shape (n_task, n_frames, 3, P).
    """

    A_p: Array
    A_r: Array
    G_p: Array
    G_r: Array


def task_sensitivity(
    chart: Parametrization, q_task: ArrayLike, frames: Sequence[str]
) -> TaskSensitivity:
    """:class:`TaskSensitivity` of ``frames`` at the task configurations ``q_task`` (N, n)."""
    qq = np.atleast_2d(np.asarray(q_task, dtype=float))
    _, D = chart.pose_jacobian(np.zeros(chart.n_params), qq)
    G = np.stack([D[f] for f in frames], axis=1)  # (N, F, 6, P)
    Gp, Gr = G[:, :, :3, :], G[:, :, 3:, :]
    k = Gp.shape[0] * Gp.shape[1]
    A_p = np.einsum("nfip,nfiq->pq", Gp, Gp) / k
    A_r = np.einsum("nfip,nfiq->pq", Gr, Gr) / k
    return TaskSensitivity(0.5 * (A_p + A_p.T), 0.5 * (A_r + A_r.T), Gp, Gr)


__all__ = [
    "Measurement",
    "PoseMeasurement",
    "StereoPoseMeasurement",
    "TaskSensitivity",
    "task_sensitivity",
]
