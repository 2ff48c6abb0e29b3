"""The scene of a view: the head in a configuration (given, or the gaze solution), with its
target and optical rays, a ghost model, measured plate positions, and a joint sweep animation.

- ``/meshcat/head/<link>``: one node per URDF link, placed at ``T_world_<link>``; its visuals and,
  for plate and camera frames, an axis triad (x red, y green, z blue) are children;
- with a target: a sphere at ``p_world``, the head in the gaze solution, and a ray along each
  camera's optical (z) axis, as long as the distance to the point of the axis nearest the target;
- with another model (e.g. the nominal one): ``/meshcat/ghost``, the same links in the same
  joint readings, translucent; in the robot's world if both are in one world, else placed so
  that its base link sits on the robot's (:func:`ghost_alignment`: a model in the rig's world
  and its gravity-aligned export compare link by link relative to the base); each link of the
  head is then coloured by how far calibration moved it from the ghost's link of the same name (:mod:`.change`: green < 1 mm, yellow, red
  >= 10 mm; grey: no such link in the ghost) and the ghost is blue, or, with
  ``change_colours=False``, the head keeps its URDF colours and the ghost is green;
- with measurements: each measured plate origin (small dark sphere) and a bar from it to the
  model's prediction at that record's joint readings, coloured by length (yellow = smallest,
  red = largest); bars are magnified so that the longest is visible (the factor is reported);
- with a reachable region (``cpc2urdf reach --html``): its targets as one point cloud per
  category under ``/meshcat/reach`` (:mod:`.region`), framed whole;
- an animation (meshcat's "Animations" panel, paused at t = 0): a sweep of one joint at a time
  around the shown configuration, which also works in the static HTML page.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import meshcat
import meshcat.animation
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from meshcat.commands import SetAnimation
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import ConfigurationError, InputFileError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.model import BASE
from cpc2urdf.transforms import Array, inverse, rotation_error
from cpc2urdf.urdf.robot import urdf_source
from cpc2urdf.validation.gaze import DEFAULT_CAMERAS, GazeSolution, GazeSolver, target_point
from cpc2urdf.validation.gaze.reachable import Region
from cpc2urdf.validation.view.camera import focus_points, place_camera, up_direction
from cpc2urdf.validation.view.change import (
    CHANGE_GHOST_RGBA,
    UNMATCHED_RGBA,
    change_rgba,
    link_changes,
)
from cpc2urdf.validation.view.geometry import (
    Visual,
    bar_pose,
    draw_triad,
    link_visuals,
    material,
    residual_rgba,
    translation,
)
from cpc2urdf.validation.view.region import draw_region_points
from cpc2urdf.validation.view.summary import ViewSummary
from cpc2urdf.validation.view.view_robot import RobotSource, ViewRobot, load_view_robot

TARGET_RGBA = (0.95, 0.1, 0.75, 1.0)  # magenta: no other part of the scene has this hue
GHOST_RGBA = (0.2, 0.75, 0.35, 0.35)
MEASURED_RGBA = (0.1, 0.1, 0.1, 1.0)
RAY_RGBA = (0.3, 0.8, 0.9, 1.0)  # the lens colour of cpc2urdf.urdf.document
BACKGROUND_TOP = (0.98, 0.98, 0.98)  # [0-1] light, so that every scene colour stands out
BACKGROUND_BOTTOM = (0.8, 0.82, 0.86)
TARGET_RADIUS = 0.015  # [m]
RAY_RADIUS = 0.0025  # [m]
MEASURED_RADIUS = 0.004  # [m]
RESIDUAL_RADIUS = 0.0025  # [m]
MIN_VISIBLE_RESIDUAL = 0.02  # [m]: the longest residual bar is drawn at least this long
SWEEP_FRACTION = 0.4  # each joint sweeps +-40 % of its range around the shown configuration
SWEEP_KEYS = 20  # keyframes per joint
SWEEP_FPS = 10  # [1/s]
ALIGN_MODES = ("auto", "base", "world")  # how a ghost is placed (ghost_alignment)
SAME_WORLD_DISTANCE = 0.05  # [m]: two anchors (bases) closer than this and ...
SAME_WORLD_ANGLE = math.radians(5.0)  # [rad]: ... turned less than this are in one world


def gaze_configuration(
    robot: ViewRobot,
    p_world: ArrayLike,
    q_current: ArrayLike,
    cameras: Sequence[str] = DEFAULT_CAMERAS,
    policy: str = "cyclopean",
) -> GazeSolution:
    """The configuration fixating ``p_world`` [m], shape (3,), from the gaze solver
    (:class:`cpc2urdf.validation.gaze.GazeSolver` on the robot's own Pinocchio model, started at
    ``q_current``, shape (n,), with its redundancy ``policy``). Its readings ``q`` are in
    :attr:`ViewRobot.joint_names` order (the solver's, as both use one model)."""
    solver = GazeSolver(robot.pinocchio, tuple(cameras))
    return solver.solve(
        np.asarray(p_world, dtype=float),
        q_current=np.asarray(q_current, dtype=float),
        policy=policy,
    )


def _parse_target(target: ArrayLike | None) -> Array | None:
    return None if target is None else target_point(target)


def build_view(
    vis: meshcat.Visualizer,
    robot: ViewRobot | RobotSource,
    *,
    q: Mapping[str, float] | ArrayLike | None = None,
    target: ArrayLike | None = None,
    ghost: ViewRobot | RobotSource | None = None,
    measurements: MeasurementSet | None = None,
    cameras: Sequence[str] = DEFAULT_CAMERAS,
    policy: str = "cyclopean",
    sweep: bool = True,
    upright: bool = True,
    change_colours: bool = True,
    align: str = "auto",
    region: Region | None = None,
) -> ViewSummary:
    """Draw the head (and target, ghost, measurements, reachable region) into a meshcat visualizer.

    Args:
        vis: A ``meshcat.Visualizer`` (served, or :func:`static_visualizer` for a page).
        robot: The robot (see :func:`load_view_robot`) or a loaded :class:`ViewRobot`.
        q: Joint values [rad]/[m]: ``{joint: value}`` (others at mid-range) or n values in
            joint order; with a target, where the gaze solve starts. Default: mid-range.
        target: A point to fixate [m], shape (3,), in world; the head is shown in the gaze
            solution (:func:`gaze_configuration`) with a ray along each camera's optical axis.
        ghost: Another model of the same robot (e.g. the nominal one) drawn translucent, in the
            same joint readings (joints matched by name).
        measurements: A :class:`cpc2urdf.files.measurements.MeasurementSet` of this robot.
        cameras: The camera optical frames used for the gaze: one (look-at), or two (left, right:
            two eyes, or a rigid pair whose cyclopean axis is pointed).
        policy: The gaze solver's redundancy policy (``"cyclopean"``, ``"min-motion"``, ...).
        sweep: Add the joint sweep animation (paused at t = 0).
        upright: For a head (camera frames), turn the scene so that its first revolute joint's
            axis (the pan axis) points up on screen; False keeps world z up. The world triad
            shows the world axes.
        change_colours: With a ghost, colour each link by how far it moved from the ghost's
            link of the same name (:mod:`cpc2urdf.validation.view.change`; the numbers are in
            :attr:`ViewSummary.link_changes`); False keeps the URDF colours.
        align: How the ghost is placed: ``"auto"``, ``"base"`` or ``"world"``
            (:func:`ghost_alignment`; :attr:`ViewSummary.alignment` says what was done).
        region: A reachable region of this robot's cameras
            (:func:`cpc2urdf.validation.gaze.reachable.reachable_region`), drawn as points
            (:func:`cpc2urdf.validation.view.region.draw_region_points`, numbers in
            :attr:`ViewSummary.region`); the view frames it whole.

    Raises:
        UnknownNameError: A camera or measured frame, or a joint, the robot does not have.
        ConfigurationError: A bad configuration or target (shape, NaN, limits).
        InputFileError: The robot or ghost cannot be loaded, or joints differ between them.
    """
    if align not in ALIGN_MODES:
        raise ConfigurationError(f"align must be one of {', '.join(ALIGN_MODES)}, got {align!r}")
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
        robot.name,
        dict(zip(robot.joint_names, q0.tolist(), strict=True)),
        p_target,
        gaze,
        cameras=tuple(cameras),
    )

    vis.delete()
    vis["/Background"].set_property("top_color", list(BACKGROUND_TOP))
    vis["/Background"].set_property("bottom_color", list(BACKGROUND_BOTTOM))
    vis["/Grid"].set_property("visible", False)
    vis["/Axes"].set_property(
        "visible", False
    )  # meshcat's axes sit at the viewer origin, not world
    draw_triad(vis["world"], 2.0)

    head = vis["head"]
    visuals, skipped = link_visuals(robot, q0)
    summary.skipped_visuals = skipped
    summary.meshes = robot.meshes
    T_links = robot.link_poses(q0)
    ghost_robot = None
    T_align = np.eye(4)  # the ghost's world -> the robot's (ghost_alignment)
    colours: dict[str, tuple[float, float, float, float]] = {}
    if ghost is not None:
        ghost_robot = ghost if isinstance(ghost, ViewRobot) else load_view_robot(ghost)
        _check_ghost(ghost_robot, robot)
        summary.ghost = ghost_robot.source
        placed = ghost_alignment(robot, ghost_robot, q0, align)
        T_align = placed.T_align
        summary.ghost_anchor, summary.ghost_offset = placed.anchor, placed.offset
        summary.ghost_aligned = placed.aligned
        if change_colours:
            colours = _change_colours(robot, ghost_robot, q0, T_links, visuals, summary, T_align)
    for v in visuals:
        node = head[v.link][v.name]
        node.set_object(v.geometry, material(colours.get(v.link, v.rgba)))
        node.set_transform(v.T_link_visual)
    for link, kind in robot.kinds.items():
        if link in robot.links and kind in ("plate", "camera"):
            draw_triad(head[link]["triad"])
    for link in robot.links:
        head[link].set_transform(T_links[link])
    points = focus_points(robot, T_links, visuals)

    if p_target is not None:
        _draw_target(vis, p_target, cameras, T_links)
        points.append(p_target)

    if ghost_robot is not None:
        _draw_ghost(
            vis["ghost"],
            ghost_robot,
            robot,
            q0,
            CHANGE_GHOST_RGBA if colours else GHOST_RGBA,
            T_align,
        )

    if measurements is not None:
        points.extend(_draw_measurements(vis["measurements"], robot, measurements, summary))

    if region is not None:
        summary.region, outer = draw_region_points(vis, robot, region)
        points.extend(outer)

    if sweep:
        _sweep(vis, robot, q0, ghost_robot, T_align)
    eyes = [T_links[c][:3, 3] for c in cameras if c in T_links]
    if p_target is not None and eyes:
        forward = p_target - np.mean(eyes, axis=0)
    else:
        forward = np.mean(
            [T_links[c][:3, 2] for c in cameras if c in T_links] or [np.array([1.0, 0, 0])], axis=0
        )
    up = up_direction(robot, q0, T_links, cameras) if upright else np.array([0.0, 0.0, 1.0])
    eye, centre = place_camera(vis, np.array(points), up, forward)
    summary.camera_position, summary.camera_target, summary.up = eye, centre, up
    return summary


