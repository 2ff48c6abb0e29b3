"""Standard calibration boards: chessboard, ChArUco, symmetric and asymmetric circle grids.

A :class:`Board` is described with OpenCV's own parameters (``docs/images.md``; the file format
is :mod:`~cpc2urdf.identification.vision.boards.board_file`):

- ``chessboard``: ``pattern_size = (cols, rows)`` *inner* corners, as ``cv2.findChessboardCorners``
  takes it, and ``square_size``; the board has ``(cols + 1) x (rows + 1)`` squares, the top-left
  one black.
- ``charuco``: ``squares = (squares_x, squares_y)``, ``square_size``, ``marker_size``,
  ``dictionary`` (``DICT_4X4_50``, ...), as ``cv2.aruco.CharucoBoard``; optional
  ``first_marker_id`` so that several boards in one image have disjoint marker ids.
- ``circles`` (symmetric grid) and ``asymmetric_circles``: ``pattern_size = (cols, rows)`` as
  ``cv2.findCirclesGrid`` takes it, ``spacing`` with OpenCV's meaning (symmetric: the distance
  between neighbours; asymmetric: circle ``(i, j)`` at ``((2 j + i % 2) spacing, i spacing)``,
  as OpenCV's calibration sample writes it), and the printed ``circle_radius``.

Frames: OpenCV puts a board's points at ``(X, Y, 0)`` with X along a row and Y down the rows, so
its z axis points *into* the board. Our board frame, like a plate frame (``targets.py``), has
its origin at the centre of the pattern, x = X, y = -Y and z = x cross y out of the printed face:
``p_board = (X - X0, Y0 - Y, 0)``. :meth:`Board.object_points` are in this frame, so
``cv2.solvePnP`` gives ``T_camera_board`` directly.

Which point is which: ChArUco corners carry the ids of their markers, so any subset and any
rotation is unique. A chessboard's corner grid looks the same rotated by 180 deg; the colour of
the corner squares tells the two apart when ``cols + rows`` is odd (OpenCV's advice: one even and
one odd side), see :func:`board_pose`. An asymmetric circle grid with an odd number of rows is
unique; a symmetric circle grid never is (:attr:`Board.pose_ambiguity` says why), so it serves
camera calibration but gives no pose.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

BOARD_KINDS = ("chessboard", "charuco", "circles", "asymmetric_circles")
BLACK_LEVEL = 0.08  # [-] grey level of the printed black (0 black .. 1 white)
WHITE_LEVEL = 0.92  # [-] grey level of the board's paper
TEXTURE_PX_PER_SQUARE = 120  # ChArUco texture resolution used for rendering [px per square]


@dataclass(frozen=True)
class Board:
    """A standard calibration board (module docstring), SI units.

    Attributes:
        kind: One of :data:`BOARD_KINDS`.
        size: ``pattern_size`` (chessboard: inner corners; circle grids: circles) or ``squares``
            (ChArUco), ``(cols, rows)``.
        square_size: Chessboard/ChArUco square side [m] (circle grids: 0).
        spacing: Circle grids: OpenCV's spacing [m] (module docstring); else 0.
        circle_radius: Circle grids: printed radius [m]; else 0.
        marker_size: ChArUco: marker side [m]; else 0.
        dictionary: ChArUco: the ArUco dictionary name (``DICT_5X5_100``); else "".
        first_marker_id: ChArUco: id of the first marker.
        margin: White border around the pattern [m].
        name: A name for messages (the file name, or a frame name).
    """

    kind: str
    size: tuple[int, int]
    square_size: float = 0.0
    spacing: float = 0.0
    circle_radius: float = 0.0
    marker_size: float = 0.0
    dictionary: str = ""
    first_marker_id: int = 0
    margin: float = 0.0
    name: str = "board"

    # ---- geometry in OpenCV's board coordinates (X, Y) ------------------------------------------

    @cached_property
    def _cv_points(self) -> Array:
        """The detectable points in OpenCV's board coordinates [m], shape (N, 3), in OpenCV's order."""
        cols, rows = self.size
        if self.kind == "chessboard":
            i, j = np.divmod(np.arange(rows * cols), cols)
            return np.stack([j * self.square_size, i * self.square_size, 0.0 * i], axis=1).astype(
                float
            )
        if self.kind == "charuco":  # cv2.aruco's getChessboardCorners(), in double precision
            i, j = np.divmod(np.arange((rows - 1) * (cols - 1)), cols - 1)
            return np.stack(
                [(j + 1) * self.square_size, (i + 1) * self.square_size, 0.0 * i], axis=1
            ).astype(float)
        i, j = np.divmod(np.arange(rows * cols), cols)
        x = (2 * j + i % 2) if self.kind == "asymmetric_circles" else j
        return np.stack([x * self.spacing, i * self.spacing, 0.0 * i], axis=1).astype(float)

    @cached_property
    def _pattern_box(self) -> tuple[float, float, float, float]:
        """The printed pattern's extent (X0, X1, Y0, Y1) in OpenCV's board coordinates [m]."""
        cols, rows = self.size
        s = self.square_size
        if self.kind == "chessboard":
            return (-s, cols * s, -s, rows * s)
        if self.kind == "charuco":
            return (0.0, cols * s, 0.0, rows * s)
        p = self._cv_points
        r = self.circle_radius
        return (
            float(p[:, 0].min()) - r,
            float(p[:, 0].max()) + r,
            float(p[:, 1].min()) - r,
            float(p[:, 1].max()) + r,
        )

    @cached_property
    def _centre(self) -> tuple[float, float]:
        x0, x1, y0, y1 = self._pattern_box
        return 0.5 * (x0 + x1), 0.5 * (y0 + y1)

    def board_from_cv(self, XY: Array) -> Array:
        """OpenCV board coordinates (X, Y) -> our board frame (x, y) [m], shape (N, 2)."""
        c = self._centre
        return np.stack([XY[:, 0] - c[0], c[1] - XY[:, 1]], axis=1)

    def cv_from_board(self, xy: Array) -> Array:
        """Our board frame (x, y) -> OpenCV board coordinates (X, Y) [m], shape (N, 2)."""
        c = self._centre
        return np.stack([xy[:, 0] + c[0], c[1] - xy[:, 1]], axis=1)

    @property
    def n_points(self) -> int:
        """Number of detectable points (corners or circle centres)."""
        return int(self._cv_points.shape[0])

    def object_points(self) -> Array:
        """The detectable points in the board frame [m], shape (N, 3), point ``k`` = id ``k``."""
        xy = self.board_from_cv(self._cv_points)
        return np.concatenate([xy, np.zeros((len(xy), 1))], axis=1)

    @property
    def outline(self) -> tuple[float, float, float, float]:
        """The board (pattern + margin) as ``(x_min, x_max, y_min, y_max)`` in the board frame [m]."""
        x0, x1, y0, y1 = self._pattern_box
        c = self._centre
        m = self.margin
        return (x0 - c[0] - m, x1 - c[0] + m, c[1] - y1 - m, c[1] - y0 + m)

    def outline_corners(self) -> Array:
        """The board's four corners in the board frame [m], shape (4, 3)."""
        x0, x1, y0, y1 = self.outline
        return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])

    @property
    def point_spacing(self) -> float:
        """Distance between neighbouring detectable points [m]."""
        return self.square_size if self.kind in ("chessboard", "charuco") else self.spacing

    @property
    def pose_ambiguity(self) -> str | None:
        """Why the board gives no unique pose, or None (module docstring)."""
        cols, rows = self.size
        if self.kind == "circles":
            return "a symmetric circle grid looks the same rotated by 180 deg"
        if self.kind == "asymmetric_circles" and rows % 2 == 0:
            return "an asymmetric circle grid with an even number of rows looks the same rotated by 180 deg"
        if self.kind == "chessboard" and (cols + rows) % 2 == 0:
            return "a chessboard whose inner-corner counts are both even or both odd looks the same rotated by 180 deg"
        return None

    # ---- OpenCV objects -------------------------------------------------------------------------

    def aruco_dictionary(self) -> Any:
        """The ``cv2.aruco.Dictionary`` of a ChArUco board."""
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    @property
    def n_markers(self) -> int:
        """ChArUco: number of markers (in the white squares); else 0."""
        cols, rows = self.size
        return (cols * rows) // 2 if self.kind == "charuco" else 0

    def charuco_board(self) -> Any:
        """The ``cv2.aruco.CharucoBoard`` (marker ids from :attr:`first_marker_id`)."""
        ids = np.arange(self.first_marker_id, self.first_marker_id + self.n_markers, dtype=np.int32)
        return cv2.aruco.CharucoBoard(
            self.size, self.square_size, self.marker_size, self.aruco_dictionary(), ids
        )

    @cached_property
    def _texture(self) -> NDArray[np.uint8]:
        cols, rows = self.size
        pp = TEXTURE_PX_PER_SQUARE
        return np.asarray(
            self.charuco_board().generateImage((cols * pp, rows * pp), marginSize=0, borderBits=1)
        )

    # ---- appearance -----------------------------------------------------------------------------

    def reflectance(self, xy: Array) -> Array:
        """Grey level (0 black .. 1 white) of the printed face at board-frame points (N, 2) [m];
        points outside the board (:attr:`outline`) get the board's white too (the caller clips)."""
        XY = self.cv_from_board(np.asarray(xy, dtype=float).reshape(-1, 2))
        X, Y = XY[:, 0], XY[:, 1]
        x0, x1, y0, y1 = self._pattern_box
        inside = (X >= x0) & (X < x1) & (Y >= y0) & (Y < y1)
        black = np.zeros(len(X), dtype=bool)
        if self.kind == "chessboard":
            a = np.floor(X / self.square_size) + 1
            b = np.floor(Y / self.square_size) + 1
            black = inside & ((a + b) % 2 == 0)
        elif self.kind == "charuco":
            cols, rows = self.size
            pp = TEXTURE_PX_PER_SQUARE / self.square_size
            u = np.clip(np.floor(X * pp), 0, cols * TEXTURE_PX_PER_SQUARE - 1).astype(np.intp)
            v = np.clip(np.floor(Y * pp), 0, rows * TEXTURE_PX_PER_SQUARE - 1).astype(np.intp)
            black = inside & (self._texture[v, u] < 128)
        else:
            # the nearest lattice centre is the nearest circle (circles are < half the spacing apart)
            cols, rows = self.size
            sp = self.spacing
            d2 = np.full(len(X), np.inf)
            i0 = np.floor(Y / sp)
            for di in (0.0, 1.0):
                i = np.clip(i0 + di, 0, rows - 1)
                if self.kind == "asymmetric_circles":
                    j = np.clip(np.rint((X / sp - i % 2) / 2), 0, cols - 1)
                    cx = (2 * j + i % 2) * sp
                else:
                    j = np.clip(np.rint(X / sp), 0, cols - 1)
                    cx = j * sp
                d2 = np.minimum(d2, (X - cx) ** 2 + (Y - i * sp) ** 2)
            black = d2 <= self.circle_radius**2
        return np.where(black, BLACK_LEVEL, WHITE_LEVEL)

    # ---- JSON -----------------------------------------------------------------------------------

    def to_json(self) -> dict[str, Any]:
        """The board's parameters in metres (what :mod:`board_file` writes with ``units: m``)."""
        out: dict[str, Any] = {"kind": self.kind}
        if self.kind == "charuco":
            out.update(
                squares=list(self.size),
                square_size=self.square_size,
                marker_size=self.marker_size,
                dictionary=self.dictionary,
                first_marker_id=self.first_marker_id,
            )
        elif self.kind == "chessboard":
            out.update(pattern_size=list(self.size), square_size=self.square_size)
        else:
            out.update(
                pattern_size=list(self.size), spacing=self.spacing, circle_radius=self.circle_radius
            )
        out["margin"] = self.margin
        return out


__all__ = ["BLACK_LEVEL", "BOARD_KINDS", "WHITE_LEVEL", "Board"]
