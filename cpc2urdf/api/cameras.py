"""The Python API's camera verbs: a head calibrated by its own cameras (one stage), and hand-eye
calibration of camera frames (stage 2). ``import cpc2urdf`` re-exports them with the rest of
:mod:`cpc2urdf.api`."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from cpc2urdf.errors import ConfigurationError, UnknownNameError
from cpc2urdf.files.robot_ref import RobotRef, is_urdf_ref, load_model
from cpc2urdf.model import CPCModel

if TYPE_CHECKING:  # the stages are imported inside the functions that use them
    from cpc2urdf.identification.handeye.axxb import HandEyeResult
    from cpc2urdf.identification.handeye.pose_file import HandEyePoses

PathLike = str | os.PathLike[str]


def calibrate_head(
    images: PathLike,
    urdf: PathLike,
    cameras: Sequence[str],
    *,
    board: PathLike | None = None,
    board_link: str | None = None,
    intrinsics: bool = False,
    accept_inconsistent: bool = False,
    on_error: str = "skip",
    show_progress: bool = False,
) -> CPCModel:
    """Calibrate a URDF robot's head from its own cameras' images of a board
    (``cpc2urdf identify IMAGES_DIR --robot ROBOT.urdf --cameras LINK``; docs/selfcal.md).

    One stage: every joint on the paths to the camera links (and, with ``board_link``, to the link
    holding the board), every camera's mount and the board's pose are fitted to the board's
    corners in pixels. What the images cannot determine keeps the URDF's values and is named in
    the notes.

    Args:
        images: ``<camera link>/<record>.png``, ``<camera link>.yaml``, ``joints.csv`` (the URDF's
            joint names) and ``board.json``.
        urdf: The robot's URDF.
        cameras: Camera link names (``LINK:optical``/``LINK:body`` where the file cannot tell).
        board: The board file (default: the folder's ``board.json``).
        board_link: The link holding the board (a gripper); None: the board is fixed.
        intrinsics: Refine each camera's ``fx, fy, cx, cy, k1, k2`` too.
        accept_inconsistent: Keep a model the consistency gate refuses (the reason in its notes).
        on_error: An unreadable image: ``"skip"`` it or ``"stop"``.
        show_progress: Progress bar on stderr while reading the images.

    Returns:
        The calibrated model: :func:`export_urdf` writes the URDF back (joints and camera links in
        their own conventions); ``metadata.provenance`` holds the corner noise, the board's pose.

    Raises:
        InconsistentDataError: The images do not fit the URDF's robot (the likely cause named).
    """
    from cpc2urdf.identification.selfcal.urdf_head import calibrate_urdf_head

    model, _ = calibrate_urdf_head(
        images,
        urdf,
        cameras,
        board=board,
        board_link=board_link,
        intrinsics=intrinsics,
        accept_inconsistent=accept_inconsistent,
        on_error=on_error,
        show_progress=show_progress,
    )
    return model


def load_handeye_poses(
    path: PathLike,
    camera: PathLike | None = None,
    *,
    time_offset: float | None = None,
    eye_to_hand: bool = False,
) -> HandEyePoses:
    """Read a ``cpc2urdf/handeye-poses@1`` file, or a robot and a camera pose stream (CSV or TUM;
    ``camera`` default: ``SEQ_camera.*`` beside ``SEQ_robot.*``) paired at the clock offset
    ``time_offset`` [s] (``t_camera = t_robot + time_offset``; estimated when None), with
    ``eye_to_hand`` for a fixed camera watching a marker on the hand (``docs/handeye.md``)."""
    from cpc2urdf.identification.handeye import stream_files
    from cpc2urdf.identification.handeye.pose_file import load_handeye_poses as _load

    if stream_files.is_pose_file(path):
        if camera is not None or time_offset is not None or eye_to_hand:
            raise ConfigurationError(
                f"{path}: a pose file pairs its poses already; a camera stream, a time offset and "
                "eye-to-hand apply to pose streams (CSV, TUM)"
            )
        return _load(path)
    return stream_files.load_handeye_streams(
        path, camera, time_offset=time_offset, eye_to_hand=eye_to_hand
    )


def solve_handeye(
    poses: HandEyePoses | PathLike,
    method: str = "ml",
    *,
    accept_inconsistent: bool = False,
    unknown_scale: bool = False,
) -> HandEyeResult:
    """Hand-eye and robot-world calibration ``A X = Z B`` of one camera (``cpc2urdf handeye``),
    through the consistency gate (the poses' stated noise against the residuals; docs/handeye.md).

    Args:
        poses: A :class:`HandEyePoses` or a ``cpc2urdf/handeye-poses@1`` file.
        method: A solver name of :data:`cpc2urdf.identification.handeye.solvers.ALL_METHODS`.
        accept_inconsistent: Keep a result whose poses fail the gate (the diagnosis is in its
            warnings) instead of raising.
        unknown_scale: The target translations are known up to one factor (monocular visual
            odometry); ``ml`` estimates it.

    Returns:
        ``X = T_hand_camera``, ``Z = T_base_target`` and the residual of every pose.
    """
    from cpc2urdf.identification.handeye.pose_file import HandEyePoses
    from cpc2urdf.identification.handeye.solvers import calibrate_poses

    data = poses if isinstance(poses, HandEyePoses) else load_handeye_poses(poses)
    return calibrate_poses(
        data, method, accept_inconsistent=accept_inconsistent, unknown_scale=unknown_scale
    )


def camera_mount(
    model: CPCModel | PathLike,
    poses: HandEyePoses,
    *,
    camera: str | None = None,
    hand: str | None = None,
) -> tuple[str, str]:
    """The camera frame to add and the frame it is fixed to, checked against ``model``.

    With ``model`` a URDF path, ``camera`` is a camera link of it (optical or x-forward body,
    docs/handeye.md) and ``hand`` (default: the mount's parent link) a link fixed to its mount's
    parent; both are checked as :func:`calibrate_cameras` will place them.

    Args:
        model: The model the camera goes into, or a URDF.
        poses: The hand-eye poses (their file may name ``camera`` and ``hand``).
        camera: Camera frame name (default: the pose file's ``camera``).
        hand: Frame of the model the camera is fixed to (default: the pose file's ``hand``).

    Raises:
        ConfigurationError: No camera or hand name; a hand the model does not have; ``camera``
            naming a frame that is not a camera.
    """
    camera, hand = camera or poses.camera, hand or poses.hand
    if not isinstance(model, CPCModel) and is_urdf_ref(os.fspath(model)):
        from cpc2urdf.identification.handeye.urdf_stage2 import urdf_camera_mount

        tree = _camera_urdf(os.fspath(model), None, camera)
        cam = urdf_camera_mount(None, tree, camera or "", hand or None)[0]
        return camera or cam.link, hand or cam.hand
    model = model if isinstance(model, CPCModel) else load_model(model)
    if not camera or not hand:
        raise ConfigurationError(
            f"{poses.source}: give the camera and hand frame names (--camera/--hand, or 'camera'/'hand' in the pose file)"
        )
    try:
        model.structure.frame(hand)
    except UnknownNameError as e:
        raise ConfigurationError(f"model {model.structure.name!r}: hand {e}") from e
    if camera in model.structure.frame_names and model.structure.frame(camera).kind != "camera":
        raise ConfigurationError(
            f"model {model.structure.name!r}: frame {camera!r} exists and is not a camera frame"
        )
    return camera, hand


def calibrate_cameras(
    model: CPCModel | RobotRef,
    poses: HandEyePoses | PathLike,
    method: str = "ml",
    *,
    camera: str | None = None,
    hand: str | None = None,
    result: HandEyeResult | None = None,
    accept_inconsistent: bool = False,
) -> CPCModel:
    """``model`` with one camera frame added (or replaced) from hand-eye poses.

    The camera frame is placed on the link of ``hand`` at ``T_link_hand @ X`` (stage 2 of
    Shih et al.); ``cpc2urdf handeye POSES --model M -o OUT`` does the same.

    A URDF robot's camera: with ``model`` a URDF path (or a model built from one) and ``camera``
    one of its links, optical (z forward) or body (x forward), the link is placed in its own
    convention (``X`` is the optical frame's pose in the mount's parent link, converted by the
    REP-103 rotation; a link whose convention the file cannot show is refused unless named
    ``LINK:optical``/``LINK:body``); :func:`export_urdf` then writes its mount origin back into
    the URDF, x forward for an x-forward link.

    Args:
        model: The identified model (or a reference :func:`load_model` accepts, or a URDF).
        poses: Head-camera observations of the target with the hand poses, or their file.
        method: Hand-eye solver (default the joint maximum likelihood ``ml``).
        camera: Camera frame name (default: the pose file's ``camera``).
        hand: Frame of the model the camera is fixed to (default: the pose file's ``hand``).
        result: A solution of these poses already computed (then ``method`` is not run again).
        accept_inconsistent: As :func:`solve_handeye`.

    Raises:
        ConfigurationError: See :func:`camera_mount`.
        DegenerateDataError: The poses cannot determine ``X`` (the solver says why).
    """
    from cpc2urdf.identification.handeye.pose_file import HandEyePoses
    from cpc2urdf.identification.handeye.solvers import calibrate_poses
    from cpc2urdf.identification.handeye.stage2 import with_camera_frame
    from cpc2urdf.identification.handeye.urdf_stage2 import with_calibrated_camera

    data = poses if isinstance(poses, HandEyePoses) else load_handeye_poses(poses)
    urdf_path = os.fspath(model) if isinstance(model, (str, os.PathLike)) else None
    m = None if urdf_path is not None and is_urdf_ref(urdf_path) else _as_model(model)
    tree = _camera_urdf(urdf_path, m, camera or data.camera)

    def solution() -> HandEyeResult:
        if result is not None:
            return result
        return calibrate_poses(data, method, accept_inconsistent=accept_inconsistent)

    if tree is not None:  # a URDF camera link, in its own convention
        name = camera or data.camera
        assert name is not None
        extra = {"poses": data.source}
        return with_calibrated_camera(
            m, tree, name, solution(), hand=hand or data.hand or None, extra=extra
        )
    assert m is not None
    camera, hand = camera_mount(m, data, camera=camera, hand=hand)
    return with_camera_frame(m, camera, hand, solution(), {"poses": data.source})


def _as_model(model: CPCModel | RobotRef) -> CPCModel:
    return model if isinstance(model, CPCModel) else load_model(model)


def _camera_urdf(urdf: str | None, model: CPCModel | None, camera: str | None) -> Any:
    """The URDF whose camera link ``camera`` names: ``urdf`` itself, or the one ``model`` was built
    from when ``camera`` is one of its links; else None (a camera frame of a CPC model)."""
    from cpc2urdf.urdf.camera_frames import split_convention
    from cpc2urdf.urdf.robot import urdf_source
    from cpc2urdf.urdf.tree import read_urdf_tree

    if model is None:
        if not camera:
            raise ConfigurationError(
                f"{urdf}: name the camera link (--camera, or 'camera' in the pose file)"
            )
        return read_urdf_tree(urdf)  # type: ignore[arg-type]
    source = urdf_source(model)
    if source is None or not camera:
        return None
    tree = read_urdf_tree(source.path)
    return tree if tree.has_link(split_convention(camera)[0]) else None


__all__ = [
    "calibrate_cameras",
    "calibrate_head",
    "camera_mount",
    "load_handeye_poses",
    "solve_handeye",
]
