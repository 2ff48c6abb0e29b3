"""meshcat geometry for the view: URDF visuals as meshcat shapes (boxes, cylinders, spheres, and
meshes as inline triangles), materials, bars and triads.

A mesh is sent as its triangles, as Pinocchio read them (assimp through coal, with the visual's
scale; :mod:`.meshes`): float32 vertices and 16- or 32-bit indices, inline in the page, whatever
the file's format (STL, DAE, OBJ, ...). three.js computes the normals.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import umsgpack
from numpy.typing import NDArray

from cpc2urdf.transforms import Array, cpc_rotation
from cpc2urdf.validation.view.view_robot import ViewRobot

TRIAD_LENGTH = 0.05  # [m]
TRIAD_RADIUS = 0.002  # [m]


def hex_colour(rgba: Sequence[float]) -> int:
    """``0xRRGGBB`` of an RGB(A) colour with components in [0, 1]."""
    r, g, b = (int(round(255 * min(max(float(c), 0.0), 1.0))) for c in rgba[:3])
    return (r << 16) | (g << 8) | b


def material(rgba: Sequence[float], opacity: float | None = None) -> mg.Material:
    """A Lambert material of colour ``rgba`` (its alpha, or ``opacity``; below 1 translucent)."""
    a = float(rgba[3]) if opacity is None else opacity
    if a < 1.0:
        return mg.MeshLambertMaterial(
            color=hex_colour(rgba), transparent=True, opacity=a, depthWrite=False
        )
    return mg.MeshLambertMaterial(color=hex_colour(rgba))


Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # Rot(x, 90 deg)


_UINT16 = 0x14  # meshcat's msgpack extension code of a Uint16Array (its viewer reads it)


class TriangleMesh(mg.Geometry):  # type: ignore[misc]
    """Triangles as a three.js ``BufferGeometry``, inline.

    Args:
        vertices: Vertex positions [m], shape (N, 3), in the mesh's frame.
        triangles: Vertex indices, shape (M, 3), counter-clockwise seen from outside.
    """

    def __init__(self, vertices: Array, triangles: NDArray[np.int64]) -> None:
        super().__init__()
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float32)
        self.triangles = np.ascontiguousarray(triangles, dtype=np.uint32)

    def lower(self, object_data: Any) -> dict[str, Any]:
        """The geometry as meshcat sends it (msgpack); 16-bit indices when they fit."""
        if len(self.vertices) <= 0xFFFF:
            data = self.triangles.astype(np.uint16).tobytes()
            index = {
                "itemSize": 1,
                "type": "Uint16Array",
                "normalized": False,
                "array": umsgpack.Ext(_UINT16, data),
            }
        else:
            index = mg.pack_numpy_array(self.triangles.reshape(1, -1))
        return {
            "uuid": self.uuid,
            "type": "BufferGeometry",
            "data": {
                "attributes": {"position": mg.pack_numpy_array(self.vertices.T)},
                "index": index,
            },
        }


def mesh_arrays(bvh: Any) -> tuple[Array, NDArray[np.int64]]:
    """Vertices [m], shape (N, 3), and triangles (vertex indices), shape (M, 3), of a coal
    ``BVHModel`` (its vertices already scaled by the visual's ``scale``)."""
    vertices = np.array(bvh.vertices(), dtype=float).reshape(-1, 3)
    triangles = np.array(
        [(t[0], t[1], t[2]) for t in (bvh.tri_indices(i) for i in range(bvh.num_tris))],
        dtype=np.int64,
    ).reshape(-1, 3)
    return vertices, triangles


def meshcat_shape(geometry: Any) -> tuple[mg.Geometry, Array, Array, Array] | None:
    """meshcat geometry of a coal shape, the local transform meshcat needs (its cylinders lie
    along y, URDF's along z), and the centre and half extents [m], each shape (3,), of its
    bounding box in meshcat's local axes; None for a shape the view cannot draw."""
    kind = type(geometry).__name__
    zero = np.zeros(3)
    if kind == "Box":
        half = np.asarray(geometry.halfSide, dtype=float)
        return mg.Box((2.0 * half).tolist()), np.eye(4), zero, half
    if kind == "Cylinder":
        r, h = float(geometry.radius), float(geometry.halfLength)
        return mg.Cylinder(2.0 * h, r), Y_TO_Z, zero, np.array([r, h, r])
    if kind == "Sphere":
        r = float(geometry.radius)
        return mg.Sphere(r), np.eye(4), zero, np.full(3, r)
    if kind.startswith("BVHModel") and geometry.num_tris > 0:
        vertices, triangles = mesh_arrays(geometry)
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        return TriangleMesh(vertices, triangles), np.eye(4), 0.5 * (lo + hi), 0.5 * (hi - lo)
    return None


@dataclass
class Visual:
    """One drawable URDF visual: its meshcat geometry, pose on its link, colour, and the centre
    and half extents [m], each shape (3,), of its bounding box in meshcat's local axes."""

    link: str
    name: str
    geometry: mg.Geometry
    T_link_visual: Array
    rgba: tuple[float, float, float, float]
    half: Array
    centre: Array = field(default_factory=lambda: np.zeros(3))

    def corners_link(self) -> Array:
        """The 8 corners of its bounding box in the link frame [m], shape (8, 3)."""
        signs = np.array(
            [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float
        )
        local = self.centre + signs * self.half
        return local @ self.T_link_visual[:3, :3].T + self.T_link_visual[:3, 3]


def link_visuals(robot: ViewRobot, q: Array) -> tuple[list[Visual], int]:
    """Every drawable URDF visual with its pose on its link at readings ``q`` (shape (n,)); and
    how many were skipped."""
    data = robot.model.createData()
    gdata = pin.GeometryData(robot.visual_model)
    pin.framesForwardKinematics(robot.model, data, q)
    pin.updateGeometryPlacements(robot.model, data, robot.visual_model, gdata)
    out, skipped = [], 0
    for k, go in enumerate(robot.visual_model.geometryObjects):
        shape = meshcat_shape(go.geometry)
        if shape is None:
            skipped += 1
            continue
        geometry, T_local, centre, half = shape
        link = robot.model.frames[go.parentFrame].name
        T_world_link = data.oMf[go.parentFrame].homogeneous
        T_world_visual = gdata.oMg[k].homogeneous
        T_link_visual = np.linalg.solve(T_world_link, T_world_visual) @ T_local
        rgba = tuple(float(c) for c in go.meshColor)
        out.append(Visual(link, str(go.name), geometry, T_link_visual, rgba, half, centre))  # type: ignore[arg-type]
    return out, skipped


def bar_pose(p0: Array, p1: Array) -> tuple[Array, float]:
    """The pose of a meshcat cylinder (axis y) from ``p0`` to ``p1`` [m], and its length [m]."""
    d = p1 - p0
    length = float(np.linalg.norm(d))
    T = np.eye(4)
    if length > 0:
        T[:3, :3] = cpc_rotation(d / length) @ Y_TO_Z[:3, :3].T  # eq. (4): z onto d, then y onto z
    T[:3, 3] = 0.5 * (p0 + p1)
    return T, length


def draw_triad(vis: meshcat.Visualizer, scale: float = 1.0) -> None:
    """An axis triad (x red, y green, z blue) at the node ``vis``, ``scale`` times the default size."""
    for axis, rgba in zip(
        range(3), ((0.9, 0.1, 0.1, 1), (0.1, 0.75, 0.1, 1), (0.1, 0.2, 0.95, 1)), strict=True
    ):
        end = np.zeros(3)
        end[axis] = scale * TRIAD_LENGTH
        T, length = bar_pose(np.zeros(3), end)
        node = vis["xyz"[axis]]
        node.set_object(mg.Cylinder(length, scale * TRIAD_RADIUS), material(rgba))
        node.set_transform(T)


def residual_rgba(fraction: float) -> tuple[float, float, float, float]:
    """Yellow (0) to red (1)."""
    f = min(max(fraction, 0.0), 1.0)
    return (0.95, 0.85 * (1.0 - f) + 0.05 * f, 0.1, 1.0)


def translation(p: Array) -> Array:
    """The (4, 4) pose that translates by ``p`` [m], shape (3,)."""
    T = np.eye(4)
    T[:3, 3] = p
    return T


__all__ = [
    "TRIAD_LENGTH",
    "TRIAD_RADIUS",
    "Y_TO_Z",
    "TriangleMesh",
    "Visual",
    "bar_pose",
    "draw_triad",
    "hex_colour",
    "link_visuals",
    "material",
    "mesh_arrays",
    "meshcat_shape",
    "residual_rgba",
    "translation",
]
