"""Uncertainty of the origins a calibrated URDF gets: the model's covariance, propagated.

A model identified with ``--method refined`` carries the covariance ``C`` of its identifiable
parameters in its own local chart (:mod:`uncertainty`, :mod:`parametrization`). Each calibrated
joint's new ``<origin>`` (:mod:`cpc2urdf.urdf.origins`) is a function ``O(x)`` of the chart's
coordinates ``x``; to first order its position moves by ``G_p x``, its orientation by the rotation
vector ``G_w x`` (in the joint frame) and a moving joint's axis direction (in the parent link's
frame) by ``G_a x``, with the Jacobians taken by central differences (the map is smooth and cheap:
one write-back plan per parameter and side). The spreads are ``sqrt(trace(G C G^T))``: the RMS
Euclidean position error [m] and the RMS angle errors [rad]. A Jacobian that sees a direction the
data leave undetermined (``C``'s null space) gives ``None``, never a number.

This is in the identification layer because the chart is; the report that prints it is core
(:mod:`cpc2urdf.urdf.report`), and ``cpc2urdf.api`` joins the two.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.uncertainty import NULL_VISIBILITY_TOL
from cpc2urdf.model import CPCModel
from cpc2urdf.model_metadata import NoUncertaintyError
from cpc2urdf.transforms import Array
from cpc2urdf.urdf.origins import OriginChange, WritebackPlan, plan_for_tree, writeback_plan
from cpc2urdf.urdf.report import OriginStd

FD_STEP = 1e-6  # [m] or [rad] per chart coordinate: central differences, error ~1e-12 relative


def _features(c: OriginChange, ref: OriginChange) -> Array:
    """Position [m], rotation vector relative to ``ref`` [rad], and axis direction in the parent
    frame (moving joints) of one origin, concatenated."""
    w = Rotation.from_matrix(ref.calibrated[:3, :3].T @ c.calibrated[:3, :3]).as_rotvec()
    axis = c.calibrated[:3, :3] @ c.axis if c.axis is not None else np.zeros(0)
    return np.concatenate([c.calibrated[:3, 3], w, axis])


def _spread(G: Array, C: Array, null_space: Array) -> float | None:
    if null_space.size and G.size:
        typical = np.linalg.norm(G) / np.sqrt(G.shape[1])
        if np.linalg.norm(G @ null_space) > NULL_VISIBILITY_TOL * max(typical, 1e-300):
            return None
    return float(np.sqrt(max(np.trace(G @ C @ G.T), 0.0)))


def origin_uncertainty(model: CPCModel, plan: WritebackPlan | None = None) -> dict[str, OriginStd]:
    """1-sigma spread of every calibrated joint's new origin (module docstring).

    Args:
        model: A model built from a URDF; without an ``uncertainty`` section the result is empty.
        plan: Its write-back plan (default: :func:`~cpc2urdf.urdf.origins.writeback_plan`).

    Returns:
        URDF joint -> :class:`~cpc2urdf.urdf.report.OriginStd` [m, rad]. Joints the covariance
        does not reach (a camera placed by hand-eye calibration) get none.

    Raises:
        NoUncertaintyError: The covariance does not belong to this model's chart.
    """
    cov = model.metadata.uncertainty
    if cov is None:
        return {}
    plan = plan if plan is not None else writeback_plan(model)
    p = Parametrization(model, cov.frames)
    if p.names != cov.names:
        raise NoUncertaintyError(
            f"uncertainty parameters {list(cov.names)[:4]}... do not match the model's chart "
            f"{list(p.names)[:4]}... (was the model edited after identification?)"
        )
    reach = {b.owner for b in p.blocks}
    ref = {c.joint.name: c for c in plan.changes}
    columns: dict[str, list[Array]] = {name: [] for name in ref}
    for k in range(p.n_params):
        x = np.zeros(p.n_params)
        x[k] = FD_STEP
        plus = plan_for_tree(p.model_from_vector(x), plan.tree, plan.source).changes
        minus = plan_for_tree(p.model_from_vector(-x), plan.tree, plan.source).changes
        for a, b in zip(plus, minus, strict=True):
            r = ref[a.joint.name]
            columns[a.joint.name].append((_features(a, r) - _features(b, r)) / (2 * FD_STEP))
    out: dict[str, OriginStd] = {}
    for name, cols in columns.items():
        c = ref[name]
        if c.owner not in reach:
            continue
        G = np.stack(cols, axis=1)  # (features, P)
        out[name] = OriginStd(
            translation=_spread(G[0:3], cov.matrix, cov.null_space),
            rotation=_spread(G[3:6], cov.matrix, cov.null_space),
            axis=_spread(G[6:9], cov.matrix, cov.null_space) if c.axis is not None else None,
        )
    return out


__all__ = ["FD_STEP", "origin_uncertainty"]
