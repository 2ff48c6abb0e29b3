"""Rigid registration of a plate's known circle layout to measured 3D points (Shih et al. sec. 3.3).

Shih et al. write eq. (16) as ``q_i = R p_i + t`` with ``p_i`` the measured world points and
``q_i`` the plate layout, so their (R, t) is ``T_plate_world``. We solve the same least-squares
problem (eq. (17)) the other way round, mapping layout points onto world points, and so obtain
``T_world_plate`` directly (the optimum of one direction is the inverse of the other's: the
residuals only differ by a rotation, which keeps their norms).

The rotation follows Arun et al. (eqs. (18)-(22)): centre both point sets, form the correlation
matrix ``H``, take its SVD ``H = U S V^T`` and ``R = V U^T``. When ``det(V U^T) = -1`` (a
reflection, which happens for coplanar points such as a plate's circles under noise) the column
of ``V`` of the smallest singular value is negated (Arun's remedy, in the Umeyama form that is
optimal in every case). Everything is vectorised over a leading batch axis, and missing points
(NaN rows, e.g. occluded circles) are simply left out.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.tolerances import COLLINEAR_TOL

Array = NDArray[np.float64]


def transforms_from_point_pairs(p_a: ArrayLike, p_b: ArrayLike, *, what: str = "points") -> Array:
    """Least-squares rigid transforms ``T_b_a`` with ``p_b ≈ R p_a + t`` (eqs. (17)-(22)).

    Args:
        p_a: Points in frame a [m], shape (K, 3) or (N, K, 3) (e.g. the plate layout, broadcast).
        p_b: The same points measured in frame b [m], shape (K, 3) or (N, K, 3). Rows with any
            NaN in either set are ignored.
        what: Name used in error messages (e.g. ``"record 3 plate_left points"``).

    Returns:
        ``T_b_a``, shape (4, 4), or (N, 4, 4) for batched input.

    Raises:
        DegenerateDataError: Fewer than 3 usable point pairs, or the points are collinear (the
            rotation about their line is then undetermined).
    """
    a = np.asarray(p_a, dtype=float)
    b = np.asarray(p_b, dtype=float)
    single = a.ndim == 2 and b.ndim == 2
    if a.ndim not in (2, 3) or b.ndim not in (2, 3) or a.shape[-1] != 3 or b.shape[-1] != 3:
        raise ValueError(
            f"{what}: points must have shape (K, 3) or (N, K, 3), got {a.shape} and {b.shape}"
        )
    try:
        a, b = np.broadcast_arrays(a, b)
    except ValueError:
        raise ValueError(
            f"{what}: point sets of shapes {a.shape} and {b.shape} do not pair up"
        ) from None
    if single:
        a, b = a[None], b[None]
    w = (np.all(np.isfinite(a), axis=-1) & np.all(np.isfinite(b), axis=-1)).astype(float)  # (N, K)
    a = np.where(w[..., None] > 0, a, 0.0)
    b = np.where(w[..., None] > 0, b, 0.0)
    n = w.sum(axis=-1)  # (N,)
    bad = np.flatnonzero(n < 3)
    if bad.size:
        i = int(bad[0])
        where = what if single else f"{what} [{i}]"
        raise DegenerateDataError(f"{where}: need at least 3 measured points, got {int(n[i])}")
    # eq. (18): the translation follows from the centroids.
    a_bar = (w[..., None] * a).sum(axis=1) / n[:, None]
    b_bar = (w[..., None] * b).sum(axis=1) / n[:, None]
    ac = (a - a_bar[:, None]) * w[..., None]
    bc = (b - b_bar[:, None]) * w[..., None]
    _check_not_collinear(ac, what, single, "layout")
    _check_not_collinear(bc, what, single, "measured")
    # eq. (22): H = sum_i a_i b_i^T of the centred points; maximise trace(R H) (eq. (21)).
    H = np.einsum("nki,nkj->nij", ac, bc)
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, -1, -2)))
    d[d == 0] = 1.0
    # Reflection case: negate V's column of the smallest singular value (SVD sorts descending).
    V[..., :, 2] *= d[:, None]
    R = V @ np.swapaxes(U, -1, -2)
    T = np.zeros((a.shape[0], 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = b_bar - np.einsum("nij,nj->ni", R, a_bar)
    T[:, 3, 3] = 1.0
    return T[0] if single else T


def _check_not_collinear(centred: Array, what: str, single: bool, which: str) -> None:
    s = np.linalg.svd(centred, compute_uv=False)  # (N, 3), descending
    scale = np.maximum(s[:, 0], 1e-300)
    bad = np.flatnonzero(s[:, 1] <= COLLINEAR_TOL * scale)
    if bad.size:
        i = int(bad[0])
        where = what if single else f"{what} [{i}]"
        raise DegenerateDataError(
            f"{where}: the {which} points are collinear (or coincide); a rigid pose needs at "
            "least 3 points that span a plane"
        )


def plate_pose_from_points(
    layout_plate: ArrayLike, p_world: ArrayLike, *, what: str = "plate"
) -> Array:
    """``T_world_plate`` from measured circle centres (sec. 3.3, solved as ``T_world_plate``).

    Args:
        layout_plate: Circle centres in the plate frame [m], shape (K, 3) (``Frame.layout``).
        p_world: Measured centres in world [m], shape (K, 3) or (N, K, 3), in layout order;
            NaN rows mark circles that were not measured.
        what: Name used in error messages.

    Returns:
        ``T_world_plate``, shape (4, 4) or (N, 4, 4).

    Raises:
        DegenerateDataError: Fewer than 3 measured circles, or collinear ones.
        ValueError: ``p_world`` does not have one row per layout point.
    """
    layout = np.asarray(layout_plate, dtype=float)
    p = np.asarray(p_world, dtype=float)
    if layout.ndim != 2 or layout.shape[1] != 3:
        raise ValueError(f"{what}: layout must have shape (K, 3), got {layout.shape}")
    if p.shape[-2:] != layout.shape:
        raise ValueError(
            f"{what}: expected {layout.shape[0]} measured points (one per layout circle), got shape {p.shape}"
        )
    if p.ndim == 2:
        return transforms_from_point_pairs(layout, p, what=what)
    return transforms_from_point_pairs(np.broadcast_to(layout, p.shape), p, what=what)


def registration_rms(T_b_a: ArrayLike, p_a: ArrayLike, p_b: ArrayLike) -> Array:
    """RMS residual ``sqrt(mean |p_b - T_b_a p_a|^2)`` [m] over the finite point pairs.

    Args:
        T_b_a: Shape (4, 4) or (N, 4, 4).
        p_a: Shape (K, 3) or (N, K, 3).
        p_b: Shape (K, 3) or (N, K, 3).

    Returns:
        Shape () or (N,).
    """
    T = np.asarray(T_b_a, dtype=float)
    a = np.asarray(p_a, dtype=float)
    b = np.asarray(p_b, dtype=float)
    pred = np.einsum("...ij,...kj->...ki", T[..., :3, :3], a) + T[..., None, :3, 3]
    r2 = np.sum((b - pred) ** 2, axis=-1)
    ok = np.isfinite(r2)
    return np.sqrt(np.where(ok, r2, 0.0).sum(axis=-1) / np.maximum(ok.sum(axis=-1), 1))


__all__ = [
    "plate_pose_from_points",
    "registration_rms",
    "transforms_from_point_pairs",
]
