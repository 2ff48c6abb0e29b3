"""Measurement noise for simulated stage-1 data (Shih et al. sec. 6, Fig. 10) and from a stereo rig.

Two models of the error of a measured plate pose ``T_world_plate``:

- **Fig. 10** (:func:`fig10_noise`): add N(0, sigma_t) to each entry of the translation, and
  pre-multiply the rotation by a rotation about a uniformly random axis through an angle drawn
  from N(0, sigma_r): ``R_meas = Rot(u, phi) R``. (The paper's σ_O is in mm and degrees.) This
  is the package's one pose-perturbation convention: the simulated true robot's geometric errors
  (:mod:`~cpc2urdf.identification.simulation.truth`) follow it too.
- **Stereo** (:func:`stereo_noise`): what the paper's rig actually does. Project the plate's
  circle centres into both cameras, add N(0, sigma_px) to every pixel coordinate, triangulate
  (``cv2.triangulatePoints``), and register the plate layout to the triangulated points (Arun,
  sec. 3.3). Its pose error follows from the rig geometry; ``cpc2urdf study stereo`` measures it.

Both are models of a *simulated* measurement (the real one is :mod:`~cpc2urdf.identification.
vision`), hence they live with the simulator, which applies them per record
(:func:`~cpc2urdf.identification.simulation.measure_poses.measure_poses`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.registration import plate_pose_from_points

Array = NDArray[np.float64]


def random_rotations(rng: np.random.Generator, sigma_rad: float, size: int) -> Array:
    """Rotations about uniformly random axes by angles drawn from N(0, sigma_rad).

    Args:
        rng: Random generator (seeded by the caller).
        sigma_rad: Standard deviation of the angle [rad].
        size: How many.

    Returns:
        Rotation matrices, shape (size, 3, 3).
    """
    axis = rng.normal(size=(size, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)  # isotropic normal -> uniform on S^2
    angle = rng.normal(0.0, sigma_rad, size=size)
    return Rotation.from_rotvec(axis * angle[:, None]).as_matrix()


def fig10_noise(
    T_world_frame: ArrayLike, sigma_t: float, sigma_r: float, rng: np.random.Generator
) -> Array:
    """The noise model of Shih et al. Fig. 10 applied to poses.

    Args:
        T_world_frame: True poses, shape (4, 4) or (N, 4, 4); NaN poses stay NaN.
        sigma_t: Standard deviation of each translation entry [m].
        sigma_r: Standard deviation of the rotation angle [rad] (random axis).
        rng: Random generator.

    Returns:
        Noisy poses of the same shape. ``R_meas = Rot(u, phi) R_true`` (pre-multiplied, i.e. a
        rotation error expressed in world), ``t_meas = t_true + N(0, sigma_t^2 I)``.
    """
    T = np.asarray(T_world_frame, dtype=float)
    single = T.ndim == 2
    TT = np.array(T[None] if single else T)
    n = TT.shape[0]
    dR = random_rotations(rng, sigma_r, n)
    dt = rng.normal(0.0, sigma_t, size=(n, 3))
    TT[:, :3, :3] = dR @ TT[:, :3, :3]
    TT[:, :3, 3] += dt
    return TT[0] if single else TT


def stereo_noise(
    T_world_plate: ArrayLike,
    layout_plate: ArrayLike,
    rig: StereoRig,
    sigma_px: float,
    rng: np.random.Generator,
    *,
    margin_px: float = 0.0,
) -> tuple[Array, Array]:
    """Measure plates through a stereo rig with pixel noise: project, perturb, triangulate, register.

    Args:
        T_world_plate: True plate poses in world = left camera frame, shape (N, 4, 4).
        layout_plate: The plate's circle centres in the plate frame [m], shape (K, 3).
        rig: The measuring rig.
        sigma_px: Standard deviation of each pixel coordinate of each circle centre [px].
        rng: Random generator.
        margin_px: Circles closer than this to an image border count as not seen.

    Returns:
        ``(T_world_plate_measured, p_world_measured)``: shapes (N, 4, 4) and (N, K, 3). Circles
        that a camera does not see are NaN points; a plate with fewer than 3 seen circles gets
        a NaN pose.
    """
    T = np.asarray(T_world_plate, dtype=float)
    layout = np.asarray(layout_plate, dtype=float)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise ValueError(f"T_world_plate must have shape (N, 4, 4), got {T.shape}")
    p_true = np.einsum("nij,kj->nki", T[:, :3, :3], layout) + T[:, None, :3, 3]  # (N, K, 3)
    seen = rig.in_view(p_true, margin_px=margin_px)
    uv1, uv2 = rig.project(p_true)
    uv1 = uv1 + rng.normal(0.0, sigma_px, size=uv1.shape)
    uv2 = uv2 + rng.normal(0.0, sigma_px, size=uv2.shape)
    p_meas = rig.triangulate(uv1, uv2)
    p_meas[~seen] = np.nan
    T_meas = np.full_like(T, np.nan)
    enough = seen.sum(axis=1) >= 3
    if enough.any():
        try:
            T_meas[enough] = plate_pose_from_points(
                layout, p_meas[enough], what="stereo measurement"
            )
        except DegenerateDataError:
            for i in np.flatnonzero(enough):  # rare: the seen circles of one plate are collinear
                try:
                    T_meas[i] = plate_pose_from_points(layout, p_meas[i])
                except DegenerateDataError:
                    pass
    return T_meas, p_meas


__all__ = ["fig10_noise", "random_rotations", "stereo_noise"]
