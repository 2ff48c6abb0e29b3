"""A calibrated two-camera pinhole stereo rig: projection and triangulation (Shih et al. sec. 3).

The rig is described exactly as OpenCV's ``cv2.stereoCalibrate`` returns it:

- ``K1, D1``: left camera matrix (3, 3) [px] and distortion ``(k1, k2, p1, p2, k3)``;
- ``K2, D2``: the same for the right camera;
- ``R, T``: the pose of the left camera in the right camera, ``x_right = R x_left + T``
  (so ``T_right_left = [R | T]``), ``T`` in metres here.

Frames: ``world`` *is* the left camera's optical frame (ROS REP-103: z forward along the optical
axis, x right, y down in the image), as in the paper, where the measuring rig defines the world.
So ``T_world_left = I`` and ``T_world_right = inverse([R | T])``.

Typical use::

    rig = StereoRig.verged()                       # the paper's geometry: 600 mm baseline, 1.5 m
    uv_left, uv_right = rig.project(p_world)       # (..., 2) pixels each, with lens distortion
    p_world_hat = rig.triangulate(uv_left, uv_right)
    seen = rig.in_view(p_world, margin_px=20)      # inside both images, in front of both cameras
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.files.jsonio import float_list
from cpc2urdf.transforms import homogeneous, inverse

Array = NDArray[np.float64]


def _rot_y(angle: float) -> Array:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True)
class StereoRig:
    """A calibrated stereo pair in OpenCV's ``stereoCalibrate`` convention (see module docstring).

    Attributes:
        K1: Left camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` [px], shape (3, 3).
        D1: Left distortion ``(k1, k2, p1, p2, k3)`` [-], shape (5,).
        K2: Right camera matrix [px], shape (3, 3).
        D2: Right distortion [-], shape (5,).
        R: Rotation of ``x_right = R x_left + T``, shape (3, 3).
        T: Translation of the same [m], shape (3,).
        image_size: ``(width, height)`` [px] of both images.
    """

    K1: Array
    D1: Array
    K2: Array
    D2: Array
    R: Array
    T: Array
    image_size: tuple[int, int] = (1280, 1024)

    def __post_init__(self) -> None:
        for name, shape in (
            ("K1", (3, 3)),
            ("K2", (3, 3)),
            ("D1", (5,)),
            ("D2", (5,)),
            ("R", (3, 3)),
            ("T", (3,)),
        ):
            a = np.array(getattr(self, name), dtype=float).reshape(shape)
            if not np.all(np.isfinite(a)):
                raise ValueError(f"stereo rig {name} must be finite")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if np.max(np.abs(self.R.T @ self.R - np.eye(3))) > 1e-6 or np.linalg.det(self.R) < 0:
            raise ValueError("stereo rig R must be a rotation matrix")
        w, h = (int(v) for v in self.image_size)
        object.__setattr__(self, "image_size", (w, h))

    # ---- construction ---------------------------------------------------------------------------

    @classmethod
    def verged(
        cls,
        *,
        baseline: float = 0.6,
        distance: float = 1.5,
        focal_px: float = 1600.0,
        image_size: tuple[int, int] = (1280, 1024),
        distortion: ArrayLike = (-0.08, 0.05, 0.0, 0.0, 0.0),
    ) -> StereoRig:
        """A symmetric rig whose optical axes meet at ``distance`` in front of the baseline middle.

        The default is the paper's rig (sec. 6: 600 mm baseline, object ~1.5 m away) with
        1280x1024 px cameras of 1600 px focal length (about 44 x 35 deg field of view, ~1.1 x
        0.9 m at 1.5 m) and a mild barrel distortion.

        Args:
            baseline: Distance between the optical centres [m].
            distance: Distance from the baseline's middle to the fixation point [m].
            focal_px: Focal length ``fx = fy`` [px]; the principal point is the image centre.
            image_size: ``(width, height)`` [px].
            distortion: ``(k1, k2, p1, p2, k3)`` of both cameras.
        """
        if baseline <= 0 or distance <= 0 or focal_px <= 0:
            raise ValueError("baseline, distance and focal_px must be positive")
        w, h = image_size
        K = np.array([[focal_px, 0.0, (w - 1) / 2], [0.0, focal_px, (h - 1) / 2], [0.0, 0.0, 1.0]])
        # Rig frame: x along the baseline (left -> right), z forward. Each camera turns inward by
        # theta about its y axis (y points down, so +theta turns z towards +x).
        theta = math.atan2(baseline / 2, distance)
        R_rig_left = _rot_y(theta)
        R_rig_right = _rot_y(-theta)
        c_rig_left = np.array([-baseline / 2, 0.0, 0.0])
        c_rig_right = np.array([baseline / 2, 0.0, 0.0])
        R = R_rig_right.T @ R_rig_left  # x_right = R x_left + T
        T = R_rig_right.T @ (c_rig_left - c_rig_right)
        D = np.asarray(distortion, dtype=float)
        return cls(K, D, K.copy(), D.copy(), R, T, (int(w), int(h)))

    # ---- frames ---------------------------------------------------------------------------------

    def T_world_camera(self, which: str) -> Array:
        """Pose of camera ``"left"`` or ``"right"`` (optical frame) in world = left camera, (4, 4)."""
        if which == "left":
            return np.eye(4)
        if which == "right":
            return inverse(homogeneous(self.R, self.T))
        raise ValueError(f"camera must be 'left' or 'right', got {which!r}")

    @property
    def baseline(self) -> float:
        """Distance between the optical centres [m]."""
        return float(np.linalg.norm(self.T))

    # ---- projection -----------------------------------------------------------------------------

    def project(self, p_world: ArrayLike) -> tuple[Array, Array]:
        """Project world points into both images with ``cv2.projectPoints`` (distortion included).

        Args:
            p_world: Points in world = left camera frame [m], shape (..., 3).

        Returns:
            ``(uv_left, uv_right)`` [px], each of shape (..., 2). Points behind a camera are
            projected anyway (check :meth:`in_view`).
        """
        p = np.asarray(p_world, dtype=float)
        flat = p.reshape(-1, 1, 3)
        zero = np.zeros(3)
        uv1, _ = cv2.projectPoints(flat, zero, zero, self.K1, self.D1)
        rvec, _ = cv2.Rodrigues(np.ascontiguousarray(self.R))
        uv2, _ = cv2.projectPoints(flat, rvec, self.T, self.K2, self.D2)
        shape = (*p.shape[:-1], 2)
        return uv1.reshape(shape), uv2.reshape(shape)

    def triangulate(self, uv_left: ArrayLike, uv_right: ArrayLike) -> Array:
        """3D points from pixel pairs: ``cv2.undistortPoints`` then ``cv2.triangulatePoints``.

        Args:
            uv_left: Pixels in the left image [px], shape (..., 2).
            uv_right: The corresponding pixels in the right image [px], shape (..., 2).

        Returns:
            Points in world = left camera frame [m], shape (..., 3); NaN where an input is NaN.
        """
        a = np.asarray(uv_left, dtype=float)
        b = np.asarray(uv_right, dtype=float)
        if a.shape != b.shape or a.shape[-1] != 2:
            raise ValueError(
                f"pixel arrays must both have shape (..., 2), got {a.shape} and {b.shape}"
            )
        out = np.full((*a.shape[:-1], 3), np.nan)
        fa, fb = a.reshape(-1, 2), b.reshape(-1, 2)
        ok = np.all(np.isfinite(fa), axis=1) & np.all(np.isfinite(fb), axis=1)
        if ok.any():
            # Normalised image coordinates: the projection matrices are then [I|0] and [R|T].
            n1 = cv2.undistortPoints(fa[ok].reshape(-1, 1, 2), self.K1, self.D1).reshape(-1, 2)
            n2 = cv2.undistortPoints(fb[ok].reshape(-1, 1, 2), self.K2, self.D2).reshape(-1, 2)
            P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
            P2 = np.hstack([self.R, self.T.reshape(3, 1)])
            X = cv2.triangulatePoints(P1, P2, n1.T.copy(), n2.T.copy())
            flat = out.reshape(-1, 3)
            flat[ok] = (X[:3] / X[3]).T
        return out

    def in_view(self, p_world: ArrayLike, *, margin_px: float = 0.0) -> NDArray[np.bool_]:
        """Which points both cameras see: in front, and at least ``margin_px`` inside both images.

        Points beyond the image corners' field angle are refused even if the distortion
        polynomial folds them back into the image.

        Args:
            p_world: Points [m], shape (..., 3).
            margin_px: Required distance from the image border [px].

        Returns:
            Boolean array of shape (...,).
        """
        p = np.asarray(p_world, dtype=float)
        ok = np.ones(p.shape[:-1], dtype=bool)
        uvs = self.project(p)
        w, h = self.image_size
        for which, uv, K, D in (
            ("left", uvs[0], self.K1, self.D1),
            ("right", uvs[1], self.K2, self.D2),
        ):
            T = inverse(self.T_world_camera(which))
            pc = p @ T[:3, :3].T + T[:3, 3]
            z = pc[..., 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                r2 = (pc[..., 0] ** 2 + pc[..., 1] ** 2) / z**2
            ok &= z > 0
            ok &= r2 <= self._max_r2(K, D)
            ok &= (uv[..., 0] >= margin_px) & (uv[..., 0] <= w - 1 - margin_px)
            ok &= (uv[..., 1] >= margin_px) & (uv[..., 1] <= h - 1 - margin_px)
        return ok

    def _max_r2(self, K: Array, D: Array) -> float:
        w, h = self.image_size
        corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=float).reshape(
            -1, 1, 2
        )
        n = cv2.undistortPoints(corners, K, D).reshape(-1, 2)
        return float(np.max(np.sum(n**2, axis=1))) * 1.0001

    # ---- files ----------------------------------------------------------------------------------

    def to_json(self) -> dict[str, Any]:
        """The rig as JSON (SI units; OpenCV's names)."""
        return {
            "K1": self.K1.tolist(),
            "D1": self.D1.tolist(),
            "K2": self.K2.tolist(),
            "D2": self.D2.tolist(),
            "R": self.R.tolist(),
            "T": self.T.tolist(),
            "image_size": list(self.image_size),
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any], where: str = "rig") -> StereoRig:
        """Inverse of :meth:`to_json`; ``ValueError`` naming ``where`` and the field."""
        if not isinstance(obj, Mapping):
            raise ValueError(f"{where} must be an object with K1, D1, K2, D2, R, T, image_size")

        def mat(key: str, rows: int) -> list[list[float]]:
            v = obj.get(key)
            if not isinstance(v, list) or len(v) != rows:
                raise ValueError(f"{where}.{key} must be {rows} rows of 3 numbers")
            return [float_list(r, 3, f"{where}.{key}[{i}]") for i, r in enumerate(v)]

        size = float_list(obj.get("image_size"), 2, f"{where}.image_size")
        return cls(
            np.array(mat("K1", 3)),
            np.array(float_list(obj.get("D1"), 5, f"{where}.D1")),
            np.array(mat("K2", 3)),
            np.array(float_list(obj.get("D2"), 5, f"{where}.D2")),
            np.array(mat("R", 3)),
            np.array(float_list(obj.get("T"), 3, f"{where}.T")),
            (int(size[0]), int(size[1])),
        )


__all__ = ["StereoRig"]
