"""A meshcat view of a (calibrated) head: the visual check an engineer trusts.

The scene is built from the robot's URDF, through Pinocchio (its kinematic model and its visual
geometry model, so a plain ``.urdf`` works as well as a cpc2urdf model file), as direct meshcat
geometry (boxes, cylinders, spheres and STL/OBJ/DAE meshes with the URDF's ``<material>`` colours):

- ``/meshcat/head/<link>``: one node per URDF link, placed at ``T_world_<link>``; its visuals and,
  for plate and camera frames, an axis triad (x red, y green, z blue) are children;
- with a target: a sphere at ``p_world``, the head in the gaze solution, and a ray along each
  camera's optical (z) axis, as long as the distance to the point of the axis nearest the target;
- with another model (e.g. the nominal one): ``/meshcat/ghost``, the same links in the same
  configuration, translucent green;
- with measurements: each measured plate origin (small dark sphere) and a bar from it to the
  model's prediction at that record's joint readings, coloured by length (yellow = smallest,
  red = largest); bars are magnified so that the longest is visible (the factor is reported);
- an animation (meshcat's "Animations" panel, paused at t = 0): a sweep of one joint at a time
  around the shown configuration, which also works in the static HTML page.

The static page (:func:`static_view_html`) is one self-contained HTML file: meshcat's viewer
JavaScript inline and every scene command inline (decoded synchronously, no ``fetch``), so it opens
without a network and without a server. :func:`screenshot_html` renders it in headless Chromium.

Frames as in DESIGN.md: ``T_world_link`` is the pose of ``link`` in ``world`` (Pinocchio's oMf).
"""

from __future__ import annotations

import base64
import math
import os
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import meshcat
import meshcat.animation
import meshcat.geometry as mg
import numpy as np
import umsgpack
from meshcat.commands import SetAnimation
from meshcat.servers.tree import SceneTree, find_node, walk
from numpy.typing import ArrayLike

from cpc2urdf.errors import ConfigurationError, InputFileError, OutputError, UnknownNameError
from cpc2urdf.fileio import read_text_file, write_atomic
from cpc2urdf.transforms import Array, cpc_rotation
from cpc2urdf.urdf import HEAD_RGBA, urdf_from_model
from cpc2urdf.validation.gaze import target_point

DEFAULT_CAMERAS = ("camera_left_optical", "camera_right_optical")
TARGET_RGBA = (0.95, 0.1, 0.75, 1.0)  # magenta: no other part of the scene has this hue
GHOST_RGBA = (0.2, 0.75, 0.35, 0.35)
MEASURED_RGBA = (0.1, 0.1, 0.1, 1.0)
RAY_RGBA = (0.3, 0.8, 0.9, 1.0)  # the lens colour of cpc2urdf.urdf
BACKGROUND_TOP = (0.98, 0.98, 0.98)  # [0-1] light, so that every scene colour stands out
BACKGROUND_BOTTOM = (0.8, 0.82, 0.86)
TARGET_RADIUS = 0.015  # [m]
RAY_RADIUS = 0.0025  # [m]
TRIAD_LENGTH = 0.05  # [m]
TRIAD_RADIUS = 0.002  # [m]
MEASURED_RADIUS = 0.004  # [m]
RESIDUAL_RADIUS = 0.0025  # [m]
MIN_VISIBLE_RESIDUAL = 0.02  # [m]: the longest residual bar is drawn at least this long
FRAME_MARGIN = 0.02  # [m]: space around what frames the view
VIEWER_FOV = 75.0  # [deg]: meshcat's default perspective camera
SWEEP_FRACTION = 0.4  # each joint sweeps +-40 % of its range around the shown configuration
SWEEP_KEYS = 20  # keyframes per joint
SWEEP_FPS = 10  # [1/s]
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-quic",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
)
NO_NETWORK_FLAG = "--host-resolver-rules=MAP * ~NOTFOUND"  # for files: the page must not need a network


# ---- the robot, through its URDF and Pinocchio ----------------------------------------------