def _draw_target(
    vis: meshcat.Visualizer, p_target: Array, cameras: Sequence[str], T_links: dict[str, Array]
) -> None:
    """The target sphere at ``p_target`` [m] (world), shape (3,), and a ray along each camera's
    optical axis (the cameras' link poses ``T_links``)."""
    vis["target"].set_object(mg.Sphere(TARGET_RADIUS), material(TARGET_RGBA))
    vis["target"].set_transform(translation(p_target))
    head = vis["head"]
    for c in cameras:
        # The ray runs along the optical axis to the point nearest the target (the fixation
        # point when the eye fixates); it hangs on the camera, so it moves in the sweep.
        d = T_links[c][:3, :3].T @ (p_target - T_links[c][:3, 3])
        T, length = bar_pose(np.zeros(3), np.array([0.0, 0.0, max(float(d[2]), 1e-3)]))
        head[c]["ray"].set_object(mg.Cylinder(length, RAY_RADIUS), material(RAY_RGBA))
        head[c]["ray"].set_transform(T)


@dataclass(frozen=True)
class GhostPlacement:
    """Where the ghost is drawn and compared (:func:`ghost_alignment`).

    Attributes:
        T_align: Takes the ghost's world to the robot's, shape (4, 4).
        anchor: The link both have to align on, or None.
        offset: ``T_r T_g^-1`` of the anchor (the ghost's world in the robot's), shape (4, 4).
        aligned: True when ``T_align`` is ``offset`` (links compared relative to the anchor),
            False when it is the identity (compared in one world).
    """

    T_align: Array
    anchor: str | None
    offset: Array
    aligned: bool


