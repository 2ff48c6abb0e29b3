"""Where the viewer camera looks from: the head's up direction, what to frame, and the camera
placement that fits it into meshcat's field of view."""

from __future__ import annotations

import math
from collections.abc import Sequence

import meshcat
import numpy as np
import pinocchio as pin

from cpc2urdf.transforms import Array, cpc_rotation
from cpc2urdf.validation.view.geometry import Visual
from cpc2urdf.validation.view.view_robot import ViewRobot

FRAME_MARGIN = 0.02  # [m]: space around what frames the view
VIEWER_FOV = 75.0  # [deg]: meshcat's default perspective camera
VIEWER_FAR = 100.0  # [m]: meshcat's default camera draws nothing farther than this


def up_direction(
    robot: ViewRobot, q: Array, T_links: dict[str, Array], cameras: Sequence[str]
) -> Array:
    """The world direction shown as "up": for a head (a robot with camera frames) the axis of
    its first revolute joint (the pan axis), pointing from the base towards the cameras; world z
    for any other robot."""
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
    """The axis, in its joint frame, of a revolute Pinocchio joint model named ``shortname``."""
    if shortname.startswith("JointModelRevoluteUnaligned") or shortname.startswith("JointModelRUB"):
        return np.array([0.0, 0.0, 1.0])  # cpc2urdf writes z axes; unaligned axes are rare
    letter = shortname.replace("JointModelRUB", "").replace("JointModelR", "")[:1].upper()
    return (
        np.eye(3)["XYZ".index(letter)] if letter in "XYZ" and letter else np.array([0.0, 0.0, 1.0])
    )


def focus_points(robot: ViewRobot, T_links: dict[str, Array], visuals: list[Visual]) -> list[Array]:
    """Where the head is: the bounding-box corners of the visuals on links moved by a revolute
    joint and on plate/camera frames (the XY table and base may lie outside the view; the viewer
    can zoom out). A robot without plate or camera frames is framed whole."""
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


def _descends(model: pin.Model, jid: int, ancestor: int) -> bool:
    """Whether joint ``jid`` is joint ``ancestor`` or below it."""
    while jid > 0:
        if jid == ancestor:
            return True
        jid = model.parents[jid]
    return False


def place_camera(
    vis: meshcat.Visualizer,
    points: Array,
    up: Array,
    forward: Array,
) -> tuple[Array, Array]:
    """Turn and shift the scene so that ``up`` points up on screen, then place meshcat's camera
    beside, a little behind and above ``forward`` (the gaze direction), centred on ``points``
    (shape (K, 3), world [m]) and just far enough for all of them (plus :data:`FRAME_MARGIN`) to
    fit meshcat's field of view in a 4:3 window. Where the farthest point lies beyond half of
    meshcat's far clipping plane (:data:`VIEWER_FAR`), the plane is moved to twice its distance
    (a reachable region out to 100 m or more was cut off or not drawn at all).

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
    farthest = float(np.max(np.linalg.norm(P - (centre + offset), axis=1)))
    if 2.0 * farthest > VIEWER_FAR:  # three.js reads the camera's far plane again every frame
        vis["/Cameras/default/rotated/<object>"].set_property("far", 2.0 * farthest)
    return R.T @ (centre + offset), R.T @ centre


__all__ = [
    "FRAME_MARGIN",
    "VIEWER_FAR",
    "VIEWER_FOV",
    "focus_points",
    "place_camera",
    "up_direction",
]
