"""The calibration targets: circle plates and their designs, in one place.

Two kinds of planar target appear in Shih et al.:

- the stage-1 end-effector plates (sec. 3.2, Fig. 7): dark circles on a light plate, one plate
  per measured frame of the robot, the circle layout taken from the robot's spec;
- the stage-2 target (sec. 5, Fig. 9): 5 x 5 light disks on a black plate, which the head's own
  cameras photograph for hand-eye calibration.

A :class:`PlateDesign` is what the renderer draws and the detector looks for: circle centres
and radii in the plate frame, the plate outline, the grey levels, and the enlarged *marker*
circle that makes the pattern's orientation and the plate's identity unambiguous.

The default designs (``docs/images.md``): the IIS-head plates are light grey (level 0.9), with
the robot's nine-circle layout (25 mm pitch) as dark circles (level 0.08) of radius 5 mm; one
circle per plate is a 6.5 mm marker (plate_left: a corner circle, plate_right: an edge circle);
the plates are 70 mm x 70 mm. The stage-2 target is black (0.08) with light disks (0.9) and one
larger marker disk.

Stage-2 target (:data:`TARGET_LAYOUT`, 25 disk centres [m] in the target frame; pitch
:data:`TARGET_PITCH`, disk radius :data:`TARGET_DISK_RADIUS`, the larger orientation marker disk
:data:`TARGET_MARKER_INDEX` / :data:`TARGET_MARKER_RADIUS`, plate size :data:`TARGET_SIZE`).
Target frame: origin at the centre disk, x along a row (increasing column), y along a column
(increasing row), z the normal of the printed face (the disks face +z, so a camera sees them
when the target's z axis points towards it). Disk ``k`` is at row ``k // 5``, column ``k % 5``:
``((col - 2) p, (row - 2) p, 0)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.model import Frame

Array = NDArray[np.float64]


@dataclass(frozen=True)
class PlateDesign:
    """A planar target: circles of known radius on a rectangular plate.

    Attributes:
        name: Frame name of the plate (``plate_left``, ``target``, ...).
        layout: Circle centres in the plate frame [m], shape (K, 3), z = 0.
        radii: Circle radii [m], shape (K,).
        outline: Plate rectangle ``(x_min, x_max, y_min, y_max)`` in the plate frame [m].
        plate_level: Grey level of the plate face (0 black .. 1 white).
        dot_level: Grey level of the circles.
        marker_index: Index of the enlarged marker circle (breaks the layout's symmetry), or None.
    """

    name: str
    layout: Array
    radii: Array
    outline: tuple[float, float, float, float]
    plate_level: float = 0.9
    dot_level: float = 0.08
    marker_index: int | None = None

    def __post_init__(self) -> None:
        layout = np.asarray(self.layout, dtype=float)
        radii = np.broadcast_to(np.asarray(self.radii, dtype=float), (layout.shape[0],)).copy()
        if layout.ndim != 2 or layout.shape[1] != 3 or layout.shape[0] < 4:
            raise ValueError(f"{self.name}: layout must have shape (K >= 4, 3), got {layout.shape}")
        if np.max(np.abs(layout[:, 2])) > 1e-9:
            raise ValueError(f"{self.name}: circle centres must lie in the plate plane z = 0")
        if np.any(radii <= 0):
            raise ValueError(f"{self.name}: circle radii must be positive")
        object.__setattr__(self, "layout", layout)
        object.__setattr__(self, "radii", radii)

    @property
    def n_circles(self) -> int:
        return int(self.layout.shape[0])

    @property
    def dark_dots(self) -> bool:
        """True when the circles are darker than the plate."""
        return self.dot_level < self.plate_level

    def outline_corners(self) -> Array:
        """The plate's four corners in the plate frame [m], shape (4, 3)."""
        x0, x1, y0, y1 = self.outline
        return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])


# ---- the stage-1 plates ---------------------------------------------------------------------------

PLATE_CIRCLE_RADIUS = 0.005  # [m] the circles of the stage-1 plates
PLATE_MARKER_RADIUS = 0.0065  # [m] the marker circle of a stage-1 plate
PLATE_MARGIN = 0.01  # [m] plate edge beyond the outermost circle centres