def ghost_alignment(
    robot: ViewRobot, ghost: ViewRobot, q: Array, align: str = "auto"
) -> GhostPlacement:
    """Where the ghost is drawn and compared: a :class:`GhostPlacement`.

    Two descriptions of one robot need not share a world: a model lives in the measuring rig's
    world, a spec's nominal model at the origin, ``export`` roots a ``world`` gravity-aligned at
    the base, a user's URDF its own root link. The anchor is ``base`` when both have it
    (cpc2urdf's models and URDFs), else the robot's root link if the ghost has it (a user's URDF
    and its written-back copy), else None. ``align``:

    - ``"base"``: the ghost's anchor is put on the robot's; links compared relative to it;
    - ``"world"``: the worlds are taken as one (``T_align`` identity);
    - ``"auto"``: as ``"base"`` when the anchors are :data:`SAME_WORLD_DISTANCE` or
      :data:`SAME_WORLD_ANGLE` apart or more (different worlds: calibration does not move a base
      that far), else as ``"world"`` (one world, e.g. a calibrated model and the true one in the
      rig: the honest comparison, which a base-aligned one would bend by the base's own error).

    Both anchors are fixed links, so nothing depends on ``q`` (shape (n,), the robot's readings).

    Raises:
        ConfigurationError: ``align`` is none of the three.
    """
    if align not in ALIGN_MODES:
        raise ConfigurationError(f"align must be one of {', '.join(ALIGN_MODES)}, got {align!r}")
    anchor = BASE if BASE in robot.links and BASE in ghost.links else robot.links[0]
    if anchor not in ghost.links:
        return GhostPlacement(np.eye(4), None, np.eye(4), False)
    T_r = robot.link_poses(q)[anchor]
    T_g = ghost.link_poses(_ghost_q(ghost, robot, q))[anchor]
    offset = T_r @ inverse(T_g)
    far = bool(
        np.linalg.norm(offset[:3, 3]) >= SAME_WORLD_DISTANCE
        or rotation_error(offset[:3, :3], np.eye(3)) >= SAME_WORLD_ANGLE
    )
    if align == "base" or (align == "auto" and far):
        return GhostPlacement(offset, anchor, offset, True)
    return GhostPlacement(np.eye(4), anchor, offset, False)


