"""Maximum a posteriori calibration about the user's URDF: what the data barely see stays put.

Real robots give few postures, joints the data barely move and unmodelled error (elastic links,
backlash, marker bodies). A maximum-likelihood fit of every CPC parameter over-fits such data and
turns weakly seen axes freely. Here each calibrated joint's axis frame is perturbed from the
nominal model's (``omega_z`` of a revolute joint, ``v_z`` of a prismatic one, is its reading's
offset) with a Gaussian prior of the stated manufacturing tolerances; the residuals and their
Jacobian are :class:`~cpc2urdf.identification.kinematics.prior_problem.MapProblem`'s. The
measurement noise is estimated from the residuals (position and rotation apart, the parameters
used counted by the hat matrix), so nothing needs to be stated.

Four model levels (:data:`LEVELS`): ``frames`` (the URDF as it is: only the measuring frame and
the measured frames or markers are fitted), ``offsets`` (plus one offset per joint), ``geometry``
(plus every origin's position and orientation) and ``compliance`` (plus each joint deflected by
its gravity load). :func:`select_model` chooses among them by leave-one-record-out
cross-validation (exact for the linearised fit); :func:`fit_map` fits one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.prior_problem import (
    MapProblem,
    Noise,
    Tolerances,
    default_joints,
    perturbation,
    start_point,
)
from cpc2urdf.model import CPCModel, RobotStructure
from cpc2urdf.transforms import Array

LEVELS = ("frames", "offsets", "geometry", "compliance")
CV_FOLDS = 5  # [-]: folds of :func:`cross_validate`
# A richer level must predict left-out records this much better (a fraction of the RMS) to be chosen.
SELECTION_MARGIN = 0.05  # [-]
NOISE_ITERATIONS = 20  # [-]: at most this many refits while the noise estimate settles (1 %)
NOISE_FLOOR = 1e-10  # [m] / [rad]: below this a noise estimate is taken as this (noise-free data)


@dataclass(frozen=True, eq=False)
class MapFit:
    """One maximum a posteriori fit.

    Attributes:
        model: The calibrated model (joints, measuring frame and measured frames).
        level: One of :data:`LEVELS`.
        joints: The calibrated joints (CPC names).
        perturbations: Joint -> ``xi = (v [m], omega [rad])``, shape (6,).
        markers: Marker -> position in its frame [m], shape (3,) (identified or given).
        noise: The noise estimated from the residuals (or as given when ``estimate_noise`` is off).
        covariance: Posterior covariance of the free parameters (:attr:`names` order).
        names: One label per free parameter.
        rms_m: RMS distance of the measured points (or frame origins) to the fit [m].
        dof: Effective number of parameters the data determined (trace of the hat matrix).
        dof_position: The part of ``dof`` the position rows used (the rest: orientations).
        loo_sq_m2: Per record, the squared distances of its points to the fit made without it,
            summed [m^2], shape (N,).
        loo_points: Per record, how many points (markers, frame origins) it measured, shape (N,).
        loo_rot_sq: Per record, its frames' squared orientation residuals left out, summed
            [rad^2], shape (N,) (zeros for marker points).
        loo_stat: Per record, ``r_i^T (I - H_ii)^-1 r_i`` over its position rows, in noise units:
            chi-square with ``3 loo_points`` degrees of freedom for a good record, shape (N,).
        loo_stat_rot: The same over its orientation rows (3 a measured frame), shape (N,).
        loo_frames: Per record, how many frame poses it measured, shape (N,).
        residual_noise: The noise the residuals show (equal to ``noise`` when it was estimated).
        data_share: Joint -> how much the data narrowed its perturbation: ``1 - posterior
            variance / prior variance``, mean over its free components (1: the data alone fix it,
            0: the prior alone, as for a joint whose effect the measuring frame absorbs).
    """

    model: CPCModel
    level: str
    joints: tuple[str, ...]
    perturbations: dict[str, Array]
    markers: dict[str, Array]
    noise: Noise
    covariance: Array
    names: tuple[str, ...]
    rms_m: float
    dof: float
    dof_position: float
    loo_sq_m2: Array
    loo_points: Array
    loo_rot_sq: Array
    loo_stat: Array
    loo_stat_rot: Array
    loo_frames: Array
    residual_noise: Noise
    data_share: dict[str, float] = field(default_factory=dict)
    compliance: dict[str, float] = field(default_factory=dict)

    @property
    def loo_rms_m(self) -> float:
        """RMS distance of the measured points to fits made without their record [m]: the error
        this fit predicts for new postures (leave-one-record-out cross-validation)."""
        return math.sqrt(float(self.loo_sq_m2.sum()) / max(float(self.loo_points.sum()), 1.0))

    def deflected(self, q: Array, loads: Array | None) -> Array:
        """Readings ``q`` (N, n) deflected by ``loads`` (N, n) through the fitted compliances."""
        if not self.compliance:
            return q
        assert loads is not None
        out = np.array(q, dtype=float)
        for j, c in self.compliance.items():
            k = self.model.structure.joint_index(j)
            out[:, k] += c * loads[:, k]
        return out


def _solve(problem: MapProblem, x0: Array) -> Array:
    sol = least_squares(
        lambda x: problem.evaluate(x, False)[0],
        x0,
        jac=lambda x: problem.evaluate(x, True)[1],
        method="lm",
        xtol=1e-12,
        ftol=1e-12,
    )
    return np.asarray(sol.x)


def fit_map(
    nominal: CPCModel,
    ms: MeasurementSet,
    level: str = "geometry",
    joints: Sequence[str] | None = None,
    tolerances: Tolerances | None = None,
    noise: Noise | None = None,
    *,
    estimate_noise: bool = True,
    loads: Array | None = None,
) -> MapFit:
    """Fit one level about ``nominal`` (module docstring).

    Args:
        nominal: The user's model (a URDF robot's nominal model): the prior's centre.
        ms: Marker points and/or measured frame poses with joint readings.
        level: One of :data:`LEVELS`.
        joints: Joints to calibrate (default :func:`default_joints`); every other joint keeps the
            nominal constants exactly.
        tolerances: The prior (default :class:`Tolerances`).
        noise: The measurement noise; with ``estimate_noise`` only its start.
        estimate_noise: Re-estimate the noise from the residuals (degrees of freedom counted by
            the hat matrix) and refit until it settles.

    Raises:
        DegenerateDataError: No measured point or frame.
    """
    if level not in LEVELS:
        raise ValueError(f"unknown level {level!r}; known: {', '.join(LEVELS)}")
    tol = tolerances or Tolerances()
    nz = noise or Noise()
    js = tuple(joints) if joints is not None else default_joints(ms)
    problem = MapProblem(nominal, ms, level, js, tol, nz, loads)
    if not problem.markers and not problem.pose_frames:
        raise DegenerateDataError(f"{ms.source}: no measured point or frame pose to calibrate from")
    x = _solve(problem, start_point(problem))
    for _ in range(NOISE_ITERATIONS if estimate_noise else 0):
        new = _estimate_noise(problem, x)
        if (
            abs(new.position_m / problem.noise.position_m - 1) < 0.01
            and abs(new.rotation_rad / problem.noise.rotation_rad - 1) < 0.01
        ):
            problem.noise = new
            break
        problem.noise = new
        x = _solve(problem, x)
    return _result(problem, x)


def _hat_traces(problem: MapProblem, J: Array) -> tuple[Array, float, float]:
    """Posterior covariance, and the hat matrix's trace over the position and the rotation rows
    (the parameters each kind of measurement used up)."""
    cov = np.linalg.pinv(J.T @ J)
    _, point = problem.row_records()
    Jm = J[: len(point)]
    Jp, Jr = Jm[point], Jm[~point]
    return cov, float(np.sum(cov * (Jp.T @ Jp))), float(np.sum(cov * (Jr.T @ Jr)))


def _noise_shown(problem: MapProblem, r: Array, hp: float, hr: float) -> Noise:
    """The noise the weighted residuals ``r`` show, the hat matrix's traces ``hp``, ``hr``
    counting the parameters the position and rotation rows used up."""
    _, point = problem.row_records()
    rm = r[: len(point)]
    rp, rr = rm[point] * problem.noise.position_m, rm[~point] * problem.noise.rotation_rad
    sp = math.sqrt(float(rp @ rp) / max(len(rp) - hp, 1.0))
    sr = (
        math.sqrt(float(rr @ rr) / max(len(rr) - hr, 1.0))
        if len(rr)
        else problem.noise.rotation_rad
    )
    return Noise(max(sp, NOISE_FLOOR), max(sr, NOISE_FLOOR))


def _estimate_noise(problem: MapProblem, x: Array) -> Noise:
    r, J = problem.evaluate(x)
    assert J is not None
    _, hp, hr = _hat_traces(problem, J)
    return _noise_shown(problem, r, hp, hr)


def _result(problem: MapProblem, x: Array) -> MapFit:
    r, J = problem.evaluate(x)
    assert J is not None
    cov, hp, hr = _hat_traces(problem, J)
    loo_sq, loo_count, loo_rot, loo_stat, loo_stat_rot, loo_frames = _leave_one_out(
        problem, r, J, cov
    )
    model = problem.model(x)
    _, point = problem.row_records()
    point_rows = r[: len(point)][point] * problem.noise.position_m  # the points' fit residuals [m]
    share: dict[
        str, float
    ] = {}  # 1 - posterior / prior variance, mean over the joint's free components
    for j in problem.joints:
        if j not in problem.slots:
            continue
        first, comps = problem.slots[j]
        idx = np.arange(first, first + len(comps))
        share[j] = float(
            np.mean(np.clip(1.0 - np.diag(cov)[idx] / problem.prior[idx] ** 2, 0.0, 1.0))
        )
    return MapFit(
        model=model,
        level=problem.level,
        joints=problem.joints,
        perturbations={j: problem.xi(x, j) for j in problem.joints if j in problem.slots},
        markers={m: problem.marker_position(x, m).copy() for m in problem.markers},
        noise=problem.noise,
        covariance=cov,
        names=problem.names,
        rms_m=math.sqrt(float(point_rows @ point_rows) / max(len(point_rows) / 3, 1.0)),
        dof=hp + hr,
        dof_position=hp,
        loo_sq_m2=loo_sq,
        loo_points=loo_count,
        loo_rot_sq=loo_rot,
        loo_stat=loo_stat,
        loo_stat_rot=loo_stat_rot,
        loo_frames=loo_frames,
        residual_noise=_noise_shown(problem, r, hp, hr),
        data_share=share,
        compliance={j: float(x[i]) for j, i in problem.compliance.items()},
    )


def _leave_one_out(problem: MapProblem, r: Array, J: Array, cov: Array) -> tuple[Array, ...]:
    """Per record: the squared distances of its points to the fit made without it, summed [m^2],
    how many points it has, the squared orientation residuals of its frames, summed [rad^2], and
    its studentized statistic ``r_i^T (I - H_ii)^-1 r_i`` over its position rows and over its
    orientation rows (chi-square with as many degrees of freedom as rows, for a good record and
    the right noise), and how many frame poses it has.
    For the linearised problem the left-out residual is exactly ``(I - H_ii)^-1 r_i``, with
    ``H_ii`` the record's block of the hat matrix (the PRESS residuals of a record)."""
    rec, point = problem.row_records()
    scale = np.where(point, problem.noise.position_m, problem.noise.rotation_rad)
    n_rec = problem.ms.n_records
    sq, count, rot = np.zeros(n_rec), np.zeros(n_rec), np.zeros(n_rec)
    stat, stat_rot, frames = np.zeros(n_rec), np.zeros(n_rec), np.zeros(n_rec)
    order = np.argsort(rec, kind="stable")
    sizes = np.bincount(rec, minlength=n_rec)
    k = int(sizes.max())
    if np.all(sizes[sizes > 0] == k):  # every record has the same rows: one batched solve
        full = np.flatnonzero(sizes == k)
        rows = order.reshape(-1, k)
        Jb = J[rows]
        H = Jb @ cov @ np.transpose(Jb, (0, 2, 1))
        e_w = np.linalg.solve(np.eye(k) - H, r[rows][..., None])[..., 0]
        pt = point[rows]
        stat[full] = np.sum(np.where(pt, e_w * r[rows], 0.0), axis=1)
        stat_rot[full] = np.sum(np.where(pt, 0.0, e_w * r[rows]), axis=1)
        frames[full] = (~pt).sum(axis=1) / 3
        e = e_w * scale[rows]
        sq[full] = np.sum(np.where(pt, e, 0.0) ** 2, axis=1)
        rot[full] = np.sum(np.where(pt, 0.0, e) ** 2, axis=1)
        count[full] = pt.sum(axis=1) / 3
        return sq, count, rot, stat, stat_rot, frames
    for i in np.flatnonzero(sizes):
        ri = np.flatnonzero(rec == i)
        Ji = J[ri]
        e_w = np.linalg.solve(np.eye(len(ri)) - Ji @ cov @ Ji.T, r[ri])
        stat[i] = float(e_w[point[ri]] @ r[ri][point[ri]])
        stat_rot[i] = float(e_w[~point[ri]] @ r[ri][~point[ri]])
        frames[i] = (~point[ri]).sum() / 3
        e = e_w * scale[ri]
        sq[i] = float(np.sum(e[point[ri]] ** 2))
        rot[i] = float(np.sum(e[~point[ri]] ** 2))
        count[i] = point[ri].sum() / 3
    return sq, count, rot, stat, stat_rot, frames


