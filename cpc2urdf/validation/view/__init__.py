"""A meshcat view of a (calibrated) head: the visual check an engineer trusts.

The scene is built from the robot's URDF, through Pinocchio (its kinematic model and its visual
geometry model, so a plain ``.urdf`` works as well as a cpc2urdf model file), as direct meshcat
geometry (boxes, cylinders, spheres and STL/OBJ/DAE meshes with the URDF's ``<material>`` colours):
the head in a configuration (given, or the gaze solution for a target), rays along the optical
axes, a ghost model, measured plate positions with bars to the model's predictions, and a joint
sweep animation (:mod:`.scene`).

The static page (:func:`static_view_html`, :mod:`.page`) is one self-contained HTML file:
meshcat's viewer JavaScript inline and every scene command inline (decoded synchronously, no
``fetch``), so it opens without a network and without a server. :func:`screenshot_html`
(:mod:`.screenshot`) renders it in headless Chromium.

Modules: :mod:`.robot` (the robot: :class:`ViewRobot` on a
:class:`~cpc2urdf.validation.pinocchio_robot.PinocchioRobot`), :mod:`.geometry` (meshcat
shapes, materials, bars, triads), :mod:`.camera` (up direction, framing, camera placement),
:mod:`.scene`, :mod:`.summary` (:class:`ViewSummary`), :mod:`.page`, :mod:`.screenshot`.

Frames as in docs/architecture.md: ``T_world_link`` is the pose of ``link`` in ``world`` (Pinocchio's oMf).
"""

from __future__ import annotations

from cpc2urdf.urdf import HEAD_RGBA
from cpc2urdf.validation.gaze import DEFAULT_CAMERAS
from cpc2urdf.validation.view.page import (
    StaticWindow,
    static_view_html,
    static_visualizer,
    write_view_html,
)
from cpc2urdf.validation.view.robot import RobotSource, ViewRobot, load_view_robot
from cpc2urdf.validation.view.scene import GHOST_RGBA, TARGET_RGBA, build_view, gaze_configuration
from cpc2urdf.validation.view.screenshot import find_chromium, screenshot_html
from cpc2urdf.validation.view.summary import ViewSummary

__all__ = [
    "DEFAULT_CAMERAS",
    "GHOST_RGBA",
    "HEAD_RGBA",
    "TARGET_RGBA",
    "RobotSource",
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
