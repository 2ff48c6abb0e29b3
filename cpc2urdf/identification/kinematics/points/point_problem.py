"""The maximum-likelihood problem of position-only data: marker point residuals and their Jacobian.

A marker m fixed to frame F (a laser tracker's reflector, a mocap ball) is measured at world
position ``y``; the model predicts ``T_world_F(q) p_m`` (the paper's forward kinematics, eqs.
(2)-(6), times the marker's position ``p_m`` in F). With isotropic Gaussian noise of ``sigma_p``
per coordinate the weighted residual is::

    r = (y - T_world_F(q) p_m) / sigma_p          (3 per seen marker) [-]

Unknowns (:class:`PointChart`): the minimal chart of :mod:`parametrization` for every joint on a
path to a marker's frame, the placement of a frame on its link only where some of its markers
have known positions (otherwise the unknown marker positions absorb it: gauge), and the
position of every marker whose position is not given. Jacobian: analytic, from the chart's
spatial twists (``dy = dp_F + w x (R_F p_m)``, ``dy/dp_m = R_F``), checked against finite
differences in ``tests/test_markers.py``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import Marker
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.model import CPCModel
from cpc2urdf.transforms import Array

# Default per-coordinate noise of a marker point when the file states none [m] (a motion-capture
# system; a laser tracker is ~10x better: state it in the file's noise section as sigma_p_m).
DEFAULT_SIGMA_P = 0.5e-3
MARKER_PARAMS = ("p_x", "p_y", "p_z")


class PointChart:
    """Local coordinates of position-only identification: model parameters + unknown markers.

    Args:
        reference: The model the chart is centred on (``x = 0``); its gauge is kept.
        markers: The markers that take part (each fixed to a frame of ``reference``).
        positions: Marker name -> its position in its frame at ``x = 0`` [m], shape (3,) (the
            given position of a known marker, the current estimate of an unknown one).

    Attributes:
        model_chart: The :class:`Parametrization` of ``reference`` through the markers' frames.
        columns: Indices of ``model_chart``'s parameters that are free here, shape (k,).
        unknown: The markers whose positions are parameters, in order.
        names: Parameter names: the model chart's free ones, then ``"<marker>.p_x"`` etc.
        units: ``"m"``/``"rad"`` per parameter.
        fixed_frames: Frames whose placement is not a parameter (no marker of known position).
    """

    def __init__(
        self, reference: CPCModel, markers: Sequence[Marker], positions: Mapping[str, Array]
    ) -> None:
        if not markers:
            raise DegenerateDataError("nothing to identify: no marker was seen")
        self.markers = tuple(markers)
        frames = list(dict.fromkeys(m.frame for m in self.markers))
        self.model_chart = Parametrization(reference, frames)
        free_frames = {m.frame for m in self.markers if m.known}
        self.fixed_frames = tuple(f for f in frames if f not in free_frames)
        cols = [
            i
            for b in self.model_chart.blocks
            if b.kind != "frame" or b.owner in free_frames
            for i in range(b.start, b.start + len(b.params))
        ]
        self.columns = np.array(cols, dtype=int)
        self.unknown = tuple(m for m in self.markers if not m.known)
        self.positions = {
            m.name: np.asarray(positions[m.name], dtype=float).copy() for m in self.markers
        }
        k = len(self.columns)
        self._marker_slot = {m.name: k + 3 * i for i, m in enumerate(self.unknown)}
        self.names: tuple[str, ...] = (
            *(self.model_chart.names[i] for i in cols),
            *(f"{m.name}.{p}" for m in self.unknown for p in MARKER_PARAMS),
        )
        self.units: tuple[str, ...] = (
            *(self.model_chart.units[i] for i in cols),
            *("m",) * (3 * len(self.unknown)),
        )

    @property
    def reference(self) -> CPCModel:
        return self.model_chart.reference

    @property
    def n_params(self) -> int:
        return len(self.names)

    @property
    def n_model_params(self) -> int:
        return len(self.columns)

    def model_vector(self, x: Array) -> Array:
        """The model chart's full vector (fixed frame blocks at 0) of ``x``."""
        full = np.zeros(self.model_chart.n_params)
        full[self.columns] = x[: len(self.columns)]
        return full

    def model_from_vector(self, x: Array) -> CPCModel:
        return self.model_chart.model_from_vector(self.model_vector(np.asarray(x, dtype=float)))

    def positions_from_vector(self, x: Array) -> dict[str, Array]:
        """Marker name -> position in its frame [m] at ``x``."""
        out = {}
        for m in self.markers:
            p = self.positions[m.name].copy()
            if m.name in self._marker_slot:
                k = self._marker_slot[m.name]
                p += x[k : k + 3]
            out[m.name] = p
        return out

    def marker_slot(self, name: str) -> int | None:
        """Index of the marker's ``p_x`` in the vector, or None for a marker of known position."""
        return self._marker_slot.get(name)