def _check_ghost(ghost: ViewRobot, robot: ViewRobot) -> None:
    """:class:`InputFileError` if the ghost lacks joints of ``robot`` (it cannot be posed alike)."""
    missing = [j for j in robot.joint_names if j not in ghost.joint_names]
    if missing:
        raise InputFileError(
            ghost.source,
            f"lacks joints {missing} of {robot.name!r}; cannot pose it alike",
        )


def _change_colours(
    robot: ViewRobot,
    ghost: ViewRobot,
    q: Array,
    T_links: dict[str, Array],
    visuals: list[Visual],
    summary: ViewSummary,
    T_align: Array,
) -> dict[str, tuple[float, float, float, float]]:
    """Link name -> the colour of how far it moved from ``ghost``'s link of that name at
    ``robot``'s readings ``q`` (shape (n,)), the ghost carried into the robot's world by
    ``T_align`` (shape (4, 4), :func:`ghost_alignment`); fills :attr:`ViewSummary.link_changes`
    and :attr:`ViewSummary.unmatched_links`."""
    points: dict[str, list[Array]] = {}
    for v in visuals:
        points.setdefault(v.link, []).append(v.corners_link())
    T_ghost = {ln: T_align @ T for ln, T in ghost.link_poses(_ghost_q(ghost, robot, q)).items()}
    # Aligned on a link, the links above it (a rig or gravity 'world') are where each model's
    # world is, not a part of the robot: not compared, drawn in their own colours.
    aligned_on = summary.ghost_anchor if summary.ghost_aligned else None
    above = set(robot.links_above(aligned_on)) if aligned_on is not None else set()
    changes = link_changes({ln: T for ln, T in T_links.items() if ln not in above}, T_ghost, points)
    summary.link_changes = changes
    summary.unmatched_links = tuple(
        ln for ln in robot.links if ln not in changes and ln not in above
    )
    colours = {ln: change_rgba(c.displacement) for ln, c in changes.items()}
    colours.update({ln: UNMATCHED_RGBA for ln in summary.unmatched_links})
    return colours


