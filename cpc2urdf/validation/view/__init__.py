"""A meshcat view of a (calibrated) head: the visual check an engineer trusts.

The scene is built from the robot's URDF, through Pinocchio (its kinematic model and its visual
geometry model, so a plain ``.urdf`` works as well as a cpc2urdf model file), as direct meshcat
geometry (boxes, cylinders, spheres and STL/OBJ/DAE meshes with the URDF's ``<material>`` colours):
the head in a configuration (given, or the gaze solution for a target), rays along the optical
axes, a ghost model (the nominal one) with each link coloured by how far calibration moved it
(:mod:`.change`), measured plate positions with bars to the model's predictions, and a joint
sweep animation (:mod:`.scene`). Meshes are the robot's own: ``package://``, ``file://`` and
relative paths resolved through the user's package directories, ``ROS_PACKAGE_PATH``/
``AMENT_PREFIX_PATH`` and the folders above the URDF (:mod:`.meshes`), inline in the page.

The static page (:func:`static_view_html`, :mod:`.page`) is one self-contained HTML file:
meshcat's viewer JavaScript inline and every scene command inline (decoded synchronously, no
``fetch``), so it opens without a network and without a server. :func:`screenshot_html`
(:mod:`.screenshot`) renders it in headless Chromium.

Modules: :mod:`.meshes` (where a URDF's meshes are; its visual geometry), :mod:`.robot` (the
robot: :class:`ViewRobot` on a :class:`~cpc2urdf.urdf.pinocchio.PinocchioRobot`),
:mod:`.geometry` (meshcat shapes, inline meshes, materials, bars, triads), :mod:`.change` (how far
calibration moved each link; colour scale, legend), :mod:`.camera` (up direction, framing, camera
placement), :mod:`.scene`, :mod:`.summary` (:class:`ViewSummary`), :mod:`.page`,
:mod:`.screenshot`.

Frames as in docs/architecture.md: ``T_world_link`` is the pose of ``link`` in ``world`` (Pinocchio's oMf).
"""

from __future__ import annotations

from cpc2urdf.urdf.document import HEAD_RGBA
from cpc2urdf.validation.gaze import DEFAULT_CAMERAS
from cpc2urdf.validation.view.change import (
    CHANGE_GHOST_RGBA,
    CHANGE_GREEN,
    CHANGE_LEVER,
    CHANGE_RED,
    LinkChange,
    change_rgba,
)
from cpc2urdf.validation.view.meshes import MeshSearch, UnresolvedMeshError, VisualMeshes
from cpc2urdf.validation.view.page import (
    StaticWindow,
    static_view_html,
    static_visualizer,
    write_view_html,
)
from cpc2urdf.validation.view.scene import GHOST_RGBA, TARGET_RGBA, build_view, gaze_configuration
from cpc2urdf.validation.view.screenshot import find_chromium, screenshot_html
from cpc2urdf.validation.view.summary import ViewSummary
from cpc2urdf.validation.view.view_robot import RobotSource, ViewRobot, load_view_robot

__all__ = [
    "CHANGE_GHOST_RGBA",
    "CHANGE_GREEN",
    "CHANGE_LEVER",
    "CHANGE_RED",
    "DEFAULT_CAMERAS",
    "GHOST_RGBA",
    "HEAD_RGBA",
    "TARGET_RGBA",
    "LinkChange",
    "MeshSearch",
    "RobotSource",
    "StaticWindow",
    "UnresolvedMeshError",
    "ViewRobot",
    "ViewSummary",
    "VisualMeshes",
    "build_view",
    "change_rgba",
    "find_chromium",
    "gaze_configuration",
    "load_view_robot",
    "screenshot_html",
    "static_view_html",
    "static_visualizer",
    "write_view_html",
]
