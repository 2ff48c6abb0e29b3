"""Stage 2 (Shih et al. sec. 5): put the cameras into the model by hand-eye calibration.

The cameras, back on the head, view a plate of 5 x 5 light disks on black (the paper's 25-disk
target, Fig. 9) from several head configurations. Per configuration and camera, ``cv2.solvePnP``
on the disk centres gives ``T_camera_target``; the (identified) kinematic model gives the pose of
the hand, the end-effector plate frame the camera is mounted on (``plate_left`` / ``plate_right``,
the paper's frames 5L / 5R), ``T_base_hand``. Solving ``A X = X B`` (Tsai-Lenz, as the paper) or
``A X = Z B`` gives ``X = T_plate_camera`` (the paper's ``5L T CL``, eq. (70)); the camera frame
then hangs on the vergence link at ``T_link_plate @ X``.

Module-level definitions other code can use:

- The target: ``TARGET_*`` of :mod:`cpc2urdf.identification.vision.targets` (25 disk centres
  :data:`~cpc2urdf.identification.vision.targets.TARGET_LAYOUT` [m] in the target frame, pitch,
  disk and marker radii, plate size, and the target frame's definition).
- The cameras: :data:`DEFAULT_INTRINSICS` (640 x 480 px, f = 500 px: 65 x 51 deg field of view, no distortion; OpenCV
  camera matrix ``K`` and distortion ``D``), REP-103 optical frames.
- The placement: :func:`default_target_placement` puts the target 0.4 m in front of the cameras
  at the middle of the joints' calibration ranges, facing them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye.axxb import HandEyeResult
from cpc2urdf.identification.handeye.gate.gate_report import InconsistentPosesError
from cpc2urdf.identification.handeye.pose_file import save_handeye_poses
from cpc2urdf.identification.handeye.solvers import Gate, calibrate
from cpc2urdf.identification.vision.targets import TARGET_LAYOUT
from cpc2urdf.model import CPCModel, CPCParams, Frame
from cpc2urdf.model_metadata import HandEyeRecord
from cpc2urdf.transforms import Array, homogeneous, inverse, rotation_error

# ---- cameras -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole camera (OpenCV model).

    Attributes:
        fx, fy: Focal lengths [px].
        cx, cy: Principal point [px] (pixel centres at integer coordinates).
        width, height: Image size [px].
        dist: OpenCV distortion coefficients (k1, k2, p1, p2, k3).
    """

    fx: float = 500.0
    fy: float = 500.0
    cx: float = 319.5
    cy: float = 239.5
    width: int = 640
    height: int = 480
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def K(self) -> Array:
        """Camera matrix, shape (3, 3) [px]."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def D(self) -> Array:
        """Distortion coefficients, shape (5,)."""
        return np.array(self.dist, dtype=float)


DEFAULT_INTRINSICS = CameraIntrinsics()
# Which hand (end-effector plate frame) carries which camera.
HAND_OF_CAMERA: dict[str, str] = {
    "camera_left_optical": "plate_left",
    "camera_right_optical": "plate_right",
}
IMAGE_MARGIN = 10.0  # [px] every disk centre must be this far inside the image
DEFAULT_TARGET_DISTANCE = 0.4  # [m]


def base_poses(model: CPCModel, frame: str, q: Array) -> Array:
    """``T_base_<frame>`` for configurations q (N, n): shape (N, 4, 4)."""
    return inverse(model.T_world_base())[None] @ model.fk_frame(frame, q)


def home_configuration(model: CPCModel) -> Array:
    """Middle of every joint's calibration range (:meth:`RobotStructure.calibration_ranges`), shape (n,)."""
    return model.structure.calibration_ranges().mean(axis=1)


def default_target_placement(
    model: CPCModel,
    cameras: Sequence[str] = tuple(HAND_OF_CAMERA),
    distance: float = DEFAULT_TARGET_DISTANCE,
    q: Array | None = None,
) -> Array:
    """``T_base_target``: the target ``distance`` [m] ahead of the cameras at configuration ``q``
    (default the home configuration), on their mean optical axis, its disks facing them (target
    z = -optical axis, target x = the cameras' mean x). Shape (4, 4)."""
    q = (home_configuration(model) if q is None else np.asarray(q, dtype=float)).reshape(1, -1)
    T = np.concatenate([base_poses(model, c, q) for c in cameras])
    d = T[:, :3, 2].mean(axis=0)
    d /= np.linalg.norm(d)
    x = T[:, :3, 0].mean(axis=0)
    x -= (x @ d) * d
    x /= np.linalg.norm(x)
    z = -d
    y = np.cross(z, x)
    return homogeneous(np.column_stack([x, y, z]), T[:, :3, 3].mean(axis=0) + distance * d)


