"""Covariance of a plate pose measured through a stereo rig with pixel noise, per view.

The simulator's stereo model (:func:`~cpc2urdf.identification.simulation.measurement_noise.stereo_noise`)
projects the plate's circle centres into both cameras, adds N(0, sigma_px) to every pixel
coordinate, triangulates and registers the layout to the triangulated points (Arun, sec. 3.3).
For small pixel noise the pose error is linear in the pixel errors: with ``H`` the Jacobian of
the pose error

    e = (p_meas - p_true,  log(R_meas R_true^T))        [m], [rad] (world; the residual of eq. (23))

with respect to the 4 K pixel coordinates (two images, K circles), the pose covariance is

    Sigma = sigma_px^2 H H^T                             (6 x 6 per plate and configuration)

``H`` is taken by central differences of the simulator's own measurement chain
(:meth:`StereoRig.project`, :meth:`StereoRig.triangulate`, :func:`plate_pose_from_points`) at the
true pose, the simulator's choices included: circles outside an image do not take part. A plate
far from the rig or seen obliquely gets a larger ``Sigma`` (depth error grows as distance^2 /
baseline), which is what a plan under stereo noise must see.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.registration import plate_pose_from_points

Array = NDArray[np.float64]

# Central-difference step on a pixel coordinate [px]: the chain is smooth; 1e-3 px keeps the
# truncation error ~1e-9 relative and far above the round-off of triangulation (~1e-12 m).
PIXEL_STEP = 1e-3


def pose_error(T_meas: Array, T_true: Array) -> Array:
    """``(p_meas - p_true, log(R_meas R_true^T))`` per pose, shape (N, 6) [m], [rad]."""
    dp = T_meas[:, :3, 3] - T_true[:, :3, 3]
    E = T_meas[:, :3, :3] @ np.swapaxes(T_true[:, :3, :3], 1, 2)
    return np.hstack([dp, Rotation.from_matrix(E).as_rotvec()])


def stereo_pose_covariance(
    T_world_plate: ArrayLike,
    layout_plate: ArrayLike,
    rig: StereoRig,
    pixel_sigma: float,
    *,
    margin_px: float = 0.0,
) -> Array:
    """Covariance of each stereo-measured plate pose's error (module docstring), shape (N, 6, 6).

    Args:
        T_world_plate: True plate poses in world = left camera frame, shape (N, 4, 4).
        layout_plate: The plate's circle centres in the plate frame [m], shape (K, 3).
        rig: The measuring rig.
        pixel_sigma: Standard deviation of each pixel coordinate [px].
        margin_px: Circles closer than this to an image border do not take part (as the simulator).

    Returns:
        Covariance of ``(dp, dtheta)`` [m^2, m rad, rad^2]; NaN for a plate with fewer than 3
        circles seen (the simulator gives no pose then).
    """
    T = np.asarray(T_world_plate, dtype=float)
    layout = np.asarray(layout_plate, dtype=float)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise ValueError(f"T_world_plate must have shape (N, 4, 4), got {T.shape}")
    n, k = len(T), len(layout)
    p_true = np.einsum("nij,kj->nki", T[:, :3, :3], layout) + T[:, None, :3, 3]  # (N, K, 3)
    seen = rig.in_view(p_true, margin_px=margin_px)
    ok = seen.sum(axis=1) >= 3
    out = np.full((n, 6, 6), np.nan)
    if not ok.any():
        return out
    uv = np.stack(rig.project(p_true[ok]), axis=0)  # (2, n_ok, K, 2): image, plate, circle, u/v
    s = seen[ok]

    def measure(uv_: Array) -> Array:
        pm = rig.triangulate(uv_[0], uv_[1])
        pm[~s] = np.nan
        return plate_pose_from_points(layout, pm, what="stereo measurement")

    H = np.zeros((int(ok.sum()), 6, 2 * k * 2))
    col = 0
    for cam in range(2):
        for c in range(k):
            for a in range(2):
                up, um = uv.copy(), uv.copy()
                up[cam, :, c, a] += PIXEL_STEP
                um[cam, :, c, a] -= PIXEL_STEP
                # Both differences against the same reference pose, so their difference is exact.
                H[:, :, col] = (pose_error(measure(up), T[ok]) - pose_error(measure(um), T[ok])) / (
                    2 * PIXEL_STEP
                )
                col += 1
    out[ok] = pixel_sigma**2 * H @ np.swapaxes(H, 1, 2)
    return out


__all__ = ["PIXEL_STEP", "pose_error", "stereo_pose_covariance"]