def _draw_ghost(
    vis: meshcat.Visualizer,
    ghost: ViewRobot,
    robot: ViewRobot,
    q: Array,
    rgba: tuple[float, float, float, float] = GHOST_RGBA,
    T_align: Array | None = None,
) -> None:
    """``ghost`` translucent in colour ``rgba`` at ``robot``'s readings ``q`` (shape (n,)),
    joint by joint by name, carried into the robot's world by ``T_align`` (shape (4, 4),
    :func:`ghost_alignment`; default identity).

    Raises:
        InputFileError: The ghost lacks joints of ``robot``.
    """
    _check_ghost(ghost, robot)
    q_ghost = _ghost_q(ghost, robot, q)
    gv, _ = link_visuals(ghost, q_ghost)
    for v in gv:
        node = vis[v.link][v.name]
        node.set_object(v.geometry, material(rgba))
        node.set_transform(v.T_link_visual)
    M = np.eye(4) if T_align is None else T_align
    for link, T in ghost.link_poses(q_ghost).items():
        vis[link].set_transform(M @ T)


def _ghost_q(ghost: ViewRobot, robot: ViewRobot, q: Array) -> Array:
    """The ghost's readings equal to ``robot``'s at ``q`` (shape (n,)), joint by joint by name,
    within the ghost's own limits."""
    by_name = dict(zip(robot.joint_names, q.tolist(), strict=True))
    qg = np.array(
        [by_name.get(j, m) for j, m in zip(ghost.joint_names, ghost.default_q(), strict=True)]
    )
    return np.clip(qg, ghost.lower, ghost.upper)


def _draw_measurements(
    vis: meshcat.Visualizer, robot: ViewRobot, ms: MeasurementSet, summary: ViewSummary
) -> list[Array]:
    """Measured plate origins and bars to the model's predictions into ``vis``; fills the
    residual statistics of ``summary``; returns the measured points [m] (world), each (3,).

    For a model identified from a user's URDF (drawn as the written-back URDF, in its root
    link's frame) the measurements name the model's joints and frames: they are mapped to the
    URDF's, the robot's other joints stay where they are shown, and the measured poses (in the
    rig's world) are carried into the root link's frame by ``T_world_base^-1``.
    """
    model = robot.written_back
    source = None if model is None else urdf_source(model)
    names = list(ms.structure.joint_names)
    T_shown_world = np.eye(4)
    link_of = {f: f for f in ms.poses}
    needed = list(robot.joint_names)
    if model is not None and source is not None:
        names = [source.joints.get(n, n) for n in names]
        link_of = {f: source.urdf_link(f) for f in ms.poses}
        T_shown_world = inverse(model.T_world_base())
        needed = [source.joints[n] for n in model.structure.joint_names]
    missing = [j for j in needed if j not in names]
    if missing:
        raise InputFileError(
            getattr(ms, "source", "<measurements>"),
            f"lacks joints {missing} of robot {robot.name!r}",
        )
    shown = dict(summary.q)
    measured, predicted = [], []
    for frame, poses in ms.poses.items():
        link = robot.frame(link_of[frame])
        for i in range(len(ms.q)):
            if np.all(np.isfinite(poses[i])):
                measured.append((T_shown_world @ poses[i])[:3, 3])
                reading = {
                    **shown,
                    **dict(zip(names, np.asarray(ms.q[i], dtype=float).tolist(), strict=True)),
                }
                q = np.array([reading[j] for j in robot.joint_names])
                predicted.append(robot.link_poses(q)[link][:3, 3])
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
        vis["measured"][str(k)].set_object(mg.Sphere(MEASURED_RADIUS), material(MEASURED_RGBA))
        vis["measured"][str(k)].set_transform(translation(pm))
        if rk > 0:
            T, length = bar_pose(pm, pm + scale * (pp - pm))
            frac = (rk - rmin) / (rmax - rmin) if rmax > rmin else 1.0
            vis["residual"][str(k)].set_object(
                mg.Cylinder(length, RESIDUAL_RADIUS), material(residual_rgba(frac))
            )
            vis["residual"][str(k)].set_transform(T)
    return list(P_m)


