"""Plate and target poses from detected circle centres (:mod:`~cpc2urdf.identification.vision.detect`).

Stage 1 (Shih et al. sec. 3): :func:`stereo_plate_poses` detects each plate in both images of
a stereo pair, triangulates the left/right centres with the rig (left/right correspondence is
by circle identity, checked by the epipolar reprojection error) and registers the layout to them
(Arun, eqs. (16)-(22)) -> ``T_world_plate``. Stage 2 (sec. 5): :func:`target_pose` gives
``T_camera_target`` of the 25-disk target with ``cv2.solvePnP``.

The projected centre of a circle is not the centre of its image ellipse (perspective): with
``correct_bias=True`` (default) the offset is predicted from the first pose estimate
(:func:`ellipse_centre_offset`, exact conic geometry) and removed before a second estimate.
At the paper's geometry the offset is 0.01-0.05 px (``docs/images.md``).

Failures are values, not crashes: every function returns, per plate, either a result or a
:class:`~cpc2urdf.identification.vision.detect.DetectionError` that names the image, the plate
and the reason, so the caller can skip the record or stop.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import Cpc2UrdfError
from cpc2urdf.identification.vision.detect import (
    DetectionError,
    InconsistentDetectionError,
    detect_plates,
)
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.identification.vision.targets import PlateDesign
from cpc2urdf.registration import plate_pose_from_points, registration_rms

Array = NDArray[np.float64]

MAX_EPIPOLAR_PX = 1.0  # [px] left/right detections disagreeing more than this are refused
MAX_PNP_RMS_PX = 0.5  # [px] a target pose reprojecting worse (RMS) is refused (wrong intrinsics)
MAX_FIT_RMS = 1.0e-3  # [m] a plate layout fitting its triangulated circles worse is refused (2x the paper's 0.5 mm)


# ---- the ellipse-centre bias ---------------------------------------------------------------------


def ellipse_centre_offset(K: ArrayLike, T_camera_plate: ArrayLike, design: PlateDesign) -> Array:
    """Image-ellipse centre minus projected circle centre, in ideal pixels [px], shape (K, 2).

    A circle ``(x - c)^T (x - c) = r^2`` in the plate plane is the conic ``C``; the plane-to-image
    homography ``H = K [r1 r2 t]`` maps it to ``C' = H^-T C H^-1``, whose centre is
    ``-A^-1 b`` for ``C' = [[A, b], [b^T, c]]``. The projected centre is ``H c``.
    """
    Km = np.asarray(K, dtype=float)
    T = np.asarray(T_camera_plate, dtype=float)
    H = Km @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])
    Hi = np.linalg.inv(H)
    out = np.zeros((design.n_circles, 2))
    for i, ((cx, cy, _), r) in enumerate(zip(design.layout, design.radii, strict=True)):
        C = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [-cx, -cy, cx * cx + cy * cy - r * r]])
        Cp = Hi.T @ C @ Hi
        centre = -np.linalg.solve(Cp[:2, :2], Cp[:2, 2])
        p = H @ np.array([cx, cy, 1.0])
        out[i] = centre - p[:2] / p[2]
    return out


# ---- stage 1: stereo -> T_world_plate --------------------------------------------------------------


@dataclass
class StereoPlatePose:
    """A plate measured by the stereo rig.

    Attributes:
        plate: Frame name.
        T_world_plate: Pose, shape (4, 4).
        p_world: Triangulated circle centres [m], shape (K, 3), layout order.
        uv_left: Left-image centres used (bias-corrected if asked) [px], shape (K, 2).
        uv_right: Right-image centres used [px], shape (K, 2).
        fit_rms: RMS registration residual [m].
        epipolar_rms: RMS reprojection error of the triangulated points [px].
        bias_px: Largest ellipse-centre offset that was corrected [px] (0 if not corrected).
    """

    plate: str
    T_world_plate: Array
    p_world: Array
    uv_left: Array
    uv_right: Array
    fit_rms: float
    epipolar_rms: float
    bias_px: float = 0.0


def _pose_from_uv(
    rig: StereoRig, design: PlateDesign, uv_l: Array, uv_r: Array
) -> tuple[Array, Array, float]:
    p = rig.triangulate(uv_l, uv_r)
    T = plate_pose_from_points(design.layout, p, what=design.name)
    return T, p, float(registration_rms(T, design.layout, p))


def stereo_plate_poses(
    image_left: ArrayLike,
    image_right: ArrayLike,
    rig: StereoRig,
    designs: Sequence[PlateDesign],
    *,
    names: tuple[str, str] = ("left", "right"),
    correct_bias: bool = True,
    max_epipolar_px: float = MAX_EPIPOLAR_PX,
    max_fit_rms: float = MAX_FIT_RMS,
) -> dict[str, StereoPlatePose | DetectionError]:
    """Detect every plate in a stereo pair and estimate ``T_world_plate`` (world = left camera).

    Args:
        image_left: Left grey image, uint8, shape (h, w).
        image_right: Right grey image.
        rig: The stereo rig (world = left camera).
        designs: The plates.
        names: The two images' names for messages (e.g. file paths).
        correct_bias: Remove the predicted ellipse-centre offset (see the module docstring).
        max_epipolar_px: Refuse a plate whose triangulated circles reproject worse (RMS) [px].
        max_fit_rms: Refuse a plate whose layout fits its triangulated circles worse (RMS) [m].
            Both catch a wrong rig file or swapped images, which otherwise give plausible poses.

    Returns:
        Per plate name, the pose or the :class:`DetectionError` saying why not.
    """
    det_l = detect_plates(image_left, rig.K1, rig.D1, designs, image_name=names[0])
    det_r = detect_plates(image_right, rig.K2, rig.D2, designs, image_name=names[1])
    out: dict[str, StereoPlatePose | DetectionError] = {}
    for d in designs:
        a, b = det_l[d.name], det_r[d.name]
        if isinstance(a, DetectionError):
            out[d.name] = a
            continue
        if isinstance(b, DetectionError):
            out[d.name] = b
            continue
        uv_l, uv_r = a.uv.copy(), b.uv.copy()
        try:
            T, p, rms = _pose_from_uv(rig, d, uv_l, uv_r)
        except Cpc2UrdfError as e:
            out[d.name] = InconsistentDetectionError(f"{names[0]} + {names[1]}", d.name, str(e))
            continue
        bias = 0.0
        if correct_bias:
            T_rl = np.eye(4)
            T_rl[:3, :3] = rig.R
            T_rl[:3, 3] = rig.T
            off_l = ellipse_centre_offset(rig.K1, T, d)
            off_r = ellipse_centre_offset(rig.K2, T_rl @ T, d)
            bias = float(max(np.abs(off_l).max(), np.abs(off_r).max()))
            uv_l, uv_r = uv_l - off_l, uv_r - off_r
            T, p, rms = _pose_from_uv(rig, d, uv_l, uv_r)
        pl, pr = rig.project(p)
        epi = float(
            np.sqrt(
                np.mean(np.concatenate([np.sum((pl - uv_l) ** 2, 1), np.sum((pr - uv_r) ** 2, 1)]))
            )
        )
        if epi > max_epipolar_px:
            out[d.name] = InconsistentDetectionError(
                f"{names[0]} + {names[1]}",
                d.name,
                f"left and right circle centres disagree by {epi:.2f} px RMS after triangulation "
                f"(> {max_epipolar_px} px): wrong rig file, or left/right images swapped?",
            )
            continue
        if rms > max_fit_rms:
            out[d.name] = InconsistentDetectionError(
                f"{names[0]} + {names[1]}",
                d.name,
                f"the plate layout fits the triangulated circles with {rms * 1e3:.2f} mm RMS "
                f"(> {max_fit_rms * 1e3:.2f} mm): wrong rig file (baseline, units), or left/right images swapped?",
            )
            continue
        # The printed face must point towards the left camera (origin of world).
        if -T[:3, 3] @ T[:3, 2] <= 0:
            out[d.name] = InconsistentDetectionError(
                f"{names[0]} + {names[1]}",
                d.name,
                "the estimated plate faces away from the cameras",
            )
            continue
        out[d.name] = StereoPlatePose(d.name, T, p, uv_l, uv_r, rms, epi, bias)
    return out


# ---- stage 2: one camera -> T_camera_target -------------------------------------------------------


@dataclass
class TargetPose:
    """The stage-2 target seen by one head camera.

    Attributes:
        T_camera_target: Pose of the target in the camera's optical frame, shape (4, 4).
        uv: Centres used (bias-corrected if asked) [px], shape (K, 2).
        reprojection_rms: RMS reprojection error [px].
        bias_px: Largest ellipse-centre offset corrected [px].
    """

    T_camera_target: Array
    uv: Array
    reprojection_rms: float
    bias_px: float = 0.0


def _solve_pnp(layout: Array, uv: Array, K: Array, D: Array) -> tuple[Array, float]:
    obj = np.ascontiguousarray(layout, dtype=np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, D, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise ValueError("solvePnP failed")
    ok, rvec, tvec = cv2.solvePnP(
        obj, img, K, D, rvec, tvec, useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE
    )
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, D)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - uv) ** 2, axis=1))))
    return T, rms


def target_pose(
    image: ArrayLike,
    K: ArrayLike,
    D: ArrayLike,
    design: PlateDesign,
    *,
    image_name: str = "image",
    correct_bias: bool = True,
    max_rms_px: float = MAX_PNP_RMS_PX,
) -> TargetPose | DetectionError:
    """``T_camera_target`` of a disk target in one image (``cv2.solvePnP``, IPPE then LM).

    Args:
        image: Grey image, uint8, shape (h, w).
        K: Camera matrix [px], shape (3, 3).
        D: Distortion coefficients, shape (n,).
        design: The target (layout in the target frame [m]).
        image_name: For messages.
        correct_bias: Remove the predicted ellipse-centre offset and solve again.
        max_rms_px: Refuse a pose whose reprojection RMS exceeds this [px].

    Returns:
        The pose, or the :class:`DetectionError` saying why not.
    """
    Km = np.asarray(K, dtype=float)
    Dm = np.asarray(D, dtype=float).ravel()
    found = detect_plates(image, Km, Dm, [design], image_name=image_name)[design.name]
    if isinstance(found, DetectionError):
        return found
    uv = found.uv.copy()
    T, rms = _solve_pnp(design.layout, uv, Km, Dm)
    bias = 0.0
    if correct_bias:
        off = ellipse_centre_offset(Km, T, design)
        bias = float(np.abs(off).max())
        uv = uv - off
        T, rms = _solve_pnp(design.layout, uv, Km, Dm)
    if rms > max_rms_px:
        return InconsistentDetectionError(
            image_name,
            design.name,
            f"reprojection error {rms:.2f} px RMS > {max_rms_px} px (wrong intrinsics?)",
        )
    return TargetPose(T, uv, rms, bias)


__all__ = [
    "MAX_EPIPOLAR_PX",
    "MAX_FIT_RMS",
    "MAX_PNP_RMS_PX",
    "StereoPlatePose",
    "TargetPose",
    "ellipse_centre_offset",
    "stereo_plate_poses",
    "target_pose",
]
