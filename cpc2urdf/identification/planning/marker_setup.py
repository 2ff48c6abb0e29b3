"""A marker measuring setup: position-only data (laser tracker, mocap), for planning.

K markers on each measured frame, at positions the identification does not know (it identifies
them with the robot, :mod:`~cpc2urdf.identification.kinematics.points.point_problem`), each point
measured with isotropic noise ``sigma_p`` per coordinate. The markers are placed as ``cpc2urdf
simulate --markers K --seed S`` places them (:func:`~cpc2urdf.identification.simulation.marker_points.
place_markers_on` drawing from ``default_rng([S, 1])``, frames in the robot's order), so a plan
made with marker seed S describes the markers of that simulation; a real setup would give its
markers' approximate positions instead (the prediction depends on them only through the lever
arms).

Information: the rows of :class:`PointProblem`'s weighted Jacobian at the nominal model (noise
free) per configuration, in the :class:`PointChart` of the nominal model and the unknown markers
(frame placements are gauge: the unknown marker positions absorb them). Task region: the markers'
points, ``G = dy/dx`` at the task configurations, so the predicted error is the RMS error of the
identified model's marker points over the task region (what the held-out file of ``simulate
--markers`` holds); point data say nothing about orientation (``orientation_rms`` is NaN).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.files.measurements import Marker
from cpc2urdf.identification.kinematics.points.point_problem import PointChart, PointProblem
from cpc2urdf.identification.planning.information import TaskSensitivity
from cpc2urdf.identification.simulation.marker_points import place_markers_on
from cpc2urdf.model import CPCModel

Array = NDArray[np.float64]

DEFAULT_MARKER_SIGMA = 0.1e-3  # [m]: as simulate --marker-sigma-mm's default


def plan_markers(
    model: CPCModel, frames: Sequence[str], per_frame: int, seed: int
) -> dict[str, tuple[str, Array]]:
    """The markers ``simulate --markers per_frame --seed seed`` puts on ``frames`` (module docstring)."""
    order = [f for f in model.structure.frame_names if f in frames]
    return place_markers_on(model, {f: per_frame for f in order}, np.random.default_rng([seed, 1]))


@dataclass(frozen=True)
class MarkerMeasurement:
    """Marker points of unknown markers, isotropic noise.

    Attributes:
        markers: Marker name -> (frame, position in the frame [m]) (the planning guess).
        sigma_p: Noise of each coordinate [m].
    """

    markers: dict[str, tuple[str, Array]]
    sigma_p: float

    def point_chart(self, reference: CPCModel) -> PointChart:
        """The :class:`PointChart` of ``reference`` and the (unknown) markers."""
        defs = [Marker(name, frame) for name, (frame, _) in self.markers.items()]
        return PointChart(reference, defs, {name: p for name, (_, p) in self.markers.items()})

    def _jacobian(self, chart: PointChart, q: Array) -> Array:
        """Weighted Jacobian regrouped per configuration, shape (N, 3 * n_markers, P)."""
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        n = len(qq)
        names = [m.name for m in chart.markers]
        points = {m: np.zeros((n, 3)) for m in names}  # the Jacobian does not read the measurements
        use = {m: np.ones(n, dtype=bool) for m in names}
        J = PointProblem(chart, qq, points, use, self.sigma_p).jacobian(np.zeros(chart.n_params))
        # Markers in chart order, records ascending, 3 rows per point: regroup per configuration.
        return np.swapaxes(J.reshape(len(names), n, 3, chart.n_params), 0, 1).reshape(
            n, -1, chart.n_params
        )

    def weighted_jacobian(self, chart: PointChart, q: Array) -> Array:
        """Rows of the weighted point residuals' Jacobian per configuration, (N, 3 * n_markers, P)."""
        return self._jacobian(chart, q)

    def task_sensitivity(self, chart: PointChart, q_task: Array) -> TaskSensitivity:
        """How the parameters move the markers' points over the task region (no orientation rows)."""
        G = -self._jacobian(chart, q_task) * self.sigma_p  # dy/dx, unweighted
        n = G.shape[0]
        Gp = G.reshape(n, -1, 3, chart.n_params)
        k = Gp.shape[0] * Gp.shape[1]
        A_p = np.einsum("nfip,nfiq->pq", Gp, Gp) / k
        Gr = np.zeros((n, 0, 3, chart.n_params))
        return TaskSensitivity(0.5 * (A_p + A_p.T), np.zeros_like(A_p), Gp, Gr)

    @property
    def targets(self) -> tuple[str, ...]:
        """The task region's targets: the markers."""
        return tuple(self.markers)


__all__ = ["DEFAULT_MARKER_SIGMA", "MarkerMeasurement", "plan_markers"]