def project_target(
    T_camera_target: Array, intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS
) -> tuple[Array, bool]:
    """Image points of the disk centres, shape (25, 2) [px], and whether all are usable: in
    front of the camera, inside the image (margin :data:`IMAGE_MARGIN`), printed face towards it."""
    p_cam = TARGET_LAYOUT @ T_camera_target[:3, :3].T + T_camera_target[:3, 3]
    rvec, _ = cv2.Rodrigues(T_camera_target[:3, :3])
    projected, _ = cv2.projectPoints(
        TARGET_LAYOUT, rvec, T_camera_target[:3, 3], intrinsics.K, intrinsics.D
    )
    uv: Array = np.asarray(projected, dtype=float).reshape(-1, 2)
    facing = T_camera_target[:3, 2] @ T_camera_target[:3, 3] < 0  # normal points back at the camera
    inside = (
        np.all(p_cam[:, 2] > 0.05)
        and np.all(uv[:, 0] > IMAGE_MARGIN)
        and np.all(uv[:, 0] < intrinsics.width - 1 - IMAGE_MARGIN)
        and np.all(uv[:, 1] > IMAGE_MARGIN)
        and np.all(uv[:, 1] < intrinsics.height - 1 - IMAGE_MARGIN)
    )
    return uv, bool(facing and inside)


def pose_from_image_points(uv: Array, intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS) -> Array:
    """``T_camera_target`` from the 25 disk centres [px] by ``cv2.solvePnP`` (IPPE start for the
    planar target, then Levenberg-Marquardt refinement). Shape (4, 4)."""
    obj = TARGET_LAYOUT.astype(np.float64)
    img = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, intrinsics.K, intrinsics.D, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise DegenerateDataError("solvePnP failed on the target's disk centres")
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-15)
    rvec, tvec = cv2.solvePnPRefineLM(
        obj, img, intrinsics.K, intrinsics.D, rvec, tvec, criteria=crit
    )
    R, _ = cv2.Rodrigues(rvec)
    return homogeneous(R, tvec.ravel())


# ---- simulation --------------------------------------------------------------------------------


@dataclass
class Stage2Observations:
    """What stage 2 measures: joint readings and, per camera, the PnP target poses.

    Attributes:
        q: Joint readings, shape (N, n) [rad]/[m], in ``structure.joint_names`` order.
        T_camera_target: Per camera name, the estimated target poses, shape (N, 4, 4) [m].
        image_points: Per camera name, the noisy disk centres used, shape (N, 25, 2) [px].
        intrinsics: The cameras' intrinsics.
        pixel_noise: Standard deviation of the Gaussian noise added to each image coordinate [px].
        T_base_target: The true target placement, shape (4, 4) [m] (for reports).
    """

    q: Array
    T_camera_target: dict[str, Array]
    image_points: dict[str, Array]
    intrinsics: CameraIntrinsics
    pixel_noise: float
    T_base_target: Array


def sample_configurations(
    truth: CPCModel,
    n_poses: int,
    rng: np.random.Generator,
    T_base_target: Array,
    *,
    cameras: Sequence[str] = tuple(HAND_OF_CAMERA),
    intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS,
    spread: float = 1.0,
) -> Array:
    """Random configurations in which every camera sees the whole target.

    Joint values are drawn uniformly from the middle ``spread`` fraction of each calibration
    range (limits if none); configurations where a camera misses a disk are rejected.

    Returns:
        Shape (n_poses, n).

    Raises:
        DegenerateDataError: Fewer than ``n_poses`` usable configurations in 200 x n_poses tries.
    """
    s = truth.structure
    lo, hi = s.calibration_ranges().T
    mid, half = 0.5 * (lo + hi), 0.5 * spread * (hi - lo)
    accepted: list[Array] = []
    tries = 0
    while len(accepted) < n_poses:
        tries += 1
        if tries > 200 * n_poses:
            raise DegenerateDataError(
                f"only {len(accepted)} of {n_poses} random configurations let every camera see the "
                "whole target; move the target or narrow the joint ranges"
            )
        q = rng.uniform(mid - half, mid + half)
        T_cam = {c: base_poses(truth, c, q[None])[0] for c in cameras}
        if all(project_target(inverse(T_cam[c]) @ T_base_target, intrinsics)[1] for c in cameras):
            accepted.append(q)
    return np.array(accepted)


