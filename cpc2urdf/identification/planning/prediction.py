"""Predicted accuracy of a plan, before any measurement.

For a list of configurations to measure, the Cramér-Rao covariance of the identified parameters at
the nominal model (:mod:`information`; the refinement reaches it within 1 %, ``cpc2urdf study
crb``) and what it implies for the measured frames over the task region:

    position:     e_p^2 = trace(A_p C)   the mean squared origin error [m^2]
    orientation:  e_r^2 = trace(A_r C)   the mean squared rotation-error angle [rad^2]

over the task configurations and frames (:func:`information.task_sensitivity`).

Under stereo pixel noise (:class:`~cpc2urdf.identification.planning.information.
StereoPoseMeasurement`) each view has its own 6 x 6 pose covariance ``Sigma_c``, but the
identification weights every pose of a file with the same scalar ``sigma_t``/``sigma_r``
(:mod:`~cpc2urdf.identification.kinematics.problem`; a stereo file states no pose sigma, so the
paper's 0.5 mm / 0.5 deg). The prediction is then what that weighted least squares actually
achieves, the sandwich covariance

    C = (J^T J)^+ (sum_c J_c^T S_c J_c) (J^T J)^+       J: the pipeline's weighted Jacobian,
                                                          S_c = W Sigma_c W its residuals' covariance

and :attr:`Prediction.bound_position_rms` is the Cramér-Rao bound with per-view optimal weights
(``sum J_c^T Sigma_c^-1 J_c``, what the optimiser maximises), which only a per-view weighting
would reach. Under Fig. 10 noise the two coincide.

With a marker setup (:class:`~cpc2urdf.identification.planning.marker_setup.MarkerMeasurement`) the
parameters are those of the :class:`~cpc2urdf.identification.kinematics.points.point_problem.PointChart`
(the model without the frame placements, plus the unknown markers' positions) and the task
region's targets are the markers' points: ``position_rms`` is their RMS error, ``orientation_rms``
NaN (position-only data). ``sqrt`` of these
are the predicted RMS held-out errors of the identified model against the true poses. Where the
plan leaves parameters undetermined (rank-deficient information), ``C`` is the pseudo-inverse on
the determined subspace (:func:`~cpc2urdf.identification.kinematics.uncertainty.
covariance_from_jacobian`), the free combinations are named (:func:`~cpc2urdf.identification.
kinematics.identifiability.analyze_jacobian`), and task configurations whose frames move along a
free combination make the prediction undetermined (``inf``).

Example::

    setup = measuring_setup(load_robot("iis_head").nominal_model())
    p = predict_plan(setup, q_plan, q_task)
    p.position_rms * 1e3, p.rank, p.free_combinations
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.identification.kinematics.identifiability import analyze_jacobian
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.points.point_problem import PointChart
from cpc2urdf.identification.kinematics.uncertainty import (
    NULL_VISIBILITY_TOL,
    covariance_from_jacobian,
)
from cpc2urdf.identification.planning.information import (
    Measurement,
    StereoPoseMeasurement,
    TaskSensitivity,
    task_sensitivity,
)
from cpc2urdf.identification.planning.marker_setup import MarkerMeasurement
from cpc2urdf.identification.planning.measuring import MeasuringSetup

Array = NDArray[np.float64]


@dataclass
class Prediction:
    """What a plan is expected to give.

    Attributes:
        n_configurations: Configurations in the plan.
        n_params: Parameters of the minimal chart (32 for the IIS-head).
        rank: How many of them the plan determines.
        undetermined: Parameters that take part in a free combination.
        free_combinations: The free combinations, named (as the identification reports them).
        condition_number: Of the column-scaled weighted Jacobian (inf if rank-deficient).
        position_rms: Predicted RMS origin error over the task region [m] (inf: undetermined).
        orientation_rms: Predicted RMS rotation-error angle over the task region [rad].
        position_rms_per_frame: Frame -> predicted RMS origin error [m].
        position_max: Largest predicted RMS origin error of one task configuration and frame [m].
        task_determined: Share of task (configuration, frame) pairs the plan determines [-].
        covariance: The covariance in the nominal chart, shape (P, P): the Cramér-Rao bound, or
            under per-view noise the sandwich of the identification's weighting (module docstring).
        names: Parameter names.
        bound_position_rms: The Cramér-Rao bound's RMS origin error with per-view optimal weights [m]
            (equal to ``position_rms`` when every view has the weights' noise).
        bound_orientation_rms: Likewise for the rotation-error angle [rad].
    """

    n_configurations: int
    n_params: int
    rank: int
    undetermined: list[str]
    free_combinations: list[str]
    condition_number: float
    position_rms: float
    orientation_rms: float
    position_rms_per_frame: dict[str, float]
    position_max: float
    task_determined: float
    covariance: Array = field(repr=False)
    names: tuple[str, ...] = field(repr=False, default=())
    bound_position_rms: float = math.nan
    bound_orientation_rms: float = math.nan

    def to_json(self) -> dict[str, object]:
        """SI numbers converted to mm / deg for a plan file; ``null`` where undetermined."""

        def num(v: float, scale: float) -> float | None:
            return v * scale if math.isfinite(v) else None

        return {
            "position_rms_mm": num(self.position_rms, 1e3),
            "orientation_rms_deg": num(self.orientation_rms, 180.0 / math.pi),
            "position_rms_per_frame_mm": {
                f: num(v, 1e3) for f, v in self.position_rms_per_frame.items()
            },
            "position_max_mm": num(self.position_max, 1e3),
            "n_configurations": self.n_configurations,
            "n_params": self.n_params,
            "rank": self.rank,
            "condition_number": num(self.condition_number, 1.0),
            "undetermined": list(self.undetermined),
            "free_combinations": list(self.free_combinations),
            "task_determined": self.task_determined,
            "bound_position_rms_mm": num(self.bound_position_rms, 1e3),
            "bound_orientation_rms_deg": num(self.bound_orientation_rms, 180.0 / math.pi),
        }


@dataclass(frozen=True)
class _Labels:
    """What :func:`covariance_from_jacobian` reads of a chart (names, units, frames)."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    frames: tuple[str, ...]


Chart = Parametrization | PointChart


def chart_and_task(
    setup: MeasuringSetup, measurement: Measurement | MarkerMeasurement, q_task: Array
) -> tuple[Chart, TaskSensitivity, tuple[str, ...]]:
    """The parameter chart of ``measurement`` at the nominal model, the task region's sensitivity and
    its targets (the measured frames; the markers of a marker setup)."""
    if isinstance(measurement, MarkerMeasurement):
        pc = measurement.point_chart(setup.nominal)
        return pc, measurement.task_sensitivity(pc, q_task), measurement.targets
    chart = Parametrization(setup.nominal, setup.frames)
    return chart, task_sensitivity(chart, q_task, setup.frames), setup.frames


def _labels(chart: Chart) -> Parametrization:
    if isinstance(chart, Parametrization):
        return chart
    return cast(
        Parametrization,
        _Labels(
            tuple(chart.names),
            tuple(chart.units),
            tuple(dict.fromkeys(m.frame for m in chart.markers)),
        ),
    )


def predict_from_jacobian(
    J: Array,
    chart: Chart,
    task: TaskSensitivity,
    frames: Sequence[str],
    sigma_t: float,
    sigma_r: float,
    *,
    pipeline: tuple[Array, Array] | None = None,
) -> Prediction:
    """:class:`Prediction` from a plan's weighted Jacobian ``J`` (rows of every configuration,
    whitened by their noise, shape (m, P)) and the task region's sensitivity.

    ``pipeline``: ``(J_w, S)``, the Jacobian as the identification weights it (m, P) and its
    residuals' covariance per 6-row block (m / 6, 6, 6); the prediction is then the sandwich
    covariance of that weighted least squares (module docstring)."""
    P = chart.n_params
    report = analyze_jacobian(J, chart.names, warn=False)
    labels = _labels(chart)
    cov = covariance_from_jacobian(
        J, labels, residuals=np.zeros(J.shape[0]), sigma_t=sigma_t, sigma_r=sigma_r
    )
    C = C_bound = cov.matrix
    if pipeline is not None:
        Jw, S = pipeline
        Cw = covariance_from_jacobian(
            Jw, labels, residuals=np.zeros(Jw.shape[0]), sigma_t=sigma_t, sigma_r=sigma_r
        ).matrix
        Jb = Jw.reshape(-1, 6, P)
        B = np.einsum("bip,bij,bjq->pq", Jb, S, Jb)
        C = Cw @ B @ Cw
        C = 0.5 * (C + C.T)
    Gp, Gr = task.G_p, task.G_r  # (N, F, 3, P); Gr empty (N, 0, 3, P) for position-only targets
    rot = Gr.shape[1] > 0
    determined = np.ones(Gp.shape[:2], dtype=bool)
    if cov.null_space.size:
        for G in (Gp, Gr) if rot else (Gp,):
            seen = np.linalg.norm(G @ cov.null_space, axis=(2, 3))
            typical = np.linalg.norm(G, axis=(2, 3)) / math.sqrt(P)
            determined &= seen <= NULL_VISIBILITY_TOL * np.maximum(typical, 1e-300)

    def mean_square(G: Array, cov_matrix: Array) -> Array:
        if G.shape[1] == 0:
            return np.full(determined.shape, np.nan)
        ms = np.einsum("nfip,pq,nfiq->nf", G, cov_matrix, G)
        return np.where(determined, np.clip(ms, 0.0, None), np.inf)

    ms_p, ms_r = mean_square(Gp, C), mean_square(Gr, C)
    bound_p, bound_r = (
        (ms_p, ms_r) if pipeline is None else (mean_square(Gp, C_bound), mean_square(Gr, C_bound))
    )
    free = [
        w.removeprefix("free combination: ")
        for w in report.warnings
        if w.startswith("free combination: ")
    ]
    return Prediction(
        n_configurations=0,
        n_params=P,
        rank=report.rank,
        undetermined=list(report.undetermined),
        free_combinations=free,
        condition_number=report.condition_number,
        position_rms=float(np.sqrt(ms_p.mean())),
        orientation_rms=float(np.sqrt(ms_r.mean())),
        position_rms_per_frame={f: float(np.sqrt(ms_p[:, k].mean())) for k, f in enumerate(frames)},
        position_max=float(np.sqrt(ms_p.max())),
        task_determined=float(determined.mean()),
        covariance=C,
        names=tuple(chart.names),
        bound_position_rms=float(np.sqrt(bound_p.mean())),
        bound_orientation_rms=float(np.sqrt(bound_r.mean())),
    )


def predict_plan(
    setup: MeasuringSetup,
    q_plan: ArrayLike,
    q_task: ArrayLike,
    *,
    measurement: Measurement | MarkerMeasurement | None = None,
) -> Prediction:
    """Predicted held-out accuracy of measuring ``q_plan`` with ``setup``, over ``q_task``.

    Args:
        setup: The measuring setup (nominal robot placed in front of the rig, noise).
        q_plan: Configurations to measure [m]/[rad], shape (N, n).
        q_task: The task region's configurations [m]/[rad], shape (K, n).
        measurement: The kind of measurement (default: the setup's, :meth:`MeasuringSetup.measurement`).

    Raises:
        ConfigurationError: Configurations of the wrong shape or not finite.
    """
    s = setup.nominal.structure
    qp = _configurations(q_plan, s.n_joints, "plan")
    qt = _configurations(q_task, s.n_joints, "task region")
    meas = measurement or setup.measurement()
    chart, task, targets = chart_and_task(setup, meas, qt)
    J = meas.weighted_jacobian(chart, qp).reshape(-1, chart.n_params)  # type: ignore[arg-type]
    pipe = (
        meas.pipeline(chart, qp)
        if isinstance(meas, StereoPoseMeasurement) and isinstance(chart, Parametrization)
        else None
    )
    pred = predict_from_jacobian(
        J, chart, task, targets, setup.sigma_t, setup.sigma_r, pipeline=pipe
    )
    pred.n_configurations = len(qp)
    return pred


def _configurations(q: ArrayLike, n: int, what: str) -> Array:
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    if qq.ndim != 2 or qq.shape[1] != n or len(qq) == 0:
        raise ConfigurationError(
            f"{what}: expected configurations of {n} joint values each, got shape {qq.shape}"
        )
    if not np.all(np.isfinite(qq)):
        raise ConfigurationError(f"{what}: configurations must be finite numbers")
    return qq


__all__ = ["Chart", "Prediction", "chart_and_task", "predict_from_jacobian", "predict_plan"]