def plate_design(
    name: str,
    layout: ArrayLike,
    *,
    marker_index: int | None,
    radius: float = PLATE_CIRCLE_RADIUS,
    marker_radius: float = PLATE_MARKER_RADIUS,
    margin: float = PLATE_MARGIN,
    plate_level: float = 0.9,
    dot_level: float = 0.08,
) -> PlateDesign:
    """A plate with dark circles of ``radius`` on a light rectangle ``margin`` beyond the layout.

    Args:
        name: Frame name.
        layout: Circle centres in the plate frame [m], shape (K, 3).
        marker_index: Which circle is the enlarged marker (None: all equal).
        radius: Circle radius [m].
        marker_radius: Radius of the marker circle [m].
        margin: Distance from the outermost circle centres to the plate edge [m].
        plate_level: Grey level of the plate.
        dot_level: Grey level of the circles.
    """
    lay = np.asarray(layout, dtype=float)
    radii = np.full(lay.shape[0], radius)
    if marker_index is not None:
        radii[marker_index] = marker_radius
    lo = lay[:, :2].min(axis=0) - margin
    hi = lay[:, :2].max(axis=0) + margin
    return PlateDesign(
        name, lay, radii, (lo[0], hi[0], lo[1], hi[1]), plate_level, dot_level, marker_index
    )


def robot_plate_designs(frames: Sequence[Frame]) -> list[PlateDesign]:
    """Default designs of a robot's plates (the frames with ``kind == "plate"`` and a layout).

    The k-th plate's marker is circle ``k + 1`` of its layout: on the IIS-head's 3x3 layout,
    circle 1 is a corner (plate_left) and circle 2 an edge middle (plate_right), which no
    rotation maps onto each other, so the detector can tell the plates apart.
    """
    out = []
    k = 0
    for f in frames:
        if f.kind != "plate" or f.layout is None:
            continue
        lay = np.array(f.layout, dtype=np.float64)
        out.append(plate_design(f.name, lay, marker_index=(k + 1) % len(lay)))
        k += 1
    return out


# ---- the stage-2 target: 5 x 5 disks ---------------------------------------------------------------

TARGET_ROWS = 5
TARGET_COLS = 5
TARGET_PITCH = 0.040  # [m] between neighbouring disk centres
TARGET_DISK_RADIUS = 0.010  # [m]
TARGET_MARKER_INDEX = 0  # the corner disk at row 0, column 0 is the larger orientation marker
TARGET_MARKER_RADIUS = 0.014  # [m]
TARGET_SIZE = (0.240, 0.240)  # [m] plate outline (x, y), centred on the target origin
TARGET_LAYOUT: Array = np.array(
    [
        (
            (c - (TARGET_COLS - 1) / 2) * TARGET_PITCH,
            (r - (TARGET_ROWS - 1) / 2) * TARGET_PITCH,
            0.0,
        )
        for r in range(TARGET_ROWS)
        for c in range(TARGET_COLS)
    ]
)  # (25, 3) [m], disk k at row k // 5, column k % 5


def target_design(
    layout: ArrayLike | None = None,
    *,
    name: str = "target",
    radius: float | None = None,
    marker_index: int | None = None,
    marker_radius: float | None = None,
    size: tuple[float, float] | None = None,
) -> PlateDesign:
    """The stage-2 target: light disks on a black plate (Shih et al. Fig. 9).

    Every argument defaults to the ``TARGET_*`` constants of this module (5 x 5 disks, 40 mm
    pitch, 10 mm disks, a 14 mm marker disk at index 0, a 240 mm square plate).

    Args:
        layout: Disk centres in the target frame [m], shape (K, 3).
        name: Frame name.
        radius: Disk radius [m].
        marker_index: The enlarged disk (breaks the grid's 4-fold symmetry, so
            ``T_camera_target`` has a unique orientation).
        marker_radius: Its radius [m].
        size: Plate outline (x, y) [m], centred on the layout's bounding box.
    """
    lay = TARGET_LAYOUT if layout is None else np.asarray(layout, dtype=float)
    r = TARGET_DISK_RADIUS if radius is None else radius
    mi = TARGET_MARKER_INDEX if marker_index is None else marker_index
    mr = TARGET_MARKER_RADIUS if marker_radius is None else marker_radius
    sx, sy = TARGET_SIZE if size is None else size
    radii = np.full(len(lay), r)
    radii[mi] = mr
    cx, cy = (lay[:, :2].min(axis=0) + lay[:, :2].max(axis=0)) / 2
    outline = (cx - sx / 2, cx + sx / 2, cy - sy / 2, cy + sy / 2)
    return PlateDesign(name, lay, radii, outline, plate_level=0.08, dot_level=0.9, marker_index=mi)


__all__ = [
    "PLATE_CIRCLE_RADIUS",
    "PLATE_MARGIN",
    "PLATE_MARKER_RADIUS",
    "TARGET_COLS",
    "TARGET_DISK_RADIUS",
    "TARGET_LAYOUT",
    "TARGET_MARKER_INDEX",
    "TARGET_MARKER_RADIUS",
    "TARGET_PITCH",
    "TARGET_ROWS",
    "TARGET_SIZE",
    "PlateDesign",
    "plate_design",
    "robot_plate_designs",
    "target_design",
]