def simulate_observations(
    truth: CPCModel,
    q: Array,
    T_base_target: Array,
    rng: np.random.Generator,
    *,
    cameras: Sequence[str] = tuple(HAND_OF_CAMERA),
    intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS,
    pixel_noise: float = 0.0,
) -> Stage2Observations:
    """Project the target into the true cameras at configurations ``q`` (N, n), add Gaussian
    pixel noise (std ``pixel_noise`` [px] per coordinate) and estimate ``T_camera_target`` with
    solvePnP."""
    poses: dict[str, Array] = {}
    points: dict[str, Array] = {}
    for c in cameras:
        T_base_cam = base_poses(truth, c, q)
        Ts, uvs = [], []
        for k in range(len(q)):
            uv, _ = project_target(inverse(T_base_cam[k]) @ T_base_target, intrinsics)
            uv = uv + rng.normal(0.0, pixel_noise, uv.shape) if pixel_noise > 0 else uv
            uvs.append(uv)
            Ts.append(pose_from_image_points(uv, intrinsics))
        poses[c], points[c] = np.array(Ts), np.array(uvs)
    return Stage2Observations(
        np.asarray(q, dtype=float), poses, points, intrinsics, pixel_noise, T_base_target
    )


# ---- calibration -------------------------------------------------------------------------------


def hand_poses(model: CPCModel, camera: str, q: Array) -> Array:
    """``T_base_hand`` of the camera's hand (its plate frame) from ``model``, shape (N, 4, 4)."""
    return base_poses(model, HAND_OF_CAMERA[camera], q)


def calibrate_cameras(
    model: CPCModel,
    obs: Stage2Observations,
    method: str = "tsai",
    *,
    accept_inconsistent: bool = False,
) -> tuple[CPCModel, dict[str, HandEyeResult]]:
    """Solve X = T_plate_camera for every observed camera and set the camera frames.

    Every camera's poses pass the consistency gate
    (:func:`~cpc2urdf.identification.handeye.gate.handeye_gate.check_consistency`, noise estimated).

    Args:
        model: The identified kinematic model (gives ``T_base_hand``).
        obs: Joint readings and PnP target poses.
        method: Any solver of :data:`cpc2urdf.identification.handeye.solvers.ALL_METHODS`.
        accept_inconsistent: Keep the cameras of inconsistent data (the diagnosis goes into the
            model's hand-eye record) instead of raising.

    Returns:
        The model with ``camera_*_optical`` frames on the vergence links at ``T_link_plate @ X``
        and ``metadata.handeye`` holding each camera's solution and residuals; and the
        per-camera results.

    Raises:
        DegenerateDataError: As the solvers (too few poses, parallel axes, ...), naming the camera;
            ``InconsistentPosesError`` (a subclass) when the gate refuses the data.
    """
    results: dict[str, HandEyeResult] = {}
    out = model
    labels = [f"config {k}" for k in range(len(obs.q))]
    for camera, C in obs.T_camera_target.items():
        hand = HAND_OF_CAMERA[camera]
        try:
            gate = Gate(labels=labels, accept_inconsistent=accept_inconsistent)
            r = calibrate(hand_poses(model, camera, obs.q), C, method, gate=gate)
        except InconsistentPosesError as e:
            raise InconsistentPosesError(e.report, camera) from e
        except DegenerateDataError as e:
            raise DegenerateDataError(f"{camera}: {e}") from e
        results[camera] = r
        out = with_camera_frame(out, camera, hand, r, {"pixel_noise_px": obs.pixel_noise})
    return out, results