def point_errors(
    model: CPCModel, ms: MeasurementSet, markers: dict[str, Array], q: Array | None = None
) -> dict[str, Array]:
    """Distance [m] from each measured point (marker, or measured frame's origin) to the model's
    prediction at readings ``q`` (default ``ms.q``), per marker / frame, over the records that
    measured it."""
    q = ms.q if q is None else q
    out: dict[str, Array] = {}
    for m, p in markers.items():
        if m not in ms.marker_points:
            continue
        rows = ms.has_marker(m)
        T = model.fk(q[rows], [ms.markers[m].frame])[ms.markers[m].frame]
        out[m] = np.linalg.norm(T[:, :3, :3] @ p + T[:, :3, 3] - ms.marker_points[m][rows], axis=1)
    for f in ms.frames:
        rows = ms.has_pose(f)
        T = model.fk(q[rows], [f])[f]
        out[f] = np.linalg.norm(T[:, :3, 3] - ms.poses[f][rows][:, :3, 3], axis=1)
    return out


def readings_within_limits(structure: RobotStructure, n: int, seed: int = 0) -> Array:
    """``n`` seeded readings uniform within every joint's limits, shape (n, joints)."""
    lo = np.array([j.lower for j in structure.joints])
    hi = np.array([j.upper for j in structure.joints])
    return np.random.default_rng(seed).uniform(lo, hi, (n, structure.n_joints))


