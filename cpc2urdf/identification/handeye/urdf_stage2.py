"""Stage 2 simulated for a URDF robot's cameras: hand-eye pose files and the true mounts.

The user names camera links of a URDF, in either convention (:mod:`cpc2urdf.urdf.camera_frames`:
an optical link, z forward, or a body link, x forward). Each camera's *hand* is the parent link of
its fixed mount joint. The robot is the URDF's sub-tree on the paths from the root to the camera
links, in CPC form (:func:`cpc2urdf.urdf.robot.urdf_robot`: the URDF's own forward kinematics, to
~1e-16). The simulation is that of :mod:`cpc2urdf.identification.handeye.stage2`: the true mounts
are the URDF's moved by up to ``translation`` per axis and turned by ``rotation`` about a random
axis (:func:`~cpc2urdf.identification.handeye.stage2.perturb_cameras`, on the optical frames);
the 25-disk target is placed ahead of the cameras at the middle of the joints' calibration ranges
(:func:`~cpc2urdf.identification.handeye.stage2.default_target_placement`); random configurations
keep it in view (:func:`~cpc2urdf.identification.handeye.stage2.sample_configurations`, drawn
from a shrinking part of the ranges until enough are found); solvePnP of the noisy disk centres
gives ``T_camera_target`` in each camera's optical frame; the URDF's forward kinematics gives
``T_base_hand`` (the hand is not perturbed: the calibration is of the camera mounts alone).

:func:`write_simulation` writes ``handeye_<link>.json`` per camera (``cpc2urdf/handeye-poses@1``,
camera = the link named, hand = its mount's parent link) and the truth: ``handeye_truth.urdf``
(the URDF with the true mounts written back) and ``handeye_truth.json`` (per camera the true and
nominal mount origins ``T_hand_link``, in the link's convention, and ``T_hand_optical``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.errors import ConfigurationError, DegenerateDataError, InputFileError
from cpc2urdf.files.jsonio import dumps, make_folder, write_all_atomic
from cpc2urdf.files.units import Units
from cpc2urdf.identification.handeye.axxb import HandEyeResult
from cpc2urdf.identification.handeye.pose_file import handeye_poses_to_json
from cpc2urdf.identification.handeye.stage2 import (
    DEFAULT_INTRINSICS,
    CameraIntrinsics,
    base_poses,
    default_target_placement,
    perturb_cameras,
    sample_configurations,
    simulate_observations,
    with_handeye_record,
)
from cpc2urdf.model import CPCModel, CPCParams, Frame
from cpc2urdf.transforms import Array, inverse, rotation_error
from cpc2urdf.urdf.camera_frames import CameraLink, camera_link, split_convention
from cpc2urdf.urdf.camera_mounts import (
    camera_links,
    frame_name,
    link_placement,
    optical_frames_model,
    with_camera_links,
)
from cpc2urdf.urdf.origins import writeback_plan
from cpc2urdf.urdf.robot import NameMap, urdf_robot
from cpc2urdf.urdf.tree import UrdfTree, read_urdf_tree
from cpc2urdf.urdf.writeback import calibrated_urdf_text

TRUTH_FORMAT = "cpc2urdf/handeye-truth@1"
TRUTH_FILES = ("handeye_truth.json", "handeye_truth.urdf")  # next to the pose files
SPREADS = (1.0, 0.5, 0.25, 0.125)  # parts of the calibration ranges tried in turn
DEFAULT_MOUNT_TRANSLATION = 0.005  # [m] per axis, as the IIS-head's stage-2 study
DEFAULT_MOUNT_ROTATION = math.radians(3.0)


@dataclass(frozen=True)
class UrdfCameraRig:
    """A URDF robot's cameras as stage 2 sees them.

    Attributes:
        tree: The URDF.
        cameras: Camera link -> its convention, mount and hand.
        model: The sub-tree on the paths to the camera links in CPC form, with frames named
            ``optical[link]`` (each camera's OPTICAL frame, kind ``camera``) and ``hand[link]``.
        optical: Camera link -> the model's frame of its optical frame.
        hand: Camera link -> the model's frame of its hand link.
    """

    tree: UrdfTree
    cameras: Mapping[str, CameraLink]
    model: CPCModel
    optical: Mapping[str, str]
    hand: Mapping[str, str]

    def mounts(self, model: CPCModel) -> dict[str, Array]:
        """Per camera link, ``T_hand_link`` (in the link's convention) in ``model`` (this rig's
        model or its truth)."""
        out = {}
        for link, cam in self.cameras.items():
            T_hand_optical = (
                inverse(model.frames[self.hand[link]].matrix())
                @ model.frames[self.optical[link]].matrix()
            )
            out[link] = cam.link_pose(T_hand_optical)
        return out


def camera_rig(
    urdf: str | Path | UrdfTree, cameras: Sequence[str], *, holding: str | None = None
) -> UrdfCameraRig:
    """The rig of ``cameras`` (URDF link names, each optionally ``LINK:optical``/``LINK:body``):
    :func:`~cpc2urdf.urdf.camera_mounts.optical_frames_model` (with the link ``holding`` a board,
    if any) plus each camera's hand frame.

    Raises:
        InputFileError: A camera link the URDF cannot carry or whose convention cannot be told (one
            line naming the link); a camera link below another.
    """
    tree = urdf if isinstance(urdf, UrdfTree) else read_urdf_tree(urdf)
    if not cameras:
        raise ConfigurationError("name at least one camera link")
    model, cams = optical_frames_model(tree, cameras, holding)
    for link in cams:
        above = [j.parent for j in tree.path(link) if j.parent in cams]
        if above:
            raise InputFileError(
                tree.source,
                f"camera link {link!r} hangs below camera link {above[0]!r}; name one of them",
            )
    optical, hand = {}, {}
    for link, cam in cams.items():
        K, T_K_hand = link_placement(model, tree, cam.hand)
        hand[link] = NameMap.of(tree).links[cam.hand]
        optical[link] = frame_name(model, tree, link)
        model = model.with_frame(Frame(hand[link], K, "frame"), CPCParams.from_matrix(T_K_hand))
    return UrdfCameraRig(tree, cams, model, optical, hand)


@dataclass(frozen=True)
class HandEyeSimulation:
    """A simulated stage 2 of a URDF robot's cameras (module docstring).

    Attributes:
        rig: The cameras and the robot.
        truth: The rig's model with the true (perturbed) camera frames.
        q: Joint readings, shape (N, n), in ``rig.model.structure.joint_names`` order.
        T_base_hand: Camera link -> ``T_base_hand`` from the URDF, shape (N, 4, 4) [m].
        T_camera_target: Camera link -> solvePnP's target pose in its optical frame, (N, 4, 4) [m].
        T_base_target: The target's true placement, shape (4, 4) [m].
        pixel_noise: Std of the image noise per coordinate [px].
        seed: The seed.
    """

    rig: UrdfCameraRig
    truth: CPCModel
    q: Array
    T_base_hand: Mapping[str, Array]
    T_camera_target: Mapping[str, Array]
    T_base_target: Array
    pixel_noise: float
    seed: int

    def true_mounts(self) -> dict[str, Array]:
        """Camera link -> its true mount ``T_hand_link``, in the link's convention."""
        return self.rig.mounts(self.truth)

    def nominal_mounts(self) -> dict[str, Array]:
        """Camera link -> the URDF's mount ``T_hand_link``."""
        return self.rig.mounts(self.rig.model)

    def pose_documents(self) -> dict[str, Any]:
        """Camera link -> its ``cpc2urdf/handeye-poses@1`` document (mm/deg)."""
        out = {}
        for link, cam in self.rig.cameras.items():
            C = self.T_camera_target[link]
            where = (
                ""
                if cam.optical == link
                else f" (the optical frame of {cam.convention} link {link})"
            )
            out[link] = handeye_poses_to_json(
                self.T_base_hand[link],
                C,
                labels=[f"config {k}" for k in range(len(C))],
                camera=_as_named(self.rig.tree, cam),
                hand=cam.hand,
                units=Units("mm", "deg"),
                description=f"stage-2 simulation of {self.rig.tree.name}: {len(C)} configurations, "
                f"pixel noise {self.pixel_noise} px, seed {self.seed}; T_camera_target in the camera's "
                f"optical frame{where}",
            )
        return out

    def truth_document(self) -> dict[str, Any]:
        """The true mounts as JSON (SI: m, rad; matrices)."""
        true, nominal = self.true_mounts(), self.nominal_mounts()
        cams = {}
        for link, cam in self.rig.cameras.items():
            d = inverse(nominal[link]) @ true[link]
            cams[link] = {
                "convention": cam.convention,
                "mount_joint": cam.mount.name,
                "hand": cam.hand,
                "optical_link": cam.optical,
                "T_hand_link": true[link].tolist(),
                "T_hand_optical": cam.optical_pose(true[link]).tolist(),
                "nominal_T_hand_link": nominal[link].tolist(),
                "moved_mm": float(np.linalg.norm(true[link][:3, 3] - nominal[link][:3, 3]) * 1e3),
                "turned_deg": float(np.degrees(rotation_error(d[:3, :3], np.eye(3)))),
            }
        return {
            "format": TRUTH_FORMAT,
            "urdf": self.rig.tree.source,
            "units": {"length": "m", "angle": "rad"},
            "T_base_target": self.T_base_target.tolist(),
            "pixel_noise_px": self.pixel_noise,
            "seed": self.seed,
            "cameras": cams,
        }

    def truth_urdf_text(self) -> str:
        """The URDF with the true mounts written back (only their ``<origin>`` tags differ)."""
        base = urdf_robot(self.rig.tree, list(self.rig.cameras)).nominal
        assert base is not None
        model = with_camera_links(base, self.rig.tree, self.true_mounts())
        return calibrated_urdf_text(writeback_plan(model))


def _as_named(tree: UrdfTree, cam: CameraLink) -> str:
    """The camera's name for its pose file: ``LINK``, or ``LINK:body``/``LINK:optical`` when the
    URDF cannot tell (so that ``cpc2urdf handeye`` reads the file as it was simulated)."""
    try:
        camera_link(tree, cam.link)
    except InputFileError:
        return f"{cam.link}:{cam.convention}"
    return cam.link


def _configurations(
    truth: CPCModel,
    n_poses: int,
    rng: np.random.Generator,
    T_base_target: Array,
    cameras: list[str],
    intrinsics: CameraIntrinsics,
) -> Array:
    """:func:`sample_configurations` over the calibration ranges, then shrinking parts of them."""
    for spread in SPREADS:
        try:
            return sample_configurations(
                truth,
                n_poses,
                rng,
                T_base_target,
                cameras=cameras,
                intrinsics=intrinsics,
                spread=spread,
            )
        except DegenerateDataError:
            if spread == SPREADS[-1]:
                raise
    raise AssertionError("unreachable")


def simulate_handeye(
    urdf: str | Path | UrdfTree,
    cameras: Sequence[str],
    *,
    n_poses: int = 20,
    pixel_noise: float = 0.1,
    seed: int = 0,
    translation: float = DEFAULT_MOUNT_TRANSLATION,
    rotation: float = DEFAULT_MOUNT_ROTATION,
    intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS,
) -> HandEyeSimulation:
    """Simulate stage 2 for the camera links ``cameras`` of ``urdf`` (module docstring).

    Args:
        urdf: The robot.
        cameras: Camera link names (``LINK:optical``/``LINK:body`` where the file cannot tell).
        n_poses: Configurations (>= 3).
        pixel_noise: Std of the Gaussian noise on each disk centre coordinate [px].
        seed: Seed of everything random.
        translation, rotation: How far the true mounts are from the URDF's [m] per axis, [rad].
        intrinsics: The cameras' intrinsics (all cameras).

    Raises:
        InputFileError: As :func:`camera_rig`.
        ConfigurationError: Fewer than 3 poses, negative noise.
        DegenerateDataError: The target cannot stay in view of every camera in enough configurations.
    """
    if n_poses < 3:
        raise ConfigurationError(f"stage 2 needs at least 3 configurations, got {n_poses}")
    for what, v in (
        ("pixel noise", pixel_noise),
        ("translation", translation),
        ("rotation", rotation),
    ):
        if not (math.isfinite(v) and v >= 0):
            raise ConfigurationError(f"{what} must be a finite number >= 0, got {v:g}")
    rig = camera_rig(urdf, cameras)
    rng = np.random.default_rng(seed)
    truth = perturb_cameras(rig.model, rng, translation, rotation)
    frames = [rig.optical[link] for link in rig.cameras]
    T_base_target = default_target_placement(truth, frames)
    q = _configurations(truth, n_poses, rng, T_base_target, frames, intrinsics)
    obs = simulate_observations(
        truth, q, T_base_target, rng, cameras=frames, intrinsics=intrinsics, pixel_noise=pixel_noise
    )
    return HandEyeSimulation(
        rig=rig,
        truth=truth,
        q=q,
        T_base_hand={link: base_poses(rig.model, rig.hand[link], q) for link in rig.cameras},
        T_camera_target={link: obs.T_camera_target[rig.optical[link]] for link in rig.cameras},
        T_base_target=T_base_target,
        pixel_noise=pixel_noise,
        seed=seed,
    )


def with_calibrated_camera(
    model: CPCModel | None,
    tree: UrdfTree,
    camera: str,
    result: HandEyeResult,
    *,
    hand: str | None = None,
    extra: dict[str, Any] | None = None,
) -> CPCModel:
    """A model built from ``tree`` with camera link ``camera`` placed by hand-eye calibration.

    ``result.X`` is ``T_hand_optical`` (the camera's optical frame in its mount's parent link);
    the link is placed in its own convention (``LINK:optical``/``LINK:body`` where the file cannot
    tell), so that writing the model back (``cpc2urdf export``) keeps an x-forward link x forward.
    The solution is recorded under ``metadata.handeye`` with the link's convention.

    Args:
        model: A model built from ``tree`` (the URDF, or identified from measurements of it); None
            for the URDF's own sub-tree on the path to the camera.
        tree: The URDF.
        camera: The camera link.
        result: Its hand-eye solution.
        hand: The hand the poses were taken with: the mount's parent link (None), or a URDF link
            or model frame fixed to it (e.g. a measured plate on the same link).
        extra: More details for the record (e.g. the pose file).

    Raises:
        InputFileError: As :func:`~cpc2urdf.urdf.camera_frames.camera_link`, or a ``hand`` that is
            not the mount's parent link.
    """
    cam, base, T_mount_hand = urdf_camera_mount(model, tree, camera, hand)
    link = cam.link
    T_hand_link = cam.link_pose(T_mount_hand @ result.X)
    out = with_camera_links(base, tree, {link: T_hand_link})
    details = {
        **(extra or {}),
        "camera_link": link,
        "convention": cam.convention,
        "optical_link": cam.optical,
        f"T_{cam.hand}_{link}": T_hand_link.tolist(),
    }
    return with_handeye_record(out, frame_name(out, tree, link), hand or cam.hand, result, details)


def urdf_camera_mount(
    model: CPCModel | None, tree: UrdfTree, camera: str, hand: str | None
) -> tuple[CameraLink, CPCModel, Array]:
    """Check a URDF camera link and the poses' hand before solving: the camera link, the model
    it goes into (``model``, or the URDF's sub-tree on its path) and the poses' hand in the
    mount's parent link, shape (4, 4).

    Raises:
        InputFileError: As :func:`with_calibrated_camera`.
    """
    link, stated = split_convention(camera)
    cam = camera_links(tree, {link: stated})[link]
    base = model if model is not None else urdf_robot(tree, [link]).nominal
    assert base is not None
    return cam, base, _hand_in_mount_parent(base, tree, cam, hand)


def _hand_in_mount_parent(
    model: CPCModel, tree: UrdfTree, cam: CameraLink, hand: str | None
) -> Array:
    """The poses' hand in the mount's parent link: identity for that link (or None); else a URDF
    link or model frame on the same rigid body (the same model link frame)."""
    if hand is None or hand == cam.hand:
        return np.eye(4)
    K, T_K_parent = link_placement(model, tree, cam.hand)
    if tree.has_link(hand):
        K_hand, T_K_hand = link_placement(model, tree, hand)
    elif hand in model.structure.frame_names:
        K_hand, T_K_hand = model.structure.frame(hand).parent, model.frames[hand].matrix()
    else:
        K_hand = None
    if K_hand != K:
        raise InputFileError(
            tree.source,
            f"camera link {cam.link!r} hangs on link {cam.hand!r} (joint {cam.mount.name!r}), but the "
            f"poses' hand {hand!r} is {'not a link' if K_hand is None else 'not fixed to it'}; give "
            f"T_base_hand of {cam.hand!r}",
        )
    return inverse(T_K_parent) @ T_K_hand


def pose_file_name(camera: str) -> str:
    """The pose file of a camera link in the simulation's folder."""
    return f"handeye_{split_convention(camera)[0]}.json"


def simulation_files(sim: HandEyeSimulation, folder: str | Path) -> dict[Path, str]:
    """The files :func:`write_simulation` writes, path -> text."""
    out = Path(folder)
    docs = sim.pose_documents()
    files = {out / pose_file_name(link): dumps(doc) for link, doc in docs.items()}
    files[out / TRUTH_FILES[0]] = dumps(sim.truth_document())
    files[out / TRUTH_FILES[1]] = sim.truth_urdf_text()
    return files


def write_simulation(sim: HandEyeSimulation, folder: str | Path) -> list[Path]:
    """Write the pose files and the truth into ``folder`` (created if missing), all or none."""
    files = simulation_files(sim, folder)
    make_folder(Path(folder))
    return write_all_atomic(files)


__all__ = [
    "DEFAULT_MOUNT_ROTATION",
    "DEFAULT_MOUNT_TRANSLATION",
    "SPREADS",
    "TRUTH_FILES",
    "TRUTH_FORMAT",
    "HandEyeSimulation",
    "UrdfCameraRig",
    "camera_rig",
    "pose_file_name",
    "simulate_handeye",
    "simulation_files",
    "urdf_camera_mount",
    "with_calibrated_camera",
    "write_simulation",
]
