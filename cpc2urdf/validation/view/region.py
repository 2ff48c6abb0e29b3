"""The reachable region in the 3D view (``cpc2urdf reach --html``): a
:class:`~cpc2urdf.validation.gaze.reachable.Region` drawn as one point cloud per category, in the
PNG's colours (fixated and disparity opaque, the others translucent), under
``/meshcat/reach/<category>/<k>`` (a cloud per sample ``k`` of the grid's first axis, each with
its point size; a category can be hidden in meshcat's "Open Controls"), and its legend for the
static page.

Where the points go: the grid lies in the *head frame* of the solver's model
(``Region.grid.points_head``: the cameras' mid-point at the home posture, x along their mean
optical axis, z up; :mod:`cpc2urdf.validation.gaze.reachable`). The view puts it on the head frame of
the robot it draws, taken the same way (the same cameras at the middle of the joints' limits).
For a URDF, a model file or a spec, solver and view load one model and the points land where the
solver put them (to rounding); for a model identified from a user's URDF the view draws the
written-back URDF in its root link's frame and names (:func:`~.robot.written_back_robot`), and
the head frame carries the region there.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass

import meshcat
import meshcat.geometry as mg
import numpy as np

from cpc2urdf.transforms import Array
from cpc2urdf.urdf.robot import urdf_source
from cpc2urdf.validation.gaze.reachable import (
    CATEGORY_COLOURS,
    REGION_CATEGORIES,
    HeadFrame,
    Region,
    head_frame_at,
)
from cpc2urdf.validation.view.geometry import hex_colour
from cpc2urdf.validation.view.view_robot import ViewRobot

REGION_NODE = "reach"  # /meshcat/reach/<category>
COLOUR_NAMES = {
    "fixated": "green",
    "disparity": "orange",
    "joint_limits": "blue",
    "behind": "grey",
    "too_close": "purple",
    "no_solution": "red",
}  # CATEGORY_COLOURS in words, for a terminal
POINTED = (
    "fixated",
    "disparity",
)  # categories the head points at (disparity: as well as it can): drawn opaque
OTHER_OPACITY = (
    0.3  # [0-1]: the other categories are drawn translucent, so the pointed-at volume shows through
)
POINT_FRACTION = 0.4  # [-]: a point's side is this fraction of the grid's spacing where it lies
MAX_POINT_FRACTION = 0.05  # [-]: and at most this fraction of the grid's far range (coarse grids)
RADIAL_FRACTION = (
    0.8  # [-]: a shell's points at most this fraction of the spacing between its distances
)
SAME_WORLD = 1e-6  # [m]: drawn points this close to the solver's are in its world
MAX_FRAMING_POINTS = 20_000  # [-]: the region's outer points that the viewer camera frames, at most


@dataclass(frozen=True)
class RegionShown:
    """What the view drew of a region.

    Attributes:
        counts: Targets per category (:data:`~cpc2urdf.validation.gaze.reachable.REGION_CATEGORIES`).
        grid: The grid's kind (``"shell"``, ``"box"``).
        point_sizes: Side of the smallest and of the largest drawn points [m] (a shell's grow
            with distance: :func:`point_sizes`).
        frame: The head frame in the view's world (where the grid was put).
        offset: Largest distance [m] between a target as drawn and as the solver placed it in its
            own world: 0 up to rounding when the two are one model, the change of world otherwise
            (a model identified from a user's URDF is drawn in the URDF's root link's frame).
    """

    counts: dict[str, int]
    grid: str
    point_sizes: tuple[float, float]
    frame: HeadFrame
    offset: float

    @property
    def n(self) -> int:
        """Targets drawn."""
        return sum(self.counts.values())

    def format(self) -> str:
        """One line for a terminal."""
        parts = ", ".join(
            f"{k} {c.replace('_', ' ')} ({COLOUR_NAMES[c]})" for c, k in self.counts.items() if k
        )
        lo, hi = (1e3 * s for s in self.point_sizes)
        size = f"{lo:.3g} mm" if hi - lo <= 1e-9 * hi else f"{lo:.3g}-{hi:.3g} mm"
        line = (
            f"reachable region: {self.n} targets ({self.grid} grid): {parts}; drawn as points of {size}, "
            f"one category a node under '{REGION_NODE}' in meshcat's controls"
        )
        return line + (f"; {self.moved()}" if self.moved() else "")

    def moved(self) -> str:
        """How far the drawn points lie from where the solver (and ``reach --json``) put them,
        when the view draws the robot in another world; empty when it is the solver's."""
        if self.offset <= SAME_WORLD:
            return ""
        return (
            f"the view draws the robot in its URDF's root link frame: the points lie up to "
            f"{1e3 * self.offset:.3g} mm from the solver's (and --json's) world, at the same place on the head"
        )


def view_cameras(robot: ViewRobot, cameras: Sequence[str]) -> tuple[str, ...]:
    """The view's names of the solver's camera frames ``cameras``: the same, except for a model
    identified from a user's URDF, drawn under the URDF's names.

    Raises:
        UnknownNameError: A camera frame the drawn robot does not have.
    """
    source = None if robot.written_back is None else urdf_source(robot.written_back)
    names = tuple(source.urdf_link(c) for c in cameras) if source is not None else tuple(cameras)
    return tuple(robot.frame(c) for c in names)


def region_in_view(robot: ViewRobot, region: Region) -> tuple[Array, HeadFrame]:
    """The region's targets in the view's world [m], shape (N, 3), and the head frame they were
    put on (module docstring): the head frame of ``robot``'s cameras at the posture the grid's
    was taken at (its joints matched by name; the middle of the limits for the others, and for
    all when the grid was laid out at home)."""
    q = robot.default_q()
    if region.grid.posture is not None:
        source = None if robot.written_back is None else urdf_source(robot.written_back)
        for name, value in zip(region.joint_names, region.grid.posture.tolist(), strict=True):
            shown = source.joints.get(name, name) if source is not None else name
            if shown in robot.joint_names:
                q[robot.joint_names.index(shown)] = value
    frame = head_frame_at(robot.model, view_cameras(robot, region.cameras), q)
    return frame.to_world(region.grid.points_head), frame


def point_sizes(region: Region) -> Array:
    """Side [m] of the drawn points at each sample of the grid's first axis, shape (K,):
    :data:`POINT_FRACTION` of the spacing there, at most :data:`MAX_POINT_FRACTION` of the far
    range. A shell's points at distance ``d`` take the smaller of its two angular spacings at
    ``d`` (so the near shells stay clear of the head), and at most :data:`RADIAL_FRACTION` of the
    spacing between distances (dense shells do not merge into spokes; thin ones are not dashes);
    a box's the smallest of its three spacings."""
    a, b, c = (np.asarray(x, dtype=float) for x in region.grid.axes)
    steps = [float(np.ptp(x)) / (x.size - 1) for x in (a, b, c)]
    cap = MAX_POINT_FRACTION * float(np.max(np.abs(a)))
    if region.grid.kind == "shell":
        size = np.minimum(POINT_FRACTION * a * min(steps[1], steps[2]), RADIAL_FRACTION * steps[0])
    else:
        size = np.full(a.size, POINT_FRACTION * min(steps))
    return np.minimum(size, cap)


def framing_points(region: Region, points: Array) -> Array:
    """The targets on the grid's outer faces (any axis at its first or last sample), at most
    :data:`MAX_FRAMING_POINTS` of them: enough for the viewer camera to frame the whole region."""
    idx = np.unravel_index(np.arange(points.shape[0]), region.grid.shape)
    outer = np.zeros(points.shape[0], dtype=bool)
    for i, k in zip(idx, region.grid.shape, strict=True):
        outer |= (i == 0) | (i == k - 1)
    P = points[outer]
    step = max(1, math.ceil(P.shape[0] / MAX_FRAMING_POINTS))
    return np.asarray(P[::step])


def draw_region_points(
    vis: meshcat.Visualizer, robot: ViewRobot, region: Region
) -> tuple[RegionShown, Array]:
    """Draw ``region`` into ``vis``: under ``/meshcat/reach/<category>`` the category's targets,
    coloured as the PNG (:data:`CATEGORY_COLOURS`), as one point cloud per sample of the grid's
    first axis (``<category>/<k>``: a shell's distances, each with its point size).

    Returns:
        What was drawn, and the points to frame (world) [m], shape (K, 3) (:func:`framing_points`).

    Raises:
        UnknownNameError: The drawn robot lacks the region's camera frames.
    """
    points, frame = region_in_view(robot, region)
    sizes = point_sizes(region)
    first = np.unravel_index(np.arange(points.shape[0]), region.grid.shape)[
        0
    ]  # index along the first axis
    for k, name in enumerate(REGION_CATEGORIES):
        opacity = 1.0 if name in POINTED else OTHER_OPACITY
        for j, size in enumerate(sizes.tolist()):
            mask = (region.category == k) & (first == j)
            if not mask.any():
                continue
            P = points[mask].T.astype(np.float32)
            C = np.repeat(
                np.array(CATEGORY_COLOURS[name], dtype=np.float32)[:, None], P.shape[1], axis=1
            )
            vis[REGION_NODE][name][str(j)].set_object(
                mg.Points(mg.PointsGeometry(P, C), _PointsMaterial(size, opacity))
            )
    offset = float(np.max(np.linalg.norm(points - region.points, axis=1))) if points.size else 0.0
    shown = RegionShown(
        region.counts(), region.grid.kind, (float(sizes.min()), float(sizes.max())), frame, offset
    )
    return shown, framing_points(region, points)


class _PointsMaterial(mg.PointsMaterial):  # type: ignore[misc]
    """meshcat's points material (colours per point) with an opacity: below 1, translucent and
    not written to the depth buffer (points behind stay visible)."""

    def __init__(self, size: float, opacity: float) -> None:
        super().__init__(
            size=size, color=hex_colour((1.0, 1.0, 1.0))
        )  # white: the points' own colours
        self.opacity = opacity

    def lower(self, object_data: object) -> dict[str, object]:
        data: dict[str, object] = super().lower(object_data)
        if self.opacity < 1.0:
            data.update(transparent=True, opacity=self.opacity, depthWrite=False)
        return data


def region_legend_html(shown: RegionShown, notes: Sequence[str] = ()) -> str:
    """The region's legend for the static page: each category's colour and count, and ``notes``
    (which joints moved, the tolerance), over the lower right of the scene."""
    rows = "".join(
        f'<div><span class="sw" style="background:{_css(CATEGORY_COLOURS[c])}"></span>'
        f"{html.escape(c.replace('_', ' '))}: {shown.counts[c]}</div>"
        for c in REGION_CATEGORIES
        if shown.counts[c]
    )
    extra = "".join(f'<div class="rule">{html.escape(n)}</div>' for n in notes)
    return (
        f'<div id="cpc2urdf-region"><b>reachable region</b>: {shown.n} targets ({html.escape(shown.grid)} grid)'
        f"{rows}{extra}"
        f'<div class="rule">each category is a node under "{REGION_NODE}" in Open Controls &rarr; Scene</div></div>'
    )


def _css(rgb: Sequence[float]) -> str:
    r, g, b = (round(255 * c) for c in rgb[:3])
    return f"rgb({r},{g},{b})"


REGION_LEGEND_CSS = """#cpc2urdf-region { position: absolute; right: 8px; bottom: 8px; width: 300px;
  padding: 6px 8px; background: rgba(255,255,255,0.88); font: 12px sans-serif; color: #222;
  border: 1px solid #bbb; border-radius: 4px; }
#cpc2urdf-region .rule { margin: 3px 0; color: #555; font-size: 11px; }
#cpc2urdf-region .sw { display: inline-block; width: 10px; height: 10px; margin-right: 4px;
  border: 1px solid #666; vertical-align: middle; }"""


__all__ = [
    "COLOUR_NAMES",
    "MAX_FRAMING_POINTS",
    "MAX_POINT_FRACTION",
    "OTHER_OPACITY",
    "POINTED",
    "RADIAL_FRACTION",
    "POINT_FRACTION",
    "REGION_LEGEND_CSS",
    "REGION_NODE",
    "SAME_WORLD",
    "RegionShown",
    "draw_region_points",
    "framing_points",
    "point_sizes",
    "region_in_view",
    "region_legend_html",
    "view_cameras",
]
