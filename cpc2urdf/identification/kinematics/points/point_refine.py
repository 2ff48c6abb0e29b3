"""Maximum-likelihood refinement from position-only data (marker points), and its start.

:func:`refine_points` minimises the weighted marker residuals of :mod:`point_problem` over the
joints' minimal chart (:mod:`parametrization`), the placements of frames with markers of known
position, and the unknown marker positions, with the solver of :mod:`refine` (Levenberg-Marquardt,
chart re-centred after large axis turns). The result carries the identifiability analysis
(:func:`identifiability.analyze_jacobian` of the point Jacobian, plus what point data cannot
determine by construction: :func:`undetermined_by_points`) and the covariance: of the model
parameters in the model's own chart (the ``uncertainty`` section of a model file, with the
unidentified frame blocks in its null space) and of the marker positions.

:func:`point_start` chooses the start: the circle-point closed form (:mod:`circle_point`) when the
records follow the one-joint-at-a-time protocol, else the nominal model placed in world
(:func:`circle_point.nominal_point_start`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import OptimizeResult

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import Marker, MeasurementSet
from cpc2urdf.identification.kinematics.identifiability import (
    IdentifiabilityReport,
    analyze_jacobian,
    scaled_svd,
)
from cpc2urdf.identification.kinematics.points.circle_point import (
    circle_point_start,
    nominal_point_start,
)
from cpc2urdf.identification.kinematics.points.point_problem import PointChart, PointProblem
from cpc2urdf.identification.kinematics.refine import (
    MAX_RECENTRES,
    RECENTRE_TILT,
    solve_least_squares,
)
from cpc2urdf.identification.kinematics.uncertainty import with_uncertainty
from cpc2urdf.model import CPCModel
from cpc2urdf.model_metadata import Covariance
from cpc2urdf.transforms import Array

RANK_TOL = 1e-9  # [-]: as identifiability.RANK_TOL


@dataclass
class PointRefinement:
    """What :func:`refine_points` returns.

    Attributes:
        model: The refined model (``metadata.uncertainty``: covariance in its own chart).
        positions: Marker name -> position in its frame [m], shape (3,).
        position_std: Marker name -> standard deviation of each coordinate [m], shape (3,)
            (zeros for markers of known position; inf where undetermined).
        chart: The :class:`PointChart` at the optimum.
        identifiability: Rank analysis of the weighted point Jacobian at the optimum.
        undetermined: Plain statements of what point data cannot determine (by construction).
        sigma_p: Noise per coordinate behind the weights [m].
        variance_factor: ``|r|^2 / dof`` of the weighted residuals (1 when ``sigma_p`` is right).
        dof: Residuals minus rank.
        cost: Half the sum of squared weighted residuals.
        n_points: Points used.
        rms: RMS 3-D point residual [m].
        residuals: Marker -> per record 3-D residual distance [m], shape (N,) (NaN where unseen).
        iterations: Solver evaluations.
        seconds: Wall time [s].
        success: The solver converged.
        message: The solver's message.
    """

    model: CPCModel
    positions: dict[str, Array]
    position_std: dict[str, Array]
    chart: PointChart
    identifiability: IdentifiabilityReport
    undetermined: list[str]
    sigma_p: float
    variance_factor: float
    dof: int
    cost: float
    n_points: int
    rms: float
    residuals: dict[str, Array] = field(default_factory=dict)
    iterations: int = 0
    seconds: float = 0.0
    success: bool = True
    message: str = ""


def undetermined_by_points(ms: MeasurementSet, markers: list[str]) -> list[str]:
    """What marker points cannot determine by construction, one sentence per frame."""
    out = []
    for f in dict.fromkeys(ms.markers[m].frame for m in markers):
        on = [m for m in markers if ms.markers[m].frame == f]
        known = [m for m in on if ms.markers[m].known]
        if not known:
            out.append(
                f"{f}: its placement on its link (orientation and origin) is not determined by point "
                f"data (kept at the nominal placement, or the start's without one); the {len(on)} marker position(s) are identified in it"
            )
        elif len(known) < 3:
            out.append(
                f"{f}: {len(known)} marker(s) of known position cannot fix its orientation "
                f"({'a rotation about any axis through the marker' if len(known) == 1 else 'a rotation about the line through the two markers'} is free)"
            )
    return out


def _covariance(J: Array, r: Array, names: tuple[str, ...]) -> tuple[Array, Array, int, float]:
    """``(C, null, dof, s0)``: pseudo-inverse covariance of ``J``'s parameters (column-scaled)."""
    d, s, Vt = scaled_svd(J)
    keep = s / (s[0] if s[0] > 0 else 1.0) >= RANK_TOL
    Vk = Vt[keep].T / d[:, None]
    C = (Vk / s[keep] ** 2) @ Vk.T
    V0 = Vt[~keep].T / d[:, None]
    if V0.size:
        V0 = V0 / np.linalg.norm(V0, axis=0)
    dof = max(J.shape[0] - int(keep.sum()), 1)
    return 0.5 * (C + C.T), V0, dof, float(r @ r / dof)


