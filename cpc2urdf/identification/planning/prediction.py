"""Predicted accuracy of a plan, before any measurement.

For a list of configurations to measure, the Cramér-Rao covariance of the identified parameters at
the nominal model (:mod:`information`; the refinement reaches it within 1 %, ``cpc2urdf study
crb``) and what it implies for the measured frames over the task region:

    position:     e_p^2 = trace(A_p C)   the mean squared origin error [m^2]
    orientation:  e_r^2 = trace(A_r C)   the mean squared rotation-error angle [rad^2]

over the task configurations and frames (:func:`information.task_sensitivity`). ``sqrt`` of these
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
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.identification.kinematics.identifiability import analyze_jacobian
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.uncertainty import (
    NULL_VISIBILITY_TOL,
    covariance_from_jacobian,
)
from cpc2urdf.identification.planning.information import (
    Measurement,
    PoseMeasurement,
    TaskSensitivity,
    task_sensitivity,
)
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
        covariance: The Cramér-Rao covariance in the nominal chart, shape (P, P).
        names: Parameter names.
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

    def to_json(self) -> dict[str, object]:
        """SI numbers converted to mm / deg for a plan file; ``null`` where undetermined."""

        def num(v: float, scale: float) -> float | None:
            return v * scale if math.isfinite(v) else None

        return {
            "position_rms_mm": num(self.position_rms, 1e3),
            "orientation_rms_deg": num(self.orientation_rms, 180.0 / math.pi),
            "position_rms_per_frame_mm": {f: num(v, 1e3) for f, v in self.position_rms_per_frame.items()},
            "position_max_mm": num(self.position_max, 1e3),
            "n_configurations": self.n_configurations,
            "n_params": self.n_params,
            "rank": self.rank,
            "condition_number": num(self.condition_number, 1.0),
            "undetermined": list(self.undetermined),
            "free_combinations": list(self.free_combinations),
            "task_determined": self.task_determined,
        }


def predict_from_jacobian(J: Array, chart: Parametrization, task: TaskSensitivity, frames: tuple[str, ...],
                          sigma_t: float, sigma_r: float) -> Prediction:
    """:class:`Prediction` from a plan's weighted Jacobian ``J`` (rows of every configuration,
    shape (m, P)) and the task region's sensitivity."""
    P = chart.n_params
    report = analyze_jacobian(J, chart.names, warn=False)
    cov = covariance_from_jacobian(J, chart, residuals=np.zeros(J.shape[0]), sigma_t=sigma_t, sigma_r=sigma_r)
    C = cov.matrix
    Gp, Gr = task.G_p, task.G_r  # (N, F, 3, P)
    ms_p = np.einsum("nfip,pq,nfiq->nf", Gp, C, Gp)
    ms_r = np.einsum("nfip,pq,nfiq->nf", Gr, C, Gr)
    determined = np.ones(ms_p.shape, dtype=bool)
    if cov.null_space.size:
        for G in (Gp, Gr):
            seen = np.linalg.norm(G @ cov.null_space, axis=(2, 3))
            typical = np.linalg.norm(G, axis=(2, 3)) / math.sqrt(P)
            determined &= seen <= NULL_VISIBILITY_TOL * np.maximum(typical, 1e-300)
    ms_p = np.where(determined, np.clip(ms_p, 0.0, None), np.inf)
    ms_r = np.where(determined, np.clip(ms_r, 0.0, None), np.inf)
    free = [w.removeprefix("free combination: ") for w in report.warnings if w.startswith("free combination: ")]
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
    )


def predict_plan(
    setup: MeasuringSetup,
    q_plan: ArrayLike,
    q_task: ArrayLike,
    *,
    measurement: Measurement | None = None,
) -> Prediction:
    """Predicted held-out accuracy of measuring ``q_plan`` with ``setup``, over ``q_task``.

    Args:
        setup: The measuring setup (nominal robot placed in front of the rig, noise).
        q_plan: Configurations to measure [m]/[rad], shape (N, n).
        q_task: The task region's configurations [m]/[rad], shape (K, n).
        measurement: The kind of measurement (default: the rig's plate poses,
            :class:`PoseMeasurement` with the setup's noise).

    Raises:
        ConfigurationError: Configurations of the wrong shape or not finite.
    """
    s = setup.nominal.structure
    qp = _configurations(q_plan, s.n_joints, "plan")
    qt = _configurations(q_task, s.n_joints, "task region")
    chart = Parametrization(setup.nominal, setup.frames)
    meas = measurement or PoseMeasurement(setup.frames, setup.sigma_t, setup.sigma_r)
    J = meas.weighted_jacobian(chart, qp).reshape(-1, chart.n_params)
    pred = predict_from_jacobian(J, chart, task_sensitivity(chart, qt, setup.frames), setup.frames,
                                 setup.sigma_t, setup.sigma_r)
    pred.n_configurations = len(qp)
    return pred


def _configurations(q: ArrayLike, n: int, what: str) -> Array:
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    if qq.ndim != 2 or qq.shape[1] != n or len(qq) == 0:
        raise ConfigurationError(f"{what}: expected configurations of {n} joint values each, got shape {qq.shape}")
    if not np.all(np.isfinite(qq)):
        raise ConfigurationError(f"{what}: configurations must be finite numbers")
    return qq


__all__ = ["Prediction", "predict_from_jacobian", "predict_plan"]
