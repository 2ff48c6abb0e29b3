"""A head seen by its own cameras: the board's corners in pixels, their residuals and Jacobian.

The data of a one-stage calibration are images, not poses: at each record the robot's joints are
read and every head camera detects a board's corners. The board is fixed in the world, or held by
the robot itself (a frame on another branch of the same tree, e.g. a gripper). A corner ``X_b``
(board frame) is predicted at the pixel

    uv = pi(K, D, T_world_camera(q)^-1 T_world_board(q) X_b)

where ``pi`` is OpenCV's projection (``cv2.projectPoints``, distortion included) and
``T_world_board = I`` for a fixed board: the world *is* the board, so the robot's placement in it
is part of the chart's first joints (:mod:`~cpc2urdf.identification.kinematics.parametrization`).
For a held board the world is the robot's base and only relative poses are seen: joints shared by
the camera's and the board's paths, and a rigid motion of everything, are not determined; the
fit (:mod:`bundle`) keeps them where they start.

Residuals are ``(uv_detected - uv) / sigma_image`` (unit variance when ``sigma`` is the
detector's corner noise in that image: blur, distance and angle change it from image to image). Parameters: the chart's (:class:`Parametrization`, the cameras and the
held board as measured frames), then optionally each camera's ``fx, fy, cx, cy, k1, k2``.
Jacobian: the chart's spatial twists (:meth:`Parametrization.pose_jacobian`) chained through the
rigid transforms and ``cv2.projectPoints``' own derivatives; checked against finite differences
in ``tests/test_selfcal.py``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.transforms import Array

INTRINSIC_PARAMS = ("fx", "fy", "cx", "cy", "k1", "k2")


@dataclass(frozen=True)
class CameraModel:
    """A camera's intrinsics (OpenCV model).

    Attributes:
        K: Camera matrix [px], shape (3, 3).
        D: Distortion coefficients (k1, k2, p1, p2[, k3]), shape (n,), n >= 4.
        image_size: (width, height) [px].
    """

    K: Array
    D: Array
    image_size: tuple[int, int]

    def updated(self, d: Array) -> CameraModel:
        """This camera with ``d = (dfx, dfy, dcx, dcy, dk1, dk2)`` added."""
        K = self.K.copy()
        K[0, 0] += d[0]
        K[1, 1] += d[1]
        K[0, 2] += d[2]
        K[1, 2] += d[3]
        D = np.zeros(max(5, len(self.D)))
        D[: len(self.D)] = self.D
        D[:2] += d[4:6]
        return CameraModel(K, D, self.image_size)


@dataclass(frozen=True)
class BoardView:
    """One image: the board's corners one camera detected at one record.

    Attributes:
        camera: The camera's frame name in the model.
        record: Index of the record (row of :attr:`PixelData.q`).
        ids: Corner ids (rows of :attr:`PixelData.board_points`), shape (k,).
        uv: Detected pixels (distorted, as in the image) [px], shape (k, 2).
        pnp: The detector's own PnP pose of the board, ``T_camera_board`` (4, 4), and its RMS
            reprojection error [px], when it solved one (reading images does).
    """

    camera: str
    record: int
    ids: NDArray[np.intp]
    uv: Array
    pnp: tuple[Array, float] | None = None


@dataclass
class PixelData:
    """What a one-stage calibration reads.

    Attributes:
        q: Joint readings per record [rad]/[m], shape (R, n) in the model's joint order.
        labels: One label per record.
        views: The images with their detected corners.
        cameras: Camera frame name -> its intrinsics.
        board_points: The board's corners in its frame [m], shape (M, 3).
        board_frame: None when the board is fixed in the world; else the model frame it is
            (on a link of the robot, e.g. held by a gripper).
        source: Where the data came from, for messages.
        notes: What reading the images said (images skipped and why).
        names: Camera frame -> the user's name for it (its folder), for messages.
    """

    q: Array
    labels: list[str]
    views: list[BoardView]
    cameras: dict[str, CameraModel]
    board_points: Array
    board_frame: str | None = None
    source: str = "<memory>"
    notes: list[str] = field(default_factory=list)
    names: dict[str, str] = field(default_factory=dict)

    def name(self, text: str) -> str:
        """``text`` with the model's camera frame names as the user names them (:attr:`names`)."""
        for frame, user in self.names.items():
            text = text.replace(frame, user)
        return text

    def view_name(self, k: int) -> str:
        v = self.views[k]
        return f"{self.name(v.camera)}/{self.labels[v.record]}"