def with_camera_frame(
    model: CPCModel,
    camera: str,
    hand: str,
    result: HandEyeResult,
    extra: dict[str, Any] | None = None,
) -> CPCModel:
    """A copy of ``model`` with frame ``camera`` (kind ``camera``) on the link carrying ``hand``,
    at ``T_link_hand @ X``, and the solution recorded (:func:`with_handeye_record`).

    Raises:
        UnknownNameError: ``hand`` is not a frame of the model.
    """
    h = model.structure.frame(hand)
    T_link_camera = model.frames[hand].matrix() @ result.X
    out = model.with_frame(Frame(camera, h.parent, "camera"), CPCParams.from_matrix(T_link_camera))
    return with_handeye_record(out, camera, hand, result, extra)


def with_handeye_record(
    model: CPCModel,
    camera: str,
    hand: str,
    result: HandEyeResult,
    extra: dict[str, Any] | None = None,
) -> CPCModel:
    """A copy of ``model`` with ``result`` recorded in ``metadata.handeye[camera]`` (a
    :class:`~cpc2urdf.model_metadata.HandEyeRecord`; the consistency gate's report, if the gate
    ran, under ``details["consistency"]``)."""
    record = HandEyeRecord(
        hand=hand,
        method=result.method,
        T_hand_camera=result.X,
        T_base_target=result.Z,
        residual_translation_mm=result.residual_translation * 1e3,
        residual_rotation_deg=np.degrees(result.residual_rotation),
        warnings=tuple(result.warnings),
        details={
            **(extra or {}),
            **(
                {"consistency": result.consistency.to_json()}
                if result.consistency is not None
                else {}
            ),
        },
    )
    handeye = {**model.metadata.handeye, camera: record}
    return model.with_params(metadata=model.metadata.replace(handeye=handeye))


@dataclass
class Stage2Result:
    """Outcome of :func:`run_stage2`.

    Attributes:
        model: The identified model with the camera frames set from hand-eye calibration.
        results: Per camera, the hand-eye solution.
        observations: The simulated measurements.
        errors: Per camera, ``(translation [m], rotation [rad])`` error of ``T_link_camera``
            against the truth model.
    """

    model: CPCModel
    results: dict[str, HandEyeResult]
    observations: Stage2Observations
    errors: dict[str, tuple[float, float]] = field(default_factory=dict)

    def summary(self) -> str:
        """A few lines for people: residuals and errors per camera in mm/deg."""
        lines = []
        for c, r in self.results.items():
            line = (
                f"{c}: X = T_{HAND_OF_CAMERA[c]}_{c} by {r.method} from {len(r.residual_translation)} "
                f"poses, residual RMS {r.rms_translation() * 1e3:.3f} mm / {math.degrees(r.rms_rotation()):.4f} deg"
            )
            if c in self.errors:
                et, er = self.errors[c]
                line += f"; error vs truth {et * 1e3:.3f} mm / {math.degrees(er):.4f} deg"
            lines.append(line)
            lines += [f"  warning: {w}" for w in r.warnings]
        return "\n".join(lines)


def camera_errors(
    estimate: CPCModel, truth: CPCModel, cameras: Sequence[str]
) -> dict[str, tuple[float, float]]:
    """Per camera, the translation [m] and rotation [rad] error of ``X = T_hand_camera``.

    Compared relative to the hand (the plate on the same link), not to the link frame: an
    identified model's link frames are a gauge choice (the CPC conventions of sec. 2.2) that need
    not coincide with the truth's, while the plate is a physical, measured frame.
    """
    out = {}
    for c in cameras:
        hand = HAND_OF_CAMERA[c]
        Te = np.linalg.solve(estimate.frames[hand].matrix(), estimate.frames[c].matrix())
        Tt = np.linalg.solve(truth.frames[hand].matrix(), truth.frames[c].matrix())
        out[c] = (
            float(np.linalg.norm(Te[:3, 3] - Tt[:3, 3])),
            float(rotation_error(Te[:3, :3], Tt[:3, :3])),
        )
    return out