@dataclass
class ViewRobot:
    """A robot as the view sees it: Pinocchio's model and visual geometry from its URDF.

    Attributes:
        name: Robot name (URDF ``<robot name>``).
        source: Where it came from (a path or a shipped robot name).
        urdf: The URDF text.
        model: ``pinocchio.Model``.
        visual_model: ``pinocchio.GeometryModel`` of the URDF visuals.
        joint_names: Moving joints in Pinocchio's configuration order (all 1-DoF).
        lower: Lower joint limits [rad]/[m], shape (n,).
        upper: Upper joint limits [rad]/[m], shape (n,).
        links: URDF link names (Pinocchio BODY frames), in tree order.
        kinds: Link name -> ``"plate"``/``"camera"``/``"frame"`` for the named frames of a cpc2urdf
            model (for a plain URDF, guessed from the names: ``plate*``, ``*camera*``).
        metadata: A cpc2urdf model's metadata (provenance, residuals, ...), else empty.
    """

    name: str
    source: str
    urdf: str
    model: Any
    visual_model: Any
    joint_names: tuple[str, ...]
    lower: Array
    upper: Array
    links: tuple[str, ...]
    kinds: dict[str, str] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def default_q(self) -> Array:
        """The middle of every joint's range [rad]/[m], shape (n,)."""
        return 0.5 * (self.lower + self.upper)

    def q_from(
        self, values: Mapping[str, float] | ArrayLike | None, *, base: ArrayLike | None = None
    ) -> Array:
        """A configuration of shape (n,) from ``{joint: value}`` (others from ``base``, default
        the middle of the ranges) or from n values in :attr:`joint_names` order.

        Raises:
            UnknownNameError: A joint the robot does not have.
            ConfigurationError: Wrong count, NaN/inf, or a value outside the joint limits.
        """
        q = np.array(base, dtype=float) if base is not None else self.default_q()
        if values is None:
            pass
        elif isinstance(values, Mapping):
            for name, v in values.items():
                if name not in self.joint_names:
                    raise UnknownNameError("joint", str(name), self.joint_names)
                q[self.joint_names.index(name)] = float(v)
        else:
            arr = np.asarray(values, dtype=float)
            if arr.shape != (self.n_joints,):
                raise ConfigurationError(
                    f"configuration needs {self.n_joints} values for joints {list(self.joint_names)}, "
                    f"got shape {arr.shape}"
                )
            q = arr.copy()
        if not np.all(np.isfinite(q)):
            raise ConfigurationError("configuration contains NaN or inf")
        for i, name in enumerate(self.joint_names):
            if not self.lower[i] - 1e-12 <= q[i] <= self.upper[i] + 1e-12:
                raise ConfigurationError(
                    f"joint {name!r}: value {q[i]:.9g} outside its limits [{self.lower[i]:.9g}, {self.upper[i]:.9g}]"
                )
        return q

    def link_poses(self, q: ArrayLike) -> dict[str, Array]:
        """``T_world_<link>`` of every URDF link, each of shape (4, 4), at ``q`` (shape (n,))."""
        import pinocchio as pin

        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, np.asarray(q, dtype=float))
        return {
            f.name: data.oMf[i].homogeneous.copy()
            for i, f in enumerate(self.model.frames)
            if f.type == pin.FrameType.BODY
        }

    def frame(self, name: str) -> str:
        """``name`` if the robot has a link of that name, else :class:`UnknownNameError`."""
        if name not in self.links:
            raise UnknownNameError("frame", name, self.links)
        return name


def _kind_from_name(link: str) -> str:
    if link.startswith("plate"):
        return "plate"
    if "camera" in link:
        return "camera"
    return "frame"


def load_view_robot(source: str | os.PathLike[str] | Any) -> ViewRobot:
    """The robot to view: a ``.urdf`` file, a model file, a robot spec, a shipped robot name
    (``iis_head``), or a :class:`cpc2urdf.model.CPCModel`.

    Raises:
        InputFileError: Missing or unreadable file, a URDF Pinocchio cannot parse, or joints other
            than revolute/prismatic.
    """
    from cpc2urdf.model import CPCModel

    kinds: dict[str, str] = {}
    metadata: dict[str, Any] = {}
    if isinstance(source, CPCModel):
        text, label = urdf_from_model(source), f"<model {source.structure.name}>"
        kinds = {f.name: f.kind for f in source.structure.frames}
        metadata = dict(source.metadata)
    elif str(source).lower().endswith(".urdf"):
        p = Path(source)
        label = str(p)
        text = read_text_file(p, "a URDF file")
    else:
        from cpc2urdf.robot_ref import load_model

        label = str(source)
        cpc = load_model(label)
        text = urdf_from_model(cpc, source=label)
        kinds = {f.name: f.kind for f in cpc.structure.frames}
        metadata = dict(cpc.metadata)
    return _robot_from_urdf(text, label, kinds, metadata)