def _solve_recentred(
    chart: PointChart,
    markers: list[Marker],
    q: Array,
    points: Mapping[str, Array],
    used: Mapping[str, NDArray[np.bool_]],
    sigma_p: float,
    max_nfev: int | None,
) -> tuple[PointChart, Array, OptimizeResult, int]:
    """Solve from ``chart``, re-centring it after large axis turns (at most MAX_RECENTRES times).

    Returns:
        ``(chart, x, sol, nfev)``: the last chart, the solution in it, the last solver result and
        the solver evaluations of all stages.
    """
    x = np.zeros(chart.n_params)
    nfev = 0
    sol = None
    for _ in range(MAX_RECENTRES + 1):
        sol = solve_least_squares(PointProblem(chart, q, points, used, sigma_p), x, max_nfev)
        x, nfev = sol.x, nfev + int(sol.nfev)
        mc = chart.model_chart
        tilt = max(
            (float(np.hypot(*chart.model_vector(x)[b.start : b.start + 2])) for b in mc.blocks),
            default=0.0,
        )
        if tilt < RECENTRE_TILT:
            break
        chart = PointChart(chart.model_from_vector(x), markers, chart.positions_from_vector(x))
        x = np.zeros(chart.n_params)
    assert sol is not None
    return chart, x, sol, nfev


def _marker_std(final: PointChart, markers: list[Marker], C: Array, V0: Array) -> dict[str, Array]:
    """Marker position std from ``C``: zeros for known markers, inf along undetermined directions."""
    std: dict[str, Array] = {}
    for mk in markers:
        slot = final.marker_slot(mk.name)
        if slot is None:
            std[mk.name] = np.zeros(3)
            continue
        sd = np.sqrt(np.clip(np.diag(C)[slot : slot + 3], 0.0, None))
        if V0.size:
            sd = np.where(np.linalg.norm(V0[slot : slot + 3], axis=1) > 1e-6, np.inf, sd)
        std[mk.name] = sd
    return std


def _model_covariance(final: PointChart, C: Array, V0: Array) -> tuple[Array, Array]:
    """``(Cm, null)`` in the model's own chart: free columns from ``C``, fixed frame blocks and
    ``V0``'s model part in the null space."""
    k = final.n_model_params
    mc = final.model_chart
    P = mc.n_params
    Cm = np.zeros((P, P))
    cols = final.columns
    Cm[np.ix_(cols, cols)] = C[:k, :k]
    nulls = []
    for b in mc.blocks:
        if b.kind == "frame" and b.owner in final.fixed_frames:
            for i in range(b.start, b.start + len(b.params)):
                e = np.zeros(P)
                e[i] = 1.0
                nulls.append(e)
    if V0.size:
        for v in V0.T:
            e = np.zeros(P)
            e[cols] = v[:k]
            if np.linalg.norm(e) > 1e-6:
                nulls.append(e / np.linalg.norm(e))
    null = np.array(nulls).T if nulls else np.zeros((P, 0))
    return Cm, null


def _residual_table(
    blocks: Mapping[str, Array],
    seen: Mapping[str, NDArray[np.bool_]],
    names: list[str],
    n_records: int,
) -> dict[str, Array]:
    """Marker -> per record 3-D residual distance [m] (NaN where unseen)."""
    res_table: dict[str, Array] = {}
    for m in names:
        tab = np.full(n_records, np.nan)
        tab[np.flatnonzero(seen[m])] = np.linalg.norm(blocks[m], axis=1)
        res_table[m] = tab
    return res_table


