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
point or marker observations plug in the same way (their rows of their own residuals).

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
from cpc2urdf.identification.kinematics.problem import IdentificationProblem

Array = NDArray[np.float64]


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
        n = len(qq)
        poses = chart.reference.fk(qq, self.frames)
        use = {f: np.ones(n, dtype=bool) for f in self.frames}
        J = IdentificationProblem(chart, qq, poses, use, self.sigma_t, self.sigma_r).jacobian(np.zeros(chart.n_params))
        # The problem stacks frame after frame, 6 rows per pose: regroup per configuration.
        blocks = J.reshape(len(self.frames), n, 6, chart.n_params)
        return np.concatenate(list(blocks), axis=1)


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


def task_sensitivity(chart: Parametrization, q_task: ArrayLike, frames: Sequence[str]) -> TaskSensitivity:
    """:class:`TaskSensitivity` of ``frames`` at the task configurations ``q_task`` (N, n)."""
    qq = np.atleast_2d(np.asarray(q_task, dtype=float))
    _, D = chart.pose_jacobian(np.zeros(chart.n_params), qq)
    G = np.stack([D[f] for f in frames], axis=1)  # (N, F, 6, P)
    Gp, Gr = G[:, :, :3, :], G[:, :, 3:, :]
    k = Gp.shape[0] * Gp.shape[1]
    A_p = np.einsum("nfip,nfiq->pq", Gp, Gp) / k
    A_r = np.einsum("nfip,nfiq->pq", Gr, Gr) / k
    return TaskSensitivity(0.5 * (A_p + A_p.T), 0.5 * (A_r + A_r.T), Gp, Gr)


__all__ = ["Measurement", "PoseMeasurement", "TaskSensitivity", "task_sensitivity"]