def run_stage2(
    identified: CPCModel,
    truth: CPCModel,
    *,
    n_poses: int = 20,
    pixel_noise: float = 0.1,
    method: str = "tsai",
    seed: int = 0,
    T_base_target: Array | None = None,
    intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS,
    cameras: Sequence[str] = tuple(HAND_OF_CAMERA),
) -> Stage2Result:
    """Simulate stage 2 on ``truth`` and calibrate the cameras of ``identified``.

    The head (``truth``, whose camera frames are the true mounts) moves to ``n_poses`` random
    configurations in which both cameras see the whole target, the cameras take pictures (pixel
    noise ``pixel_noise`` [px]), solvePnP gives ``T_camera_target``, ``identified`` gives
    ``T_base_hand``; hand-eye calibration (``method``) yields the camera frames.

    Args:
        identified: Stage-1 result (its camera frames, if any, are replaced).
        truth: The simulated real head, with true camera frames.
        n_poses: Number of head configurations (>= 3).
        pixel_noise: Std of image noise per coordinate [px].
        method: Hand-eye solver (default ``tsai``, as Shih et al.).
        seed: Seed of ``np.random.default_rng``.
        T_base_target: Target placement [m]; default :func:`default_target_placement` of truth.
        intrinsics: Camera intrinsics (both cameras).
        cameras: Camera frames to calibrate.

    Returns:
        The calibrated model, per-camera results and errors against the truth.
    """
    rng = np.random.default_rng(seed)
    if T_base_target is None:
        T_base_target = default_target_placement(truth, cameras)
    q = sample_configurations(
        truth, n_poses, rng, T_base_target, cameras=cameras, intrinsics=intrinsics
    )
    obs = simulate_observations(
        truth,
        q,
        T_base_target,
        rng,
        cameras=cameras,
        intrinsics=intrinsics,
        pixel_noise=pixel_noise,
    )
    model, results = calibrate_cameras(identified, obs, method)
    return Stage2Result(model, results, obs, camera_errors(model, truth, cameras))


def perturb_cameras(
    model: CPCModel,
    rng: np.random.Generator,
    translation: float = 0.005,
    rotation: float = math.radians(3.0),
) -> CPCModel:
    """A copy with every camera frame moved by up to ``translation`` [m] per axis and rotated by
    ``rotation`` [rad] about a random axis (a "true" head whose cameras differ from the nominal)."""
    from scipy.spatial.transform import Rotation

    out = model
    for f in model.structure.frames:
        if f.kind != "camera":
            continue
        axis = rng.normal(size=3)
        dT = homogeneous(
            Rotation.from_rotvec(axis / np.linalg.norm(axis) * rotation).as_matrix(),
            rng.uniform(-translation, translation, 3),
        )
        out = out.with_frame(f, CPCParams.from_matrix(model.frames[f.name].matrix() @ dT))
    return out


def write_pose_files(
    result: Stage2Result, folder: str | Path, model: CPCModel | None = None
) -> dict[str, Path]:
    """Write one ``cpc2urdf/handeye-poses@1`` file per camera (``handeye_<camera>.json``, mm/deg),
    hand poses from ``model`` (default: the identified model of the result), so that
    ``cpc2urdf handeye`` can be run on them."""
    from cpc2urdf.files.units import Units

    m = model or result.model
    obs = result.observations
    paths = {}
    for c, C in obs.T_camera_target.items():
        paths[c] = save_handeye_poses(
            Path(folder) / f"handeye_{c}.json",
            hand_poses(m, c, obs.q),
            C,
            labels=[f"config {k}" for k in range(len(C))],
            camera=c,
            hand=HAND_OF_CAMERA[c],
            units=Units("mm", "deg"),
            description=f"stage-2 simulation: {len(C)} head configurations, pixel noise {obs.pixel_noise} px",
        )
    return paths


__all__ = [
    "CameraIntrinsics",
    "DEFAULT_INTRINSICS",
    "HAND_OF_CAMERA",
    "Stage2Observations",
    "Stage2Result",
    "DEFAULT_TARGET_DISTANCE",
    "IMAGE_MARGIN",
    "base_poses",
    "calibrate_cameras",
    "camera_errors",
    "default_target_placement",
    "hand_poses",
    "home_configuration",
    "perturb_cameras",
    "pose_from_image_points",
    "project_target",
    "run_stage2",
    "sample_configurations",
    "simulate_observations",
    "with_camera_frame",
    "with_handeye_record",
    "write_pose_files",
]