def refine_points(
    model: CPCModel,
    ms: MeasurementSet,
    positions: Mapping[str, Array],
    sigma_p: float,
    *,
    covariance_scale: str = "known",
    use: Mapping[str, NDArray[np.bool_]] | None = None,
    max_nfev: int | None = 200,
    warn: bool = True,
) -> PointRefinement:
    """Weighted least squares of the model and the unknown marker positions from marker points.

    Args:
        model: Start model (circle-point or placed nominal); its gauge is kept.
        ms: Position-only measurements.
        positions: Start marker positions in their frames [m] (every seen marker).
        sigma_p: Noise of each measured coordinate [m].
        covariance_scale: ``"known"`` or ``"a_posteriori"`` (scale by the variance factor).
        use: Marker -> records that take part (default: every seen point).
        max_nfev: Cap on solver evaluations per stage.
        warn: Issue :class:`IdentifiabilityWarning` for undetermined parameters.

    Raises:
        DegenerateDataError: No marker seen, or a non-positive sigma.
    """
    t0 = time.perf_counter()
    q = np.atleast_2d(model.structure.check_q(ms.q))
    names = [m for m in ms.marker_points if ms.has_marker(m).any()]
    if not names:
        raise DegenerateDataError(f"{ms.source}: no marker was seen in any record")
    markers = [ms.markers[m] for m in names]
    seen = {m: ms.has_marker(m) for m in names}
    used = {
        m: (np.asarray(use[m], dtype=bool) & seen[m]) if use is not None and m in use else seen[m]
        for m in names
    }
    points = {m: ms.marker_points[m] for m in names}
    chart = PointChart(model, markers, positions)
    chart, x, sol, nfev = _solve_recentred(chart, markers, q, points, used, sigma_p, max_nfev)
    refined = chart.model_from_vector(x)
    final = PointChart(refined, markers, chart.positions_from_vector(x))
    problem = PointProblem(final, q, points, used, sigma_p)
    x0 = np.zeros(final.n_params)
    r = problem.residuals(x0)
    J = problem.jacobian(x0)
    ident = analyze_jacobian(J, final.names, warn=warn)
    C, V0, dof, s0 = _covariance(J, r, final.names)
    if covariance_scale == "a_posteriori":
        C = s0 * C
    # Marker position std; inf along undetermined directions.
    k = final.n_model_params
    pos = final.positions_from_vector(x0)
    std = _marker_std(final, markers, C, V0)
    # The model's own chart: free columns from C, fixed frame blocks in the null space.
    mc = final.model_chart
    Cm, null = _model_covariance(final, C, V0)
    blocks = PointProblem(final, q, points, seen, sigma_p).residual_blocks(x0)
    res_table = _residual_table(blocks, seen, names, ms.n_records)
    used_res = np.concatenate([res_table[m][used[m]] for m in names])
    undetermined = undetermined_by_points(ms, names)
    seconds = time.perf_counter() - t0
    cov = Covariance(
        mc.names,
        mc.units,
        mc.frames,
        0.5 * (Cm + Cm.T),
        null,
        covariance_scale,
        s0,
        dof,
        float(sigma_p),
        0.0,
        details={
            "refinement": {
                "method": "weighted least squares of marker points (scipy least_squares, Levenberg-Marquardt)",
                "parameters": final.n_params,
                "model_parameters": k,
                "marker_parameters": final.n_params - k,
                "gauge": mc.gauge_description()
                + "; frames with no marker of known position: their placement",
                "points_used": problem.n_points,
                "seconds": seconds,
            },
            "identifiability": ident.to_json(),
            "not_determined_by_points": undetermined,
            "markers": {
                m: {
                    "frame": ms.markers[m].frame,
                    "position_m": [float(v) for v in pos[m]],
                    "std_m": [float(v) if np.isfinite(v) else None for v in std[m]],
                    "known": ms.markers[m].known,
                }
                for m in names
            },
        },
    )
    refined = with_uncertainty(refined, cov)
    return PointRefinement(
        model=refined,
        positions=pos,
        position_std=std,
        chart=final,
        identifiability=ident,
        undetermined=undetermined,
        sigma_p=float(sigma_p),
        variance_factor=s0,
        dof=dof,
        cost=0.5 * float(r @ r),
        n_points=problem.n_points,
        rms=float(np.sqrt(np.mean(used_res**2))) if used_res.size else 0.0,
        residuals=res_table,
        iterations=nfev,
        seconds=seconds,
        success=bool(sol.success),
        message=str(sol.message),
    )


def point_start(
    ms: MeasurementSet, nominal: CPCModel | None, sigma_p: float
) -> tuple[CPCModel, dict[str, Array], str, list[str]]:
    """Where a point-data refinement starts.

    Returns:
        ``(model, positions, kind, notes)``: ``kind`` is ``"circle-point"`` (one-joint-at-a-time
        records) or ``"nominal"`` (other configurations; the nominal model placed in world).

    Raises:
        DegenerateDataError: Neither applies (the message says why the closed form does not),
            or the circle-point analysis refuses the data (a marker on the wrong link, too few
            markers for a joint).
    """
    from cpc2urdf.identification.kinematics.protocol import recognise_protocol

    try:
        recognise_protocol(ms)
    except DegenerateDataError as e:
        if nominal is None:
            raise DegenerateDataError(
                f"position-only identification needs a start: the circle-point closed form needs the "
                f"one-joint-at-a-time protocol ({e}) and the robot has no nominal geometry"
            ) from e
        model, pos = nominal_point_start(nominal, ms)
        return (
            model,
            pos,
            "nominal",
            [
                f"closed form not applicable ({e}); refinement started from the nominal model placed in world "
                "by a rigid fit of the marker points"
            ],
        )
    start = circle_point_start(ms, nominal, sigma_p)
    return start.model, start.positions, "circle-point", start.notes


__all__ = ["PointRefinement", "point_start", "refine_points", "undetermined_by_points"]