def first_point(fit: MapFit, ms: MeasurementSet, q: Array) -> Array:
    """World prediction [m] of the first measured point (marker, else frame origin) of ``ms`` at
    readings ``q`` (N, n) with the geometry alone (no deflection), shape (N, 3)."""
    if fit.markers:
        m = next(iter(fit.markers))
        frame = ms.markers[m].frame
        T = fit.model.fk(q, [frame])[frame]
        return T[:, :3, :3] @ fit.markers[m] + T[:, :3, 3]
    return fit.model.fk(q, [ms.frames[0]])[ms.frames[0]][:, :3, 3]


def folds(n: int, k: int = CV_FOLDS, seed: int = 0) -> list[Array]:
    """The records of each fold: ``array_split`` of a seeded permutation."""
    return list(np.array_split(np.random.default_rng(seed).permutation(n), k))


def cross_validate(
    ms: MeasurementSet,
    fit: Callable[[MeasurementSet, Array | None], MapFit],
    loads: Array | None = None,
    k: int = CV_FOLDS,
) -> Array:
    """Every held-out distance [m] of ``k``-fold cross-validation: each fold's records predicted by
    ``fit(training records, their loads)``."""
    errs: list[Array] = []
    for test in folds(ms.n_records, k):
        train = np.setdiff1d(np.arange(ms.n_records), test)
        f = fit(ms.subset(train), None if loads is None else loads[train])
        held = ms.subset(test)
        q = f.deflected(held.q, None if loads is None else loads[test])
        errs += list(point_errors(f.model, held, f.markers, q).values())
    return np.concatenate(errs)