def _sweep(
    vis: meshcat.Visualizer,
    robot: ViewRobot,
    q0: Array,
    ghost: ViewRobot | None,
    T_align: Array | None = None,
) -> None:
    """One joint at a time: q0 -> q0 - a -> q0 + a -> q0 (a = SWEEP_FRACTION of the range, clamped
    to the limits), so the animation starts and ends at the shown configuration.

    A link gets keys only while a joint above it moves, and at the first and last frame (so every
    link's clip lasts the whole sweep): between those keys it rests at its shown pose. A robot
    with many joints and links (a TIAGo: 48 joints, 90 links) then stays a page of a few MB.
    """
    anim = meshcat.animation.Animation(default_framerate=SWEEP_FPS)
    s = np.sin(np.linspace(0.0, 2.0 * np.pi, SWEEP_KEYS + 1))
    last = SWEEP_KEYS * robot.n_joints
    models = [(robot, vis["head"], np.eye(4))]
    if ghost is not None:
        models.append((ghost, vis["ghost"], np.eye(4) if T_align is None else T_align))
    for model, node, M in models:
        data = model.model.createData()
        keys: dict[str, dict[int, Array]] = {}
        for i, joint in enumerate(robot.joint_names):
            if joint not in model.joint_names:
                continue
            below = model.links_below(joint)
            frames = [model.pinocchio.frame_id(link, pin.FrameType.BODY) for link in below]
            a = SWEEP_FRACTION * (robot.upper[i] - robot.lower[i])
            for k, sk in enumerate(s):
                q = q0.copy()
                q[i] = np.clip(q0[i] + a * sk, robot.lower[i], robot.upper[i])
                pin.framesForwardKinematics(model.model, data, _ghost_q(model, robot, q))
                for link, f in zip(below, frames, strict=True):
                    keys.setdefault(link, {})[SWEEP_KEYS * i + k] = M @ data.oMf[f].homogeneous
        rest = {ln: M @ T for ln, T in model.link_poses(_ghost_q(model, robot, q0)).items()}
        for link, by_frame in keys.items():
            by_frame[0] = by_frame[last] = rest[link]
            times = sorted(by_frame)
            T = np.array([by_frame[t] for t in times])
            xyzw = Rotation.from_matrix(T[:, :3, :3]).as_quat()  # three.js order (x, y, z, w)
            anim.clips[node[link].path] = meshcat.animation.AnimationClip(
                tracks={
                    "position": meshcat.animation.AnimationTrack(
                        "position", "vector3", times, T[:, :3, 3].tolist()
                    ),
                    "quaternion": meshcat.animation.AnimationTrack(
                        "quaternion", "quaternion", times, xyzw.tolist()
                    ),
                },
                fps=SWEEP_FPS,
            )
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


__all__ = [
    "BACKGROUND_BOTTOM",
    "BACKGROUND_TOP",
    "GHOST_RGBA",
    "MEASURED_RADIUS",
    "MEASURED_RGBA",
    "MIN_VISIBLE_RESIDUAL",
    "RAY_RADIUS",
    "RAY_RGBA",
    "RESIDUAL_RADIUS",
    "SWEEP_FPS",
    "SWEEP_FRACTION",
    "SWEEP_KEYS",
    "TARGET_RADIUS",
    "TARGET_RGBA",
    "build_view",
    "gaze_configuration",
    "ghost_alignment",
    "ALIGN_MODES",
    "GhostPlacement",
    "SAME_WORLD_ANGLE",
    "SAME_WORLD_DISTANCE",
]