def _skew_cross(a: Array, w: Array) -> Array:
    """``a_i x w_p`` (= ``-w_p x a_i``) for points ``a`` (k, 3) and twists' rotations ``w`` (3, P): shape (k, 3, P)."""
    return np.cross(a[:, :, None], w[None, :, :], axis=1)


class PixelProblem:
    """Weighted pixel residuals of the used corners and their Jacobian (module docstring).

    Args:
        chart: Chart centred on the current model (cameras and, if held, the board as frames).
        data: The images.
        use: Per view, which of its corners take part, shape (k,) booleans.
        sigma: Per view, the corner noise per pixel coordinate [px], shape (n_views,).
        intrinsics: Estimate each camera's ``fx, fy, cx, cy, k1, k2`` too.
        board_scale: Estimate the board's scale too (its last parameter, ``ds``: the points are
            ``(1 + ds) X_b``), to tell a wrong square size.
    """

    def __init__(
        self,
        chart: Parametrization,
        data: PixelData,
        use: Sequence[NDArray[np.bool_]],
        sigma: ArrayLike,
        intrinsics: bool = False,
        board_scale: bool = False,
    ) -> None:
        self.chart, self.data = chart, data
        self.sigma = np.asarray(sigma, dtype=float)
        self.views = [k for k, u in enumerate(use) if u.any()]
        self.points = {k: data.board_points[data.views[k].ids[use[k]]] for k in self.views}
        self.uv = {k: data.views[k].uv[use[k]] for k in self.views}
        self.cams = list(data.cameras) if intrinsics else []
        n_i = len(INTRINSIC_PARAMS)
        self.scaled = board_scale
        self.n_params = chart.n_params + n_i * len(self.cams) + int(board_scale)
        self.n_residuals = 2 * sum(len(p) for p in self.points.values())
        frames = sorted({data.views[k].camera for k in self.views})
        self.frames = frames + ([data.board_frame] if data.board_frame else [])

    def names(self) -> list[str]:
        names = [f"{c}.{p}" for c in self.cams for p in INTRINSIC_PARAMS]
        return list(self.chart.names) + names + (["board.scale"] if self.scaled else [])

    def camera_models(self, x: Array) -> dict[str, CameraModel]:
        out = dict(self.data.cameras)
        n_i, P = len(INTRINSIC_PARAMS), self.chart.n_params
        for i, c in enumerate(self.cams):
            out[c] = out[c].updated(x[P + n_i * i : P + n_i * (i + 1)])
        return out

    def _poses(self, x: Array, derivatives: bool) -> tuple[dict[str, Array], dict[str, Array]]:
        xc = x[: self.chart.n_params]
        if derivatives:
            return self.chart.pose_jacobian(xc, self.data.q)
        return self.chart.model_from_vector(xc).fk(self.data.q, self.frames), {}

    def _board_world(self, k: int, T: dict[str, Array], x: Array) -> tuple[Array, Array | None]:
        """Corners of view ``k`` in world, and the board's pose at its record (None if fixed)."""
        X = self.points[k] * (1.0 + x[-1]) if self.scaled else self.points[k]
        if self.data.board_frame is None:
            return X, None
        Tb = T[self.data.board_frame][self.data.views[k].record]
        return X @ Tb[:3, :3].T + Tb[:3, 3], Tb

    def _project(
        self, k: int, T: dict[str, Array], cams: dict[str, CameraModel], x: Array
    ) -> tuple[Array, Array, Array, Array]:
        """Predicted pixels (k, 2), projection Jacobian (2k, 10 + n_D), corners in world and camera."""
        v = self.data.views[k]
        Tc = T[v.camera][v.record]
        Xw, _ = self._board_world(k, T, x)
        Xc = (Xw - Tc[:3, 3]) @ Tc[:3, :3]
        cam = cams[v.camera]
        uv, jac = cv2.projectPoints(Xc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.D)
        return np.asarray(uv, float).reshape(-1, 2), np.asarray(jac, float), Xw, Xc

    def residuals(self, x: Array) -> Array:
        """Weighted residuals, shape (2 * used corners,), per view then per corner (u, v)."""
        try:
            T, _ = self._poses(x, False)
        except DegenerateDataError:  # a trial step left the chart
            return np.full(self.n_residuals, 1e6)
        cams = self.camera_models(x)
        out = []
        for k in self.views:
            uv, _, _, Xc = self._project(k, T, cams, x)
            r = (self.uv[k] - uv) / self.sigma[k]
            out.append(np.where(Xc[:, 2:3] > 0, r, 1e6).ravel())
        return np.concatenate(out)

    def pixel_residuals(self, x: Array) -> dict[int, Array]:
        """Unweighted residuals per used view [px], shape (k_used, 2)."""
        r = self.residuals(x)
        out, i = {}, 0
        for k in self.views:
            n = len(self.uv[k])
            out[k] = r[i : i + 2 * n].reshape(n, 2) * self.sigma[k]
            i += 2 * n
        return out

    def jacobian(self, x: Array) -> Array:
        """Jacobian of :meth:`residuals`, shape (2 * used corners, n_params)."""
        T, D = self._poses(x, True)
        cams = self.camera_models(x)
        P, n_i = self.chart.n_params, len(INTRINSIC_PARAMS)
        rows = []
        for k in self.views:
            v = self.data.views[k]
            _, jac, Xw, _ = self._project(k, T, cams, x)
            Tc, Dc = T[v.camera][v.record], D[v.camera][v.record]
            # dX_c = R_c^T (dX_w - dp_c - w_c x (X_w - p_c)); dX_w = dp_b + w_b x (X_w - p_b) if held
            dXw = -Dc[None, :3, :] + _skew_cross(Xw - Tc[:3, 3], Dc[3:])
            if self.data.board_frame is not None:
                Tb = T[self.data.board_frame][v.record]
                Db = D[self.data.board_frame][v.record]
                dXw = dXw + Db[None, :3, :] - _skew_cross(Xw - Tb[:3, 3], Db[3:])
            dXc = np.einsum("ji,kjp->kip", Tc[:3, :3], dXw)
            Jpi = jac[:, 3:6].reshape(-1, 2, 3)  # d uv / d X_c (translation at zero rotation)
            Jk = np.zeros((2 * len(Xw), self.n_params))
            Jk[:, :P] = np.einsum("kuj,kjp->kup", Jpi, dXc).reshape(-1, P)
            if v.camera in self.cams:
                i = P + n_i * self.cams.index(v.camera)
                Jk[:, i : i + n_i] = jac[:, [6, 7, 8, 9, 10, 11]]
            if self.scaled:  # d X_w / d ds = R_b X_b
                Xb = self.points[k]
                dX = Xb if self.data.board_frame is None else Xb @ Tb[:3, :3].T
                Jk[:, -1] = np.einsum("kuj,kj->ku", Jpi, dX @ Tc[:3, :3]).ravel()
            rows.append(-Jk / self.sigma[k])
        return np.concatenate(rows, axis=0)


__all__ = ["INTRINSIC_PARAMS", "BoardView", "CameraModel", "PixelData", "PixelProblem"]