@dataclass(frozen=True, eq=False)
class Selection:
    """The model chosen among the levels, and why.

    Attributes:
        fit: The chosen level's fit on every record.
        fits: Every level's fit, by level (``compliance`` only with loads).
        chosen: The chosen level.
    """

    fit: MapFit
    fits: dict[str, MapFit]

    @property
    def chosen(self) -> str:
        return self.fit.level

    @property
    def beats_urdf(self) -> bool:
        """False when the URDF as it is (``frames``) predicts held-out records at least as well."""
        return self.chosen != "frames"


def select_model(
    nominal: CPCModel,
    ms: MeasurementSet,
    joints: Sequence[str] | None = None,
    tolerances: Tolerances | None = None,
    loads: Array | None = None,
    margin: float = SELECTION_MARGIN,
    noise: Noise | None = None,
) -> Selection:
    """Fit every level and keep the one that predicts left-out records best.

    Each level is scored by its leave-one-record-out residuals (:attr:`MapFit.loo_sq_m2`, and for
    frame poses their orientations too, :attr:`MapFit.loo_rot_sq`, weighed by the URDF-as-is
    fit's position / orientation noise so that both count on one scale). The default is
    ``geometry``: its prior already keeps what the data barely see at the URDF's values. A level
    that departs from it (compliance added, or offsets alone) must lower the RMS of that score by
    more than ``margin`` (a fraction; few records cannot tell small differences apart), and the
    URDF as it is (``frames``) is kept whenever it scores no worse than the level chosen. A stated
    ``noise`` is used as it is; without one the noise is estimated.
    """
    levels = [lv for lv in LEVELS if lv != "compliance" or loads is not None]
    fits = {
        lv: fit_map(
            nominal, ms, lv, joints, tolerances, noise, estimate_noise=noise is None, loads=loads
        )
        for lv in levels
    }
    base = fits["frames"].noise
    weight = (base.position_m / base.rotation_rad) ** 2 if ms.frames else 0.0  # [m^2 / rad^2]

    def score(f: MapFit) -> float:
        return float(f.loo_sq_m2.sum() + weight * f.loo_rot_sq.sum())

    best = fits["geometry"]
    for lv in ("compliance", "offsets"):
        if lv in fits and score(fits[lv]) < (1.0 - margin) ** 2 * score(best):
            best = fits[lv]
    if score(fits["frames"]) <= score(best):
        best = fits["frames"]
    return Selection(best, fits)


__all__ = [
    "LEVELS",
    "MapFit",
    "Noise",
    "Tolerances",
    "cross_validate",
    "default_joints",
    "fit_map",
    "folds",
    "perturbation",
    "first_point",
    "readings_within_limits",
    "point_errors",
    "select_model",
    "Selection",
]