class PointProblem:
    """Weighted marker residuals and their Jacobian for the seen (record, marker) points.

    Args:
        chart: The :class:`PointChart`.
        q: Joint readings [rad]/[m], shape (N, n).
        points: Marker name -> measured world positions [m], shape (N, 3), NaN where unseen.
        use: Marker name -> which records take part, shape (N,) booleans.
        sigma_p: Standard deviation of each measured coordinate [m].

    Attributes:
        rows: Marker -> indices of its used records.
        n_points: Used points; there are ``3 * n_points`` residuals.
    """

    def __init__(
        self,
        chart: PointChart,
        q: Array,
        points: Mapping[str, Array],
        use: Mapping[str, NDArray[np.bool_]],
        sigma_p: float,
    ) -> None:
        if not (sigma_p > 0 and np.isfinite(sigma_p)):
            raise DegenerateDataError(f"marker noise sigma must be positive, got {sigma_p}")
        self.chart = chart
        self.q = np.atleast_2d(q)
        self.markers = [m for m in chart.markers if use[m.name].any()]
        self.rows = {m.name: np.flatnonzero(use[m.name]) for m in self.markers}
        self.y = {
            m.name: np.asarray(points[m.name], dtype=float)[self.rows[m.name]] for m in self.markers
        }
        self.w = 1.0 / sigma_p
        self.n_points = sum(len(r) for r in self.rows.values())

    def predict(self, x: Array) -> dict[str, Array]:
        """Predicted world positions of the used points, marker -> (n_m, 3) [m]."""
        model = self.chart.model_from_vector(x)
        pos = self.chart.positions_from_vector(x)
        frames = list(dict.fromkeys(m.frame for m in self.markers))
        T = model.fk(self.q, frames)
        out = {}
        for m in self.markers:
            Tf = T[m.frame][self.rows[m.name]]
            out[m.name] = Tf[:, :3, :3] @ pos[m.name] + Tf[:, :3, 3]
        return out

    def residual_blocks(self, x: Array) -> dict[str, Array]:
        """Unweighted ``y - y_pred`` per marker, (n_m, 3) [m]."""
        pred = self.predict(x)
        return {k: self.y[k] - v for k, v in pred.items()}

    def residuals(self, x: Array) -> Array:
        """Weighted residuals, shape (3 * n_points,) [-], markers in chart order, records ascending."""
        try:
            blocks = self.residual_blocks(x)
        except DegenerateDataError:  # a trial step left the chart: make the solver reject it
            return np.full(3 * self.n_points, 1e6)
        return np.concatenate([b.ravel() for b in blocks.values()]) * self.w

    def jacobian(self, x: Array) -> Array:
        """Jacobian of :meth:`residuals`, shape (3 * n_points, n_params) [1/m] or [1/rad]."""
        x = np.asarray(x, dtype=float)
        c = self.chart
        T, D = c.model_chart.pose_jacobian(c.model_vector(x), self.q)
        pos = c.positions_from_vector(x)
        out = []
        for m in self.markers:
            rows = self.rows[m.name]
            Tf, Df = T[m.frame][rows], D[m.frame][rows][:, :, c.columns]  # (n, 6, k)
            pw = Tf[:, :3, :3] @ pos[m.name]  # marker lever from the frame origin, in world
            # dy = dp + w x pw = dp - [pw]x w
            dy = Df[:, :3, :] + np.cross(np.swapaxes(Df[:, 3:, :], 1, 2), pw[:, None, :]).swapaxes(
                1, 2
            )
            J = np.zeros((len(rows), 3, c.n_params))
            J[:, :, : c.n_model_params] = dy
            k = c.marker_slot(m.name)
            if k is not None:
                J[:, :, k : k + 3] = Tf[:, :3, :3]
            out.append(-J.reshape(-1, c.n_params) * self.w)
        return np.concatenate(out, axis=0)


__all__ = ["DEFAULT_SIGMA_P", "MARKER_PARAMS", "PointChart", "PointProblem"]