def _robot_from_urdf(
    text: str, label: str, kinds: dict[str, str], metadata: dict[str, Any]
) -> ViewRobot:
    import xml.etree.ElementTree as ET

    import pinocchio as pin

    try:  # urdfdom prints its own multi-line complaints about malformed XML; say it in one line
        ET.fromstring(text)
    except ET.ParseError as e:
        raise InputFileError(label, f"not well-formed XML ({e})") from e
    try:
        model = pin.buildModelFromXML(text)
        visual = pin.buildGeomFromUrdfString(model, text, pin.GeometryType.VISUAL)
    except (RuntimeError, ValueError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputFileError(label, f"not a URDF Pinocchio can read ({first})") from e
    names, lower, upper = [], [], []
    for jid in range(1, model.njoints):
        j = model.joints[jid]
        if j.nq != 1 or j.nv != 1:
            short = j.shortname().replace("JointModel", "")
            kind = {
                "RUBX": "continuous",
                "RUBY": "continuous",
                "RUBZ": "continuous",
                "RUBUnaligned": "continuous",
                "FreeFlyer": "floating",
                "Planar": "planar",
            }.get(short, short)
            raise InputFileError(
                label,
                f"joint {model.names[jid]!r} is {kind}; the view supports revolute and prismatic joints",
            )
        names.append(str(model.names[jid]))
        lower.append(float(model.lowerPositionLimit[j.idx_q]))
        upper.append(float(model.upperPositionLimit[j.idx_q]))
    lo, hi = np.array(lower), np.array(upper)
    # URDF joints without limits give +-huge; show them at 0 and sweep them +-pi (or +-0.5 m).
    unlimited = ~np.isfinite(lo) | ~np.isfinite(hi) | (hi - lo > 1e6)
    lo[unlimited], hi[unlimited] = -math.pi, math.pi
    links = tuple(f.name for f in model.frames if f.type == pin.FrameType.BODY)
    robot_name = str(model.name) or label
    kinds = {**{ln: _kind_from_name(ln) for ln in links if _kind_from_name(ln) != "frame"}, **kinds}
    return ViewRobot(
        robot_name, label, text, model, visual, tuple(names), lo, hi, links, kinds, metadata
    )


# ---- configurations: given, or the gaze solution -------------------------------------------


@dataclass
class GazeResult:
    """What the view shows of a gaze solve.

    Attributes:
        q: Joint values [rad]/[m], shape (n,), in :attr:`ViewRobot.joint_names` order.
        reachable: Whether the solver reports the target fixated within limits.
        pointing_error: Angle between each camera's optical axis and its target direction [rad],
            by camera frame.
        status: The solver's status text.
    """

    q: Array
    reachable: bool
    pointing_error: dict[str, float]
    status: str


def gaze_configuration(
    robot: ViewRobot,
    p_world: ArrayLike,
    q_current: ArrayLike,
    cameras: Sequence[str] = DEFAULT_CAMERAS,
    policy: str = "cyclopean",
) -> GazeResult:
    """The configuration fixating ``p_world`` [m], shape (3,), from the gaze solver
    (:class:`cpc2urdf.validation.gaze.GazeSolver` on the robot's URDF, started at ``q_current``,
    shape (n,), with its redundancy ``policy``)."""
    from cpc2urdf.validation.gaze import GazeSolver

    solver = GazeSolver(robot.urdf, tuple(cameras))
    sol = solver.solve(
        np.asarray(p_world, dtype=float),
        q_current=np.asarray(q_current, dtype=float),
        policy=policy,
    )
    by_name = dict(zip(sol.joint_names, np.asarray(sol.q, dtype=float).tolist(), strict=True))
    q = np.array([by_name[j] for j in robot.joint_names])
    errors = dict(zip(cameras, np.asarray(sol.pointing_error, dtype=float).tolist(), strict=True))
    return GazeResult(q, bool(sol.reachable), errors, str(sol.status))


# ---- meshcat geometry -----------------------------------------------------------------------


def _hex(rgba: Sequence[float]) -> int:
    r, g, b = (int(round(255 * min(max(float(c), 0.0), 1.0))) for c in rgba[:3])
    return (r << 16) | (g << 8) | b


def _material(rgba: Sequence[float], opacity: float | None = None) -> mg.Material:
    a = float(rgba[3]) if opacity is None else opacity
    if a < 1.0:
        return mg.MeshLambertMaterial(
            color=_hex(rgba), transparent=True, opacity=a, depthWrite=False
        )
    return mg.MeshLambertMaterial(color=_hex(rgba))


_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # Rot(x, 90 deg)


def _meshcat_shape(geometry: Any, mesh_path: str) -> tuple[mg.Geometry, Array, Array] | None:
    """meshcat geometry of a coal shape, the local transform meshcat needs (its cylinders lie
    along y, URDF's along z) and the half extents [m], shape (3,), of its bounding box in
    meshcat's local axes (zeros for meshes); None for a shape the view cannot draw."""
    kind = type(geometry).__name__
    if kind == "Box":
        half = np.asarray(geometry.halfSide, dtype=float)
        return mg.Box((2.0 * half).tolist()), np.eye(4), half
    if kind == "Cylinder":
        r, h = float(geometry.radius), float(geometry.halfLength)
        return mg.Cylinder(2.0 * h, r), _Y_TO_Z, np.array([r, h, r])
    if kind == "Sphere":
        r = float(geometry.radius)
        return mg.Sphere(r), np.eye(4), np.full(3, r)
    ext = Path(mesh_path).suffix.lower()
    loaders = {".stl": mg.StlMeshGeometry, ".obj": mg.ObjMeshGeometry, ".dae": mg.DaeMeshGeometry}
    if ext in loaders and Path(mesh_path).is_file():
        return loaders[ext].from_file(mesh_path), np.eye(4), np.zeros(3)
    return None


@dataclass
class _Visual:
    link: str
    name: str
    geometry: mg.Geometry
    T_link_visual: Array
    rgba: tuple[float, float, float, float]
    half: Array

    def corners_link(self) -> Array:
        """The 8 corners of its bounding box in the link frame [m], shape (8, 3)."""
        signs = np.array(
            [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float
        )
        local = signs * self.half
        return local @ self.T_link_visual[:3, :3].T + self.T_link_visual[:3, 3]


def _visuals(robot: ViewRobot, q: Array) -> tuple[list[_Visual], int]:
    """Every drawable URDF visual with its pose on its link; and how many were skipped."""
    import pinocchio as pin

    data = robot.model.createData()
    gdata = pin.GeometryData(robot.visual_model)
    pin.framesForwardKinematics(robot.model, data, q)
    pin.updateGeometryPlacements(robot.model, data, robot.visual_model, gdata)
    out, skipped = [], 0
    for k, go in enumerate(robot.visual_model.geometryObjects):
        shape = _meshcat_shape(go.geometry, str(go.meshPath))
        if shape is None:
            skipped += 1
            continue
        geometry, T_local, half = shape
        link = robot.model.frames[go.parentFrame].name
        T_world_link = data.oMf[go.parentFrame].homogeneous
        T_world_visual = gdata.oMg[k].homogeneous
        T_link_visual = np.linalg.solve(T_world_link, T_world_visual) @ T_local
        if type(go.geometry).__name__ not in ("Box", "Cylinder", "Sphere"):
            T_link_visual = T_link_visual @ np.diag([*np.asarray(go.meshScale, dtype=float), 1.0])
        rgba = tuple(float(c) for c in go.meshColor)
        out.append(_Visual(link, str(go.name), geometry, T_link_visual, rgba, half))  # type: ignore[arg-type]
    return out, skipped


def _bar(p0: Array, p1: Array) -> tuple[Array, float]:
    """The pose of a meshcat cylinder (axis y) from ``p0`` to ``p1`` [m], and its length [m]."""
    d = p1 - p0
    length = float(np.linalg.norm(d))
    T = np.eye(4)
    if length > 0:
        T[:3, :3] = cpc_rotation(d / length) @ _Y_TO_Z[:3, :3].T  # eq. (4): z onto d, then y onto z
    T[:3, 3] = 0.5 * (p0 + p1)
    return T, length


def _triad(vis: meshcat.Visualizer, scale: float = 1.0) -> None:
    for axis, rgba in zip(
        range(3), ((0.9, 0.1, 0.1, 1), (0.1, 0.75, 0.1, 1), (0.1, 0.2, 0.95, 1)), strict=True
    ):
        end = np.zeros(3)
        end[axis] = scale * TRIAD_LENGTH
        T, length = _bar(np.zeros(3), end)
        node = vis["xyz"[axis]]
        node.set_object(mg.Cylinder(length, scale * TRIAD_RADIUS), _material(rgba))
        node.set_transform(T)


def _residual_rgba(fraction: float) -> tuple[float, float, float, float]:
    """Yellow (0) to red (1)."""
    f = min(max(fraction, 0.0), 1.0)
    return (0.95, 0.85 * (1.0 - f) + 0.05 * f, 0.1, 1.0)


# ---- the scene ------------------------------------------------------------------------------


@dataclass
class ViewSummary:
    """What a view shows, for the CLI to print and tests to check.

    Attributes:
        robot: Robot name.
        q: Shown configuration, joint name -> value [rad]/[m].
        target: The target [m], shape (3,), or None.
        gaze: The gaze solve, or None without a target.
        ghost: Source of the ghost model, or None.
        n_measured: Measured plate positions drawn.
        residual_max: Longest measured-to-predicted distance [m] (NaN without measurements).
        residual_rms: RMS of those distances [m] (NaN without measurements).
        residual_scale: Magnification of the residual bars (1 = true length).
        skipped_visuals: URDF visuals the view cannot draw (unsupported shapes, missing meshes).
        camera_position: Where the viewer camera was placed [m], shape (3,), in world.
        camera_target: The point it looks at [m], shape (3,), in world.
        up: The world direction shown upwards, unit, shape (3,).
    """

    robot: str
    q: dict[str, float]
    target: Array | None = None
    gaze: GazeResult | None = None
    ghost: str | None = None
    n_measured: int = 0
    residual_max: float = float("nan")
    residual_rms: float = float("nan")
    residual_scale: float = 1.0
    skipped_visuals: int = 0
    camera_position: Array = field(default_factory=lambda: np.zeros(3))
    camera_target: Array = field(default_factory=lambda: np.zeros(3))
    up: Array = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def pixel(
        self, p_world: ArrayLike, width: int = 1024, height: int = 768
    ) -> tuple[float, float]:
        """Where ``p_world`` [m], shape (3,), appears in a ``width`` x ``height`` [px] screenshot
        of the page before the user moves the camera: (column, row) from the top left [px]."""
        back = self.camera_position - self.camera_target
        back /= np.linalg.norm(back)
        right = np.cross(self.up, back)
        right /= np.linalg.norm(right)
        cam_up = np.cross(back, right)
        d = np.asarray(p_world, dtype=float) - self.camera_position
        depth = -float(d @ back)
        tan_v = math.tan(math.radians(VIEWER_FOV / 2.0))
        tan_u = tan_v * width / height
        x, y = float(d @ right) / depth / tan_u, float(d @ cam_up) / depth / tan_v
        return 0.5 * width * (1.0 + x), 0.5 * height * (1.0 - y)

    def format(self) -> str:
        """A few lines for a terminal."""
        lines = [f"robot {self.robot}: " + ", ".join(f"{k}={v:.6g}" for k, v in self.q.items())]
        if self.target is not None and self.gaze is not None:
            err = ", ".join(
                f"{k} {math.degrees(v):.3g} deg" for k, v in self.gaze.pointing_error.items()
            )
            lines.append(
                f"target {np.array2string(self.target, precision=4)} m: {self.gaze.status}"
                f" (reachable={self.gaze.reachable}; pointing error {err})"
            )
        if self.ghost:
            lines.append(f"ghost: {self.ghost} (translucent green, same configuration)")
        if self.n_measured:
            lines.append(
                f"measurements: {self.n_measured} plate positions, residual rms {1e3 * self.residual_rms:.3g} mm,"
                f" max {1e3 * self.residual_max:.3g} mm (bars magnified x{self.residual_scale:.3g})"
            )
        if self.skipped_visuals:
            lines.append(
                f"note: {self.skipped_visuals} URDF visuals could not be drawn (unsupported shape or mesh)"
            )
        return "\n".join(lines)


def _parse_target(target: ArrayLike | None) -> Array | None:
    return None if target is None else target_point(target)


def build_view(
    vis: meshcat.Visualizer,
    robot: ViewRobot | str | os.PathLike[str] | Any,
    *,
    q: Mapping[str, float] | ArrayLike | None = None,
    target: ArrayLike | None = None,
    ghost: ViewRobot | str | os.PathLike[str] | Any | None = None,
    measurements: Any | None = None,
    cameras: Sequence[str] = DEFAULT_CAMERAS,
    policy: str = "cyclopean",
    sweep: bool = True,
    upright: bool = True,
) -> ViewSummary:
    """Draw the head (and target, ghost, measurements) into a meshcat visualizer.

    Args:
        vis: A ``meshcat.Visualizer`` (served, or :func:`static_visualizer` for a page).
        robot: The robot (see :func:`load_view_robot`) or a loaded :class:`ViewRobot`.
        q: Joint values [rad]/[m]: ``{joint: value}`` (others at mid-range) or n values in
            joint order; with a target, where the gaze solve starts. Default: mid-range.
        target: A point to fixate [m], shape (3,), in world; the head is shown in the gaze
            solution (:func:`gaze_configuration`) with a ray along each camera's optical axis.
        ghost: Another model of the same robot (e.g. the nominal one) drawn translucent.
        measurements: A :class:`cpc2urdf.measurements.MeasurementSet` of this robot.
        cameras: The two camera optical frames (left, right) used for the gaze.
        policy: The gaze solver's redundancy policy (``"cyclopean"``, ``"min-motion"``, ...).
        sweep: Add the joint sweep animation (paused at t = 0).
        upright: For a head (camera frames), turn the scene so that its first revolute joint's
            axis (the pan axis) points up on screen; False keeps world z up. The world triad
            shows the world axes.

    Raises:
        UnknownNameError: A camera or measured frame, or a joint, the robot does not have.
        ConfigurationError: A bad configuration or target (shape, NaN, limits).
        InputFileError: The robot or ghost cannot be loaded, or joints differ between them.
    """
    robot = robot if isinstance(robot, ViewRobot) else load_view_robot(robot)
    p_target = _parse_target(target)
    q0 = robot.q_from(q)
    gaze = None
    if p_target is not None:
        for c in cameras:
            robot.frame(c)
        gaze = gaze_configuration(robot, p_target, q0, cameras, policy)
        q0 = gaze.q
    summary = ViewSummary(
        robot.name, dict(zip(robot.joint_names, q0.tolist(), strict=True)), p_target, gaze
    )

    vis.delete()
    vis["/Background"].set_property("top_color", list(BACKGROUND_TOP))
    vis["/Background"].set_property("bottom_color", list(BACKGROUND_BOTTOM))
    vis["/Grid"].set_property("visible", False)
    vis["/Axes"].set_property(
        "visible", False
    )  # meshcat's axes sit at the viewer origin, not world
    _triad(vis["world"], 2.0)

    head = vis["head"]
    visuals, skipped = _visuals(robot, q0)
    summary.skipped_visuals = skipped
    for v in visuals:
        node = head[v.link][v.name]
        node.set_object(v.geometry, _material(v.rgba))
        node.set_transform(v.T_link_visual)
    for link, kind in robot.kinds.items():
        if link in robot.links and kind in ("plate", "camera"):
            _triad(head[link]["triad"])
    T_links = robot.link_poses(q0)
    for link in robot.links:
        head[link].set_transform(T_links[link])
    points = _focus_points(robot, T_links, visuals)

    if p_target is not None:
        vis["target"].set_object(mg.Sphere(TARGET_RADIUS), _material(TARGET_RGBA))
        vis["target"].set_transform(_translation(p_target))
        points.append(p_target)
        for c in cameras:
            # The ray runs along the optical axis to the point nearest the target (the fixation
            # point when the eye fixates); it hangs on the camera, so it moves in the sweep.
            d = T_links[c][:3, :3].T @ (p_target - T_links[c][:3, 3])
            T, length = _bar(np.zeros(3), np.array([0.0, 0.0, max(float(d[2]), 1e-3)]))
            head[c]["ray"].set_object(mg.Cylinder(length, RAY_RADIUS), _material(RAY_RGBA))
            head[c]["ray"].set_transform(T)

    ghost_robot = None
    if ghost is not None:
        ghost_robot = ghost if isinstance(ghost, ViewRobot) else load_view_robot(ghost)
        missing = [j for j in robot.joint_names if j not in ghost_robot.joint_names]
        if missing:
            raise InputFileError(
                ghost_robot.source,
                f"lacks joints {missing} of {robot.name!r}; cannot pose it alike",
            )
        q_ghost = _ghost_q(ghost_robot, robot, q0)
        gv, _ = _visuals(ghost_robot, q_ghost)
        for v in gv:
            node = vis["ghost"][v.link][v.name]
            node.set_object(v.geometry, _material(GHOST_RGBA))
            node.set_transform(v.T_link_visual)
        for link, T in ghost_robot.link_poses(q_ghost).items():
            vis["ghost"][link].set_transform(T)
        summary.ghost = ghost_robot.source

    if measurements is not None:
        points.extend(_draw_measurements(vis["measurements"], robot, measurements, summary))

    if sweep:
        _sweep(vis, robot, q0, ghost_robot)
    eyes = [T_links[c][:3, 3] for c in cameras if c in T_links]
    if p_target is not None and eyes:
        forward = p_target - np.mean(eyes, axis=0)
    else:
        forward = np.mean(
            [T_links[c][:3, 2] for c in cameras if c in T_links] or [np.array([1.0, 0, 0])], axis=0
        )
    up = _up_direction(robot, q0, T_links, cameras) if upright else np.array([0.0, 0.0, 1.0])
    eye, centre = _place_camera(vis, np.array(points), up, forward)
    summary.camera_position, summary.camera_target, summary.up = eye, centre, up
    return summary


def _ghost_q(ghost: ViewRobot, robot: ViewRobot, q: Array) -> Array:
    """The ghost's readings equal to ``robot``'s at ``q`` (shape (n,)), joint by joint by name,
    within the ghost's own limits."""
    by_name = dict(zip(robot.joint_names, q.tolist(), strict=True))
    qg = np.array(
        [by_name.get(j, m) for j, m in zip(ghost.joint_names, ghost.default_q(), strict=True)]
    )
    return np.clip(qg, ghost.lower, ghost.upper)


def _translation(p: Array) -> Array:
    T = np.eye(4)
    T[:3, 3] = p
    return T


def _draw_measurements(
    vis: meshcat.Visualizer, robot: ViewRobot, ms: Any, summary: ViewSummary
) -> list[Array]:
    names = list(ms.structure.joint_names)
    missing = [j for j in robot.joint_names if j not in names]
    if missing:
        raise InputFileError(
            getattr(ms, "source", "<measurements>"),
            f"lacks joints {missing} of robot {robot.name!r}",
        )
    cols = [names.index(j) for j in robot.joint_names]
    measured, predicted = [], []
    for frame, poses in ms.poses.items():
        robot.frame(frame)
        for i in range(len(ms.q)):
            if np.all(np.isfinite(poses[i])):
                measured.append(poses[i][:3, 3])
                predicted.append(
                    robot.link_poses(np.asarray(ms.q[i], dtype=float)[cols])[frame][:3, 3]
                )
    if not measured:
        return []
    P_m, P_p = np.array(measured), np.array(predicted)
    r = np.linalg.norm(P_p - P_m, axis=1)
    rmax = float(r.max())
    scale = max(1.0, MIN_VISIBLE_RESIDUAL / rmax) if rmax > 0 else 1.0
    summary.n_measured = len(r)
    summary.residual_max = rmax
    summary.residual_rms = float(np.sqrt(np.mean(r**2)))
    summary.residual_scale = scale
    rmin = float(r.min())
    for k, (pm, pp, rk) in enumerate(zip(P_m, P_p, r, strict=True)):
        vis["measured"][str(k)].set_object(mg.Sphere(MEASURED_RADIUS), _material(MEASURED_RGBA))
        vis["measured"][str(k)].set_transform(_translation(pm))
        if rk > 0:
            T, length = _bar(pm, pm + scale * (pp - pm))
            frac = (rk - rmin) / (rmax - rmin) if rmax > rmin else 1.0
            vis["residual"][str(k)].set_object(
                mg.Cylinder(length, RESIDUAL_RADIUS), _material(_residual_rgba(frac))
            )
            vis["residual"][str(k)].set_transform(T)
    return list(P_m)


def _sweep(vis: meshcat.Visualizer, robot: ViewRobot, q0: Array, ghost: ViewRobot | None) -> None:
    """One joint at a time: q0 -> q0 - a -> q0 + a -> q0 (a = SWEEP_FRACTION of the range, clamped
    to the limits), so the animation starts and ends at the shown configuration."""
    anim = meshcat.animation.Animation(default_framerate=SWEEP_FPS)
    frame = 0
    s = np.sin(np.linspace(0.0, 2.0 * np.pi, SWEEP_KEYS + 1))
    for i in range(robot.n_joints):
        a = SWEEP_FRACTION * (robot.upper[i] - robot.lower[i])
        for k, sk in enumerate(s if i == robot.n_joints - 1 else s[:-1]):
            q = q0.copy()
            q[i] = np.clip(q0[i] + a * sk, robot.lower[i], robot.upper[i])
            with anim.at_frame(vis, frame + k) as f:
                for link, T in robot.link_poses(q).items():
                    f["head"][link].set_transform(T)
                if ghost is not None:
                    for link, T in ghost.link_poses(_ghost_q(ghost, robot, q)).items():
                        f["ghost"][link].set_transform(T)
        frame += SWEEP_KEYS
    vis.window.send(_SetAnimationLast(anim, play=False))


class _SetAnimationLast(SetAnimation):
    """meshcat's ``set_animation``, stored on its own node created after the scene. meshcat's
    server replays its tree to each new browser root first; an animation stored on the root would
    load before the objects it animates and bind to nothing (the static page orders it last
    anyway)."""

    def lower(self) -> dict[str, Any]:
        data: dict[str, Any] = super().lower()
        data["path"] = "/cpc2urdf_sweep"
        return data


def _up_direction(
    robot: ViewRobot, q: Array, T_links: dict[str, Array], cameras: Sequence[str]
) -> Array:
    """The world direction shown as "up": for a head (a robot with camera frames) the axis of
    its first revolute joint (the pan axis), pointing from the base towards the cameras; world z
    for any other robot."""
    import pinocchio as pin

    if "camera" not in robot.kinds.values():
        return np.array([0.0, 0.0, 1.0])

    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    for jid in range(1, robot.model.njoints):
        if robot.model.joints[jid].shortname().startswith("JointModelR"):
            M = data.oMi[jid].homogeneous
            axis = M[:3, :3] @ _revolute_axis(robot.model.joints[jid].shortname())
            ref = [T_links[c][:3, 3] for c in cameras if c in T_links] or [
                T[:3, 3] for T in T_links.values()
            ]
            if float(axis @ (np.mean(ref, axis=0) - M[:3, 3])) < 0:
                axis = -axis
            return axis / np.linalg.norm(axis)
    return np.array([0.0, 0.0, 1.0])


def _revolute_axis(shortname: str) -> Array:
    if shortname.startswith("JointModelRevoluteUnaligned") or shortname.startswith("JointModelRUB"):
        return np.array([0.0, 0.0, 1.0])  # cpc2urdf writes z axes; unaligned axes are rare
    letter = shortname.replace("JointModelRUB", "").replace("JointModelR", "")[:1].upper()
    return (
        np.eye(3)["XYZ".index(letter)] if letter in "XYZ" and letter else np.array([0.0, 0.0, 1.0])
    )


def _focus_points(
    robot: ViewRobot, T_links: dict[str, Array], visuals: list[_Visual]
) -> list[Array]:
    """Where the head is: the bounding-box corners of the visuals on links moved by a revolute
    joint and on plate/camera frames (the XY table and base may lie outside the view; the viewer
    can zoom out). A robot without plate or camera frames is framed whole."""
    import pinocchio as pin

    if not robot.kinds:  # not a head with plates or cameras: frame the whole robot
        head_links = set(T_links)
    else:
        head_links = set(robot.kinds)
    for jid in range(1, robot.model.njoints if robot.kinds else 1):
        if robot.model.joints[jid].shortname().startswith("JointModelR"):
            for f in robot.model.frames:
                if f.type == pin.FrameType.BODY and _descends(robot.model, f.parentJoint, jid):
                    head_links.add(f.name)
    if not head_links & set(T_links):
        head_links = set(T_links)
    pts = [T_links[ln][:3, 3] for ln in head_links if ln in T_links]
    for v in visuals:
        if v.link in head_links:
            T = T_links[v.link]
            pts.extend(v.corners_link() @ T[:3, :3].T + T[:3, 3])
    return pts


def _descends(model: Any, jid: int, ancestor: int) -> bool:
    while jid > 0:
        if jid == ancestor:
            return True
        jid = model.parents[jid]
    return False


def _place_camera(
    vis: meshcat.Visualizer,
    points: Array,
    up: Array,
    forward: Array,
) -> tuple[Array, Array]:
    """Turn and shift the scene so that ``up`` points up on screen, then place meshcat's camera
    beside, a little behind and above ``forward`` (the gaze direction), centred on ``points``
    (shape (K, 3), world [m]) and just far enough for all of them (plus :data:`FRAME_MARGIN`) to
    fit meshcat's field of view in a 4:3 window.

    Returns:
        The camera position and the point it looks at, both in world [m], shape (3,).
    """
    R = cpc_rotation(up).T  # eq. (4): cpc_rotation(up) maps z onto up, so its inverse maps up to z
    P = points @ R.T  # display coordinates: up is +z
    f = R @ forward
    f[2] = 0.0
    f = f / np.linalg.norm(f) if np.linalg.norm(f) > 1e-9 else np.array([1.0, 0.0, 0.0])
    z = np.array([0.0, 0.0, 1.0])
    back = -0.35 * f + 0.85 * np.cross(z, f) + 0.4 * z  # from the centre towards the viewer
    back /= np.linalg.norm(back)
    right = np.cross(z, back)
    right /= np.linalg.norm(right)
    cam_up = np.cross(back, right)
    tan_v = math.tan(math.radians(VIEWER_FOV / 2.0))
    tan_u = tan_v * 4.0 / 3.0
    centre = 0.5 * (P.min(axis=0) + P.max(axis=0))
    for _ in range(20):  # perspective: centre the *projected* extents, then fit the distance
        rel = P - centre
        u, v, w = rel @ right, rel @ cam_up, rel @ back
        distance = float(
            np.max(
                np.maximum(
                    w + (np.abs(u) + FRAME_MARGIN) / tan_u, w + (np.abs(v) + FRAME_MARGIN) / tan_v
                )
            )
        )
        x, y = u / (distance - w) / tan_u, v / (distance - w) / tan_v  # screen coordinates, -1..1
        shift = (
            0.5 * (x.min() + x.max()) * tan_u * right + 0.5 * (y.min() + y.max()) * tan_v * cam_up
        )
        centre = centre + distance * shift
    offset = distance * back
    # meshcat's orbit controls always look at the viewer's origin, so the scene is turned and
    # shifted to put the centre there. The camera node is rotated +90 deg about x (three.js is
    # y-up): viewer (x, y, z) is (x, z, -y) there.
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -centre
    vis.set_transform(T)
    vis["/Cameras/default/rotated/<object>"].set_property(
        "position", [offset[0], offset[2], -offset[1]]
    )
    return R.T @ (centre + offset), R.T @ centre


# ---- a static page and its screenshot -------------------------------------------------------


class StaticWindow:
    """A meshcat window that records the scene instead of talking to a server.

    ``meshcat.Visualizer(window=StaticWindow())`` accepts every scene command; ``static_html()``
    then returns one self-contained page (same scene tree semantics as meshcat's server).
    """

    def __init__(self) -> None:
        self.tree = SceneTree()
        self.web_url = None

    def send(self, command: Any) -> None:
        data = command.lower()
        path = [p for p in data["path"].split("/") if p]
        packed = umsgpack.packb(data)
        kind = data["type"]
        if kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()
            return
        node = find_node(self.tree, path)
        if kind == "set_object":
            node.object = packed
            node.properties = []
        elif kind == "set_transform":
            node.transform = packed
        elif kind == "set_property":
            node.properties.append(packed)
        elif kind == "set_animation":
            node.animation = packed

    def get_scene(self) -> str:
        """The page: meshcat's viewer script, then every command, animations last (an animation
        binds to the objects that exist when it loads)."""
        commands, animations = [], []
        for node in walk(self.tree):
            if node.object is not None:
                commands.append(node.object)
            commands.extend(node.properties)
            if node.transform is not None:
                commands.append(node.transform)
            if node.animation is not None:
                animations.append(node.animation)
        blobs = ",\n".join(
            f'"{base64.b64encode(c).decode("ascii")}"' for c in commands + animations
        )
        viewer_js = (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text(
            encoding="utf-8"
        )
        return _PAGE.format(viewer_js=viewer_js.replace("</script", "<\\/script"), blobs=blobs)


_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>cpc2urdf view</title>
<style>body {{ margin: 0; }} #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}</style>
</head>
<body>
<div id="meshcat-pane"></div>
<script>
{viewer_js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
function cpc2urdfBytes(s) {{
  var b = atob(s), a = new Uint8Array(b.length);
  for (var i = 0; i < b.length; i++) a[i] = b.charCodeAt(i);
  return a;
}}
[{blobs}].forEach(function (s) {{ viewer.handle_command_bytearray(cpc2urdfBytes(s)); }});
document.title = "cpc2urdf view (loaded)";
</script>
</body>
</html>
"""


def static_visualizer() -> meshcat.Visualizer:
    """A ``meshcat.Visualizer`` that needs no server; ``vis.static_html()`` gives the page."""
    return meshcat.Visualizer(window=StaticWindow())


def static_view_html(
    robot: ViewRobot | str | os.PathLike[str] | Any, **options: Any
) -> tuple[str, ViewSummary]:
    """The self-contained HTML page of :func:`build_view` (same options) and its summary."""
    vis = static_visualizer()
    summary = build_view(vis, robot, **options)
    return vis.static_html(), summary


def write_view_html(
    path: str | os.PathLike[str], robot: ViewRobot | str | os.PathLike[str] | Any, **options: Any
) -> ViewSummary:
    """Write the page of :func:`build_view` to ``path`` atomically (for the demo: a calibrated
    model with ``target=[x, y, z]``); returns the summary.

    Example:
        ``write_view_html("out/view.html", model, target=[-0.9, -0.1, 0.1], ghost="iis_head")``
    """
    html, summary = static_view_html(robot, **options)
    write_atomic(path, html)
    return summary


def find_chromium() -> str | None:
    """Path of a Chromium/Chrome executable (``$CPC2URDF_CHROMIUM`` first), or None."""
    env = os.environ.get("CPC2URDF_CHROMIUM")
    if env:
        return env if Path(env).is_file() else shutil.which(env)
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


def screenshot_html(
    page: str | os.PathLike[str],
    png_path: str | os.PathLike[str],
    *,
    size: tuple[int, int] = (1024, 768),
    budget_ms: int = 2000,
    timeout: float = 120.0,
) -> Path:
    """Render a page in headless Chromium (software WebGL) and save a PNG screenshot.

    Args:
        page: The page file (e.g. from :func:`write_view_html`), or an ``http://`` URL (a served
            view; the static page needs no network, and Chromium is kept from resolving names).
        png_path: The PNG to write.
        size: Window width and height [px].
        budget_ms: Chromium's virtual time budget for the page to load and render [ms].
        timeout: Give up after this long [s] (the browser never waits for a user).

    Raises:
        InputFileError: The page file does not exist.
        OutputError: No Chromium found (install Debian's ``chromium``), it failed or timed out,
            or the PNG's folder does not exist.
    """
    exe = find_chromium()
    if exe is None:
        raise OutputError(
            "no Chromium found: install it (apt-get install chromium) or set CPC2URDF_CHROMIUM"
        )
    text = str(page)
    flags = list(CHROMIUM_FLAGS)
    if text.startswith(("http://", "https://")):
        url = text
    else:
        flags.append(NO_NETWORK_FLAG)
        html = Path(page).resolve()
        if not html.is_file():
            raise InputFileError(html, "no such file")
        url = html.as_uri()
    png = Path(png_path).resolve()
    if not png.parent.is_dir():
        raise OutputError(f"{png}: cannot write, folder {png.parent} does not exist")
    with tempfile.TemporaryDirectory(prefix="cpc2urdf-chromium-") as profile:
        tmp_png = Path(profile) / "shot.png"
        cmd = [
            exe,
            *flags,
            f"--user-data-dir={profile}/profile",
            f"--window-size={size[0]},{size[1]}",
            f"--virtual-time-budget={budget_ms}",
            f"--screenshot={tmp_png}",
            url,
        ]
        # Its own process group, so that a timeout ends the browser and all its helpers.
        proc = subprocess.Popen(
            cmd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
        )
        try:
            _, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired as e:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            raise OutputError(f"{png}: Chromium did not finish within {timeout:.0f} s") from e
        if proc.returncode != 0 or not tmp_png.is_file():
            tail = (err.strip().splitlines() or ["no output"])[-1]
            raise OutputError(f"{png}: Chromium failed (exit {proc.returncode}): {tail}")
        shutil.move(str(tmp_png), str(png))
    return png


__all__ = [
    "DEFAULT_CAMERAS",
    "HEAD_RGBA",
    "TARGET_RGBA",
    "GazeResult",
    "StaticWindow",
    "ViewRobot",
    "ViewSummary",
    "build_view",
    "find_chromium",
    "gaze_configuration",
    "load_view_robot",
    "screenshot_html",
    "static_view_html",
    "static_visualizer",
    "write_view_html",
]
