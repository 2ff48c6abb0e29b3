"""Measurement files from images: an images folder + joint readings -> measurements.

Stage 1 (Shih et al. sec. 3): a calibrated stereo rig photographs the head's plates at every
configuration. The folder layout (``docs/images.md``)::

    IMAGES_DIR/
      left/<record>.png      # left rig camera (world frame), any format OpenCV reads
      right/<record>.png     # right rig camera
      joints.csv             # one row per record: record,<joint>[unit],...

``joints.csv`` has a header ``record,table_x[mm],table_y[mm],pan[deg],...``: a ``record`` column
naming the image files (without extension), optionally a ``label`` column, and one column per
joint, whose header may carry the unit in brackets (``m``, ``cm``, ``mm`` for prismatic joints,
``rad``, ``deg`` for revolute ones; no bracket: SI). :func:`measure_stereo_images` detects the
plates in each pair (:mod:`cpc2urdf.identification.vision.detect`), triangulates and registers them and
returns a :class:`~cpc2urdf.measurements.MeasurementSet` with ``T_world_<plate>`` and the
triangulated circle centres (``points``).

Stage 2 (sec. 5): the head's own cameras photograph the 25-disk target::

    IMAGES_DIR/
      camera_left_optical/<record>.png
      camera_right_optical/<record>.png
      joints.csv

:func:`measure_head_images` gives ``T_camera_target`` per camera and record by ``cv2.solvePnP``
and, with the identified model, ``T_base_hand``: the input of ``cpc2urdf handeye``.

A plate (or target) that cannot be measured is reported with the image, the plate and the reason;
``on_error="stop"`` raises at the first one, ``"skip"`` leaves that plate out of that record
(and drops a record with nothing measured), ``"skip-record"`` drops the whole record; both skips
list every problem.

:func:`render_experiment` and :func:`render_head_experiment` write such folders from a simulated
experiment (plus ``rig.yaml`` / camera files and the truth), so the whole pipeline can run from
rendered pixels.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import (
    ConfigurationError,
    Cpc2UrdfError,
    DegenerateDataError,
    InputFileError,
    OutputError,
)
from cpc2urdf.fileio import read_text_file
from cpc2urdf.identification.vision.detect import (
    DetectionError,
    StereoPlatePose,
    stereo_plate_poses,
    target_pose,
)
from cpc2urdf.identification.vision.render import PlateDesign, robot_plate_designs, target_design
from cpc2urdf.measurements import MeasurementSet
from cpc2urdf.model import CPCModel, RobotStructure
from cpc2urdf.progress import progress
from cpc2urdf.units import ANGLE_UNITS, LENGTH_UNITS

Array = NDArray[np.float64]

STEREO_FOLDERS = ("left", "right")
IMAGE_EXTENSIONS = (".png", ".tif", ".tiff", ".bmp", ".pgm", ".jpg", ".jpeg")
ON_ERROR = ("skip", "skip-record", "stop")
_HEADER = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_.-]*)\s*(?:\[\s*([A-Za-z]+)\s*\])?\s*$")


# ---- joints.csv ------------------------------------------------------------------------------------


@dataclass
class JointTable:
    """The rows of a ``joints.csv``.

    Attributes:
        records: Image file stems, one per row.
        labels: Labels (the ``label`` column, else the record names).
        q: Joint readings [m]/[rad], shape (N, n), in ``structure.joint_names`` order.
    """

    records: list[str]
    labels: list[str]
    q: Array


def read_joints_csv(path: str | Path, structure: RobotStructure) -> JointTable:
    """Read a ``joints.csv`` (see the module docstring).

    Raises:
        InputFileError: Naming the file, the row and the column: missing/unknown/duplicate
            columns, a unit that does not fit the joint, a non-number, a duplicate record.
    """
    p = Path(path)
    text = read_text_file(p, "a CSV file", encoding="utf-8-sig")
    rows = [r for r in csv.reader(io.StringIO(text)) if r and not (len(r) == 1 and not r[0].strip())]
    rows = [r for r in rows if not r[0].lstrip().startswith("#")]
    if not rows:
        raise InputFileError(p, "empty; expected a header 'record,<joint>[unit],...' and one row per record")
    names, scales = [], []
    for col, h in enumerate(rows[0]):
        m = _HEADER.match(h)
        if not m:
            raise InputFileError(p, f"column {col + 1} header {h!r} must be a name, optionally with a unit like pan[deg]")
        names.append(m.group(1))
        scales.append(m.group(2))
    if len(set(names)) != len(names):
        raise InputFileError(p, f"duplicate column in header {rows[0]}")
    if "record" not in names:
        raise InputFileError(p, "missing column 'record' (the image file name without extension)")
    joint_cols = [n for n in names if n not in ("record", "label")]
    unknown = [n for n in joint_cols if n not in structure.joint_names]
    if unknown:
        raise InputFileError(p, f"unknown joint column {unknown[0]!r}; joints of {structure.name}: {', '.join(structure.joint_names)}")
    missing = [n for n in structure.joint_names if n not in names]
    if missing:
        raise InputFileError(p, f"missing joint column {missing[0]!r} (every joint needs a reading)")
    factor = {}
    for n, unit in zip(names, scales, strict=True):
        if n in ("record", "label"):
            continue
        jt = structure.joint(n).type
        table = LENGTH_UNITS if jt == "prismatic" else ANGLE_UNITS
        if unit is None:
            factor[n] = 1.0
        elif unit not in table:
            raise InputFileError(p, f"column {n}: unit [{unit}] does not fit a {jt} joint; use one of {sorted(table)}")
        else:
            factor[n] = table[unit]
    records, labels, qs = [], [], []
    for k, row in enumerate(rows[1:], start=2):
        if len(row) != len(names):
            raise InputFileError(p, f"row {k}: {len(row)} values, the header has {len(names)} columns")
        d = dict(zip(names, (v.strip() for v in row), strict=True))
        rec = d["record"]
        if not rec or "/" in rec or "\\" in rec:
            raise InputFileError(p, f"row {k}: record must be a file name without folders, got {rec!r}")
        if rec in records:
            raise InputFileError(p, f"row {k}: record {rec!r} appears twice")
        q = []
        for n in structure.joint_names:
            try:
                v = float(d[n])
            except ValueError:
                raise InputFileError(p, f"row {k} (record {rec}): {n} must be a number, got {d[n]!r}") from None
            if not math.isfinite(v):
                raise InputFileError(p, f"row {k} (record {rec}): {n} must be finite, got {d[n]!r}")
            q.append(v * factor[n])
        records.append(rec)
        labels.append(d.get("label") or rec)
        qs.append(q)
    if not records:
        raise InputFileError(p, "has a header but no records")
    return JointTable(records, labels, np.array(qs))


def write_joints_csv(
    path: str | Path, structure: RobotStructure, records: Sequence[str], q: ArrayLike,
    labels: Sequence[str] | None = None, *, length: str = "mm", angle: str = "deg",
) -> Path:
    """Write a ``joints.csv`` atomically (lengths in ``length``, angles in ``angle``)."""
    from cpc2urdf.fileio import write_atomic

    qq = np.asarray(q, dtype=float)
    head = ["record", "label"] + [
        f"{j.name}[{length if j.type == 'prismatic' else angle}]" for j in structure.joints
    ]
    scale = [LENGTH_UNITS[length] if j.type == "prismatic" else ANGLE_UNITS[angle] for j in structure.joints]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    for i, rec in enumerate(records):
        lab = labels[i] if labels is not None else rec
        w.writerow([rec, lab] + [repr(float(v / s)) for v, s in zip(qq[i], scale, strict=True)])
    return write_atomic(path, buf.getvalue())


# ---- images ----------------------------------------------------------------------------------------


def find_image(folder: Path, record: str) -> Path | None:
    """The image file ``folder/<record>.<ext>`` (first of :data:`IMAGE_EXTENSIONS`), or None.
    A record that already names a file with its extension is taken as is."""
    if Path(record).suffix.lower() in IMAGE_EXTENSIONS and (folder / record).is_file():
        return folder / record
    for ext in IMAGE_EXTENSIONS:
        for e in (ext, ext.upper()):
            p = folder / f"{record}{e}"
            if p.is_file():
                return p
    return None


def read_grey(path: Path) -> NDArray[np.uint8]:
    """An image as 8-bit grey (colour converted, 16-bit scaled).

    Raises:
        InputFileError: Missing, unreadable or not an image.
    """
    data = np.fromfile(str(path), dtype=np.uint8) if path.is_file() else None
    if data is None:
        raise InputFileError(path, "no such image file")
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # our message says it once
    try:
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if img is None:
        raise InputFileError(path, "not a readable image (corrupt or unsupported format)")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype == np.uint16:
        img = (img / 257.0).round().astype(np.uint8)
    elif img.dtype != np.uint8:
        raise InputFileError(path, f"unsupported pixel type {img.dtype} (expected 8 or 16 bit)")
    return np.asarray(img, dtype=np.uint8)


class RecordError(DetectionError):
    """A record's image files are missing or unreadable."""


@dataclass
class ImageMeasurement:
    """What :func:`measure_stereo_images` returns.

    Attributes:
        measurements: The records where at least one plate was measured.
        problems: One line per plate (or record) that was skipped, naming image, plate, reason.
        details: Per record and plate, the detector's :class:`StereoPlatePose`.
    """

    measurements: MeasurementSet
    problems: list[str]
    details: dict[tuple[str, str], StereoPlatePose] = field(default_factory=dict)


def _fail(problem: Cpc2UrdfError, on_error: str, problems: list[str]) -> None:
    if on_error == "stop":
        raise problem
    problems.append(str(problem))


def measure_stereo_images(
    images_dir: str | Path,
    rig: Any,
    structure: RobotStructure,
    *,
    joints: str | Path | None = None,
    designs: Sequence[PlateDesign] | None = None,
    on_error: str = "skip",
    correct_bias: bool = True,
    robot_ref: str | None = None,
    show_progress: bool = False,
) -> ImageMeasurement:
    """Stage-1 measurements from stereo images of the plates.

    Args:
        images_dir: Folder with ``left/`` and ``right/`` images (module docstring).
        rig: A :class:`~cpc2urdf.identification.vision.stereo.StereoRig` (world = left camera).
        structure: The robot (joint names, plate frames and their layouts).
        joints: The ``joints.csv`` (default ``images_dir/joints.csv``).
        designs: Plate designs (default :func:`~cpc2urdf.identification.vision.render.robot_plate_designs`).
        on_error: ``"skip"`` (the plate), ``"skip-record"`` or ``"stop"`` (module docstring).
        correct_bias: Remove the ellipse-centre offset (:mod:`~cpc2urdf.identification.vision.detect`).
        robot_ref: Robot reference for the measurement file.
        show_progress: Progress bar on stderr.

    Raises:
        InputFileError: A missing folder or bad ``joints.csv``; with ``on_error="stop"`` also a
            missing/corrupt image.
        DetectionError: With ``on_error="stop"``, the first plate that could not be measured.
        DegenerateDataError: No plate measured in any record.
    """
    if on_error not in ON_ERROR:
        raise ConfigurationError(f"on_error must be one of {ON_ERROR}, got {on_error!r}")
    root = Path(images_dir)
    if not root.is_dir():
        raise InputFileError(root, "no such images folder")
    for sub in STEREO_FOLDERS:
        if not (root / sub).is_dir():
            raise InputFileError(root, f"missing sub-folder {sub}/ (expected left/<record>.png and right/<record>.png)")
    table = read_joints_csv(joints or root / "joints.csv", structure)
    designs = list(designs or robot_plate_designs(structure.frames))
    if not designs:
        raise ConfigurationError(f"robot {structure.name!r} has no plate frames with a circle layout")
    if tuple(rig.image_size) == (0, 0):
        raise ConfigurationError("the rig has no image size")
    names = [d.name for d in designs]
    N = len(table.records)
    poses = {n: np.full((N, 4, 4), np.nan) for n in names}
    points = {n: np.full((N, d.n_circles, 3), np.nan) for n, d in zip(names, designs, strict=True)}
    fit = {n: np.full(N, np.nan) for n in names}
    problems: list[str] = []
    details: dict[tuple[str, str], StereoPlatePose] = {}
    items = progress(range(N), "measure") if show_progress else range(N)
    for i in items:
        rec = table.records[i]
        imgs = []
        for sub in STEREO_FOLDERS:
            path = find_image(root / sub, rec)
            try:
                if path is None:
                    raise RecordError(f"{sub}/{rec}.*", "all plates", f"no image file (looked for {', '.join(IMAGE_EXTENSIONS)})")
                img = read_grey(path)
                if (img.shape[1], img.shape[0]) != tuple(rig.image_size):
                    raise RecordError(
                        str(path), "all plates",
                        f"image is {img.shape[1]} x {img.shape[0]} px, the rig file says {rig.image_size[0]} x {rig.image_size[1]}",
                    )
                imgs.append((img, str(path)))
            except InputFileError as e:
                _fail(RecordError(e.path, "all plates", e.problem), on_error, problems)
                break
            except RecordError as e:
                _fail(e, on_error, problems)
                break
        if len(imgs) != 2:
            continue
        result = stereo_plate_poses(imgs[0][0], imgs[1][0], rig, designs, names=(imgs[0][1], imgs[1][1]),
                                    correct_bias=correct_bias)
        failed = [r for r in result.values() if isinstance(r, DetectionError)]
        for err in failed:
            _fail(err, on_error, problems)
        if failed and on_error == "skip-record":
            continue
        for n in names:
            r = result[n]
            if isinstance(r, DetectionError):
                continue
            poses[n][i] = r.T_world_plate
            points[n][i] = r.p_world
            fit[n][i] = r.fit_rms
            details[(rec, n)] = r
    keep = np.array([any(np.isfinite(poses[n][i]).all() for n in names) for i in range(N)], dtype=bool)
    if not keep.any():
        raise DegenerateDataError(
            f"{root}: no plate could be measured in any of the {N} records"
            + (f"; first problem: {problems[0]}" if problems else "")
        )
    idx = np.flatnonzero(keep)
    ms = MeasurementSet(
        structure, table.q[idx], {n: poses[n][idx] for n in names}, str(root), robot_ref,
        [table.labels[i] for i in idx], {n: points[n][idx] for n in names}, {n: fit[n][idx] for n in names},
        {
            "description": f"stage-1 measurements of {structure.name} from stereo images in {root}",
            "provenance": {
                "source": "cpc2urdf measure (identification/measure_images.py)",
                "images": str(root),
                "records_in_joints_csv": N,
                "records_measured": int(keep.sum()),
                "ellipse_bias_corrected": bool(correct_bias),
                "plate_designs": {d.name: {"radii_m": d.radii.tolist(), "marker_index": d.marker_index} for d in designs},
                "rig": rig.to_json(),
                "skipped": problems[:200],
            },
        },
    )
    return ImageMeasurement(ms, problems, details)


# ---- stage 2 ---------------------------------------------------------------------------------------


@dataclass
class HeadCamera:
    """A head camera's intrinsics (OpenCV model).

    Attributes:
        K: Camera matrix [px], shape (3, 3).
        D: Distortion coefficients, shape (5,).
        image_size: (width, height) [px].
    """

    K: Array
    D: Array
    image_size: tuple[int, int]


@dataclass
class HeadImageMeasurement:
    """What :func:`measure_head_images` returns.

    Attributes:
        labels: Per camera, the labels of the records used.
        q: Per camera, the joint readings of those records, shape (N_c, n).
        T_camera_target: Per camera, solvePnP target poses, shape (N_c, 4, 4).
        reprojection_rms: Per camera, the RMS reprojection error per record [px], shape (N_c,).
        problems: Skipped images with the reason.
    """

    labels: dict[str, list[str]]
    q: dict[str, Array]
    T_camera_target: dict[str, Array]
    reprojection_rms: dict[str, Array]
    problems: list[str]


def measure_head_images(
    images_dir: str | Path,
    cameras: Mapping[str, HeadCamera],
    structure: RobotStructure,
    *,
    joints: str | Path | None = None,
    design: PlateDesign | None = None,
    on_error: str = "skip",
    correct_bias: bool = True,
    show_progress: bool = False,
) -> HeadImageMeasurement:
    """Stage-2 target poses ``T_camera_target`` from the head cameras' images.

    Args:
        images_dir: Folder with one sub-folder per camera (named like the camera frame) and
            ``joints.csv``.
        cameras: Camera frame name -> intrinsics.
        structure: The robot (for the joint columns).
        joints: The ``joints.csv`` (default ``images_dir/joints.csv``).
        design: The target (default :func:`~cpc2urdf.identification.vision.render.target_design`).
        on_error: ``"skip"``/``"skip-record"`` (the image) or ``"stop"``.
        correct_bias: Remove the ellipse-centre offset before the final solvePnP.
        show_progress: Progress bar on stderr.

    Raises:
        InputFileError, DetectionError, DegenerateDataError: as :func:`measure_stereo_images`.
    """
    if on_error not in ON_ERROR:
        raise ConfigurationError(f"on_error must be one of {ON_ERROR}, got {on_error!r}")
    root = Path(images_dir)
    if not root.is_dir():
        raise InputFileError(root, "no such images folder")
    if not cameras:
        raise ConfigurationError("no head camera given")
    for c in cameras:
        if not (root / c).is_dir():
            raise InputFileError(root, f"missing sub-folder {c}/ for camera {c}")
    table = read_joints_csv(joints or root / "joints.csv", structure)
    design = design or target_design()
    problems: list[str] = []
    out_l: dict[str, list[str]] = {c: [] for c in cameras}
    out_q: dict[str, list[Array]] = {c: [] for c in cameras}
    out_T: dict[str, list[Array]] = {c: [] for c in cameras}
    out_r: dict[str, list[float]] = {c: [] for c in cameras}
    jobs = [(i, c) for i in range(len(table.records)) for c in cameras]
    for i, c in progress(jobs, "measure") if show_progress else jobs:
        rec = table.records[i]
        cam = cameras[c]
        path = find_image(root / c, rec)
        try:
            if path is None:
                raise RecordError(f"{c}/{rec}.*", design.name, "no image file")
            img = read_grey(path)
        except InputFileError as e:
            _fail(RecordError(e.path, design.name, e.problem), on_error, problems)
            continue
        except RecordError as e:
            _fail(e, on_error, problems)
            continue
        if (img.shape[1], img.shape[0]) != tuple(cam.image_size):
            _fail(RecordError(str(path), design.name, f"image is {img.shape[1]} x {img.shape[0]} px, the camera file says "
                              f"{cam.image_size[0]} x {cam.image_size[1]}"), on_error, problems)
            continue
        r = target_pose(img, cam.K, cam.D, design, image_name=str(path), correct_bias=correct_bias)
        if isinstance(r, DetectionError):
            _fail(r, on_error, problems)
            continue
        out_l[c].append(table.labels[i])
        out_q[c].append(table.q[i])
        out_T[c].append(r.T_camera_target)
        out_r[c].append(r.reprojection_rms)
    for c in cameras:
        if len(out_T[c]) < 3:
            raise DegenerateDataError(
                f"{root}: camera {c} saw the target in {len(out_T[c])} records; hand-eye calibration needs at least 3"
                + (f"; first problem: {problems[0]}" if problems else "")
            )
    return HeadImageMeasurement(
        out_l, {c: np.array(v) for c, v in out_q.items()}, {c: np.array(v) for c, v in out_T.items()},
        {c: np.array(v) for c, v in out_r.items()}, problems,
    )


def stage2_observations(result: HeadImageMeasurement, cameras: Mapping[str, HeadCamera]) -> Any:
    """The records every camera measured, as :class:`cpc2urdf.identification.handeye.stage2.Stage2Observations`
    (for :func:`~cpc2urdf.identification.handeye.stage2.calibrate_cameras`, which puts the cameras into
    the model). ``T_base_target`` is unknown from images and left as NaN; ``image_points`` empty.

    Raises:
        DegenerateDataError: Fewer than 3 records seen by every camera.
    """
    from cpc2urdf.identification.handeye.stage2 import CameraIntrinsics, Stage2Observations

    names = list(result.T_camera_target)
    common = [lab for lab in result.labels[names[0]] if all(lab in result.labels[c] for c in names)]
    if len(common) < 3:
        raise DegenerateDataError(f"only {len(common)} records were measured by every camera ({', '.join(names)}); need 3")
    idx = {c: [result.labels[c].index(lab) for lab in common] for c in names}
    cam = cameras[names[0]]
    intr = CameraIntrinsics(float(cam.K[0, 0]), float(cam.K[1, 1]), float(cam.K[0, 2]), float(cam.K[1, 2]),
                            int(cam.image_size[0]), int(cam.image_size[1]), tuple(float(v) for v in cam.D))
    return Stage2Observations(
        result.q[names[0]][idx[names[0]]], {c: result.T_camera_target[c][idx[c]] for c in names}, {}, intr,
        float("nan"), np.full((4, 4), np.nan),
    )


def write_handeye_files(
    result: HeadImageMeasurement, model: CPCModel, folder: str | Path, *, hands: Mapping[str, str] | None = None
) -> dict[str, Path]:
    """One ``cpc2urdf/handeye-poses@1`` file per camera (``handeye_<camera>.json``, mm/deg), with
    ``T_base_hand`` of the camera's hand frame from ``model`` at the records' readings."""
    from cpc2urdf.identification.handeye.pose_file import save_handeye_poses
    from cpc2urdf.identification.handeye.stage2 import HAND_OF_CAMERA
    from cpc2urdf.transforms import inverse
    from cpc2urdf.units import Units

    hands = dict(hands or HAND_OF_CAMERA)
    out_dir = Path(folder)
    if not out_dir.is_dir():
        raise OutputError(f"{out_dir}: output folder does not exist")
    paths = {}
    for c, C in result.T_camera_target.items():
        if c not in hands:
            raise ConfigurationError(f"no hand frame known for camera {c!r}; known: {sorted(hands)}")
        hand = hands[c]
        model.structure.frame(hand)
        T_base_hand = inverse(model.T_world_base())[None] @ model.fk_frame(hand, result.q[c])
        paths[c] = save_handeye_poses(
            out_dir / f"handeye_{c}.json", T_base_hand, C, labels=result.labels[c], camera=c, hand=hand,
            units=Units("mm", "deg"),
            description=f"stage-2 target poses from images ({len(C)} records), hand poses from the identified model",
        )
    return paths


# ---- rendering whole experiments ---------------------------------------------------------------------


@dataclass
class RenderedExperiment:
    """What :func:`render_experiment` wrote and simulated.

    Attributes:
        folder: The images folder.
        truth: The true robot (placed in the rig's world).
        measured: The exact (noise-free) plate poses of the rendered records.
        heldout: Held-out configurations with true poses.
        rig: The rig.
        paths: Written files by role (``rig``, ``joints``, ``truth``, ``heldout``, ``exact``).
        hidden: Per record, the number of circles hidden (occluded/at the border) in either image.
    """

    folder: Path
    truth: CPCModel
    measured: MeasurementSet
    heldout: MeasurementSet
    rig: Any
    paths: dict[str, Path]
    hidden: list[int]


def clear_placement(spec: Any, rig: Any, q: Array, designs: Sequence[PlateDesign]) -> Any:
    """A ``world_to_base`` (CPC constants) that shows both cameras every circle of every plate.

    The simulator's search (:func:`cpc2urdf.identification.simulation.simulate.clear_placement`) for the
    nominal robot of ``spec`` over configurations ``q`` (N, n) with the plate outlines of
    ``designs``; raises ``ConfigurationError`` when no candidate keeps every plate in view.
    """
    from cpc2urdf.identification.simulation.simulate import check_view
    from cpc2urdf.identification.simulation.simulate import clear_placement as search

    nominal = spec.nominal_model()
    frames = [d.name for d in designs]
    w2b = search(nominal, rig, q, frames, designs=designs)
    view = check_view(nominal.with_params(world_to_base=w2b), rig, q, frames, [str(i) for i in range(len(q))],
                      designs=designs)
    if view.unseen:
        raise ConfigurationError("no placement of the robot lets both rig cameras see every plate")
    return w2b


def render_experiment(
    folder: str | Path,
    robot: str = "iis_head",
    *,
    seed: int = 0,
    M: int = 9,
    n_heldout: int = 50,
    rig: Any = None,
    blur_sigma: float = 0.7,
    noise_sigma: float = 2.0,
    supersample: int = 8,
    show_progress: bool = False,
) -> RenderedExperiment:
    """Simulate a stage-1 experiment and write it as images (the input of ``cpc2urdf measure``).

    Writes ``folder/left/<record>.png``, ``folder/right/<record>.png``, ``folder/joints.csv``
    (mm/deg), ``folder/rig.yaml`` (mm), and for scoring ``folder/truth.json`` (the true model),
    ``folder/heldout.json`` and ``folder/exact.json`` (the true poses of the rendered records).

    Args:
        folder: Output folder (created if missing; its parent must exist).
        robot: Shipped robot name or spec path.
        seed: Seed of the true robot's geometric errors and of the image noise.
        M: Values per joint (one-joint-at-a-time protocol, n M + 1 records).
        n_heldout: Held-out configurations (true poses, not rendered).
        rig: The stereo rig (default the paper's: 600 mm baseline, 1.5 m).
        blur_sigma: Optical blur [px].
        noise_sigma: Grey-level noise [of 255].
        supersample: Anti-aliasing sub-samples per axis.
        show_progress: Progress bar on stderr.
    """
    from cpc2urdf.identification.simulation.simulate import (
        simulate_experiment,
    )
    from cpc2urdf.identification.vision.render import (
        PinholeView,
        hidden_circles,
        render_view,
        write_image,
    )
    from cpc2urdf.identification.vision.rig_file import save_rig
    from cpc2urdf.identification.vision.stereo import StereoRig
    from cpc2urdf.measurements import save_measurements
    from cpc2urdf.model_file import save_model
    from cpc2urdf.robot_ref import load_robot

    out = Path(folder)
    if not out.parent.is_dir():
        raise OutputError(f"{out}: parent folder {out.parent} does not exist")
    spec = load_robot(robot)
    s = spec.structure
    rig = rig or StereoRig.verged()
    designs = robot_plate_designs(s.frames)
    # The simulator's default placement: no circle hidden over the protocol and the held-out box.
    truth, exact, heldout = simulate_experiment(spec, seed=seed, M=M, noise="none", n_heldout=n_heldout, rig=rig,
                                                robot_ref=robot)
    for sub in STEREO_FOLDERS:
        (out / sub).mkdir(parents=True, exist_ok=True)
    views = [PinholeView(rig.K1, rig.D1, rig.image_size, np.linalg.inv(rig.T_world_camera(w))) for w in STEREO_FOLDERS]
    fk = truth.fk(exact.q, [d.name for d in designs])
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(4)[3])
    records = [f"{i:04d}" for i in range(exact.n_records)]
    hidden = []
    items = progress(range(exact.n_records), "render") if show_progress else range(exact.n_records)
    for i in items:
        plates = [(d, fk[d.name][i]) for d in designs]
        hidden.append(sum(sum(hidden_circles(v, plates).values()) for v in views))
        for sub, v in zip(STEREO_FOLDERS, views, strict=True):
            img = render_view(v, plates, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng, supersample=supersample)
            write_image(out / sub / f"{records[i]}.png", img)
    paths = {
        "joints": write_joints_csv(out / "joints.csv", s, records, exact.q, exact.labels),
        "rig": save_rig(rig, out / "rig.yaml", units="mm"),
        "truth": save_model(truth, out / "truth.json"),
        "heldout": save_measurements(heldout, out / "heldout.json"),
        "exact": save_measurements(exact, out / "exact.json"),
    }
    return RenderedExperiment(out, truth, exact, heldout, rig, paths, hidden)


def render_head_experiment(
    folder: str | Path,
    truth: CPCModel,
    *,
    n_poses: int = 12,
    seed: int = 0,
    intrinsics: Any = None,
    blur_sigma: float = 0.7,
    noise_sigma: float = 2.0,
) -> dict[str, Path]:
    """Simulate stage 2 and write it as images: the head's cameras (their frames in ``truth``)
    photograph the 25-disk target from ``n_poses`` random configurations.

    Writes ``folder/<camera>/<record>.png`` for both camera frames, ``folder/joints.csv``,
    ``folder/<camera>.yaml`` (intrinsics, OpenCV FileStorage) and ``folder/target_truth.json``
    (the true ``T_base_target``).

    Returns:
        Written files by role.
    """
    from cpc2urdf.fileio import write_json
    from cpc2urdf.identification.handeye import stage2
    from cpc2urdf.identification.vision.render import PinholeView, render_view, write_image
    from cpc2urdf.identification.vision.rig_file import save_camera
    from cpc2urdf.transforms import inverse

    out = Path(folder)
    if not out.parent.is_dir():
        raise OutputError(f"{out}: parent folder {out.parent} does not exist")
    intr = intrinsics or stage2.DEFAULT_INTRINSICS
    cameras = list(stage2.HAND_OF_CAMERA)
    rng = np.random.default_rng(seed)
    T_base_target = stage2.default_target_placement(truth, cameras)
    q = stage2.sample_configurations(truth, n_poses, rng, T_base_target, cameras=cameras, intrinsics=intr)
    design = target_design()
    T_world_target = truth.T_world_base() @ T_base_target
    records = [f"{i:04d}" for i in range(len(q))]
    paths: dict[str, Path] = {}
    for c in cameras:
        (out / c).mkdir(parents=True, exist_ok=True)
        paths[c] = save_camera(intr.K, intr.D, (intr.width, intr.height), out / f"{c}.yaml")
        T_world_cam = truth.fk_frame(c, q)
        for i, rec in enumerate(records):
            view = PinholeView(intr.K, intr.D, (intr.width, intr.height), inverse(T_world_cam[i]))
            img = render_view(view, [(design, T_world_target)], blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)
            write_image(out / c / f"{rec}.png", img)
    paths["joints"] = write_joints_csv(out / "joints.csv", truth.structure, records, q)
    paths["target_truth"] = write_json(out / "target_truth.json", {
        "description": "true pose of the stage-2 target in the robot base frame (for scoring)",
        "T_base_target": T_base_target.tolist(), "units": {"length": "m"}})
    return paths


__all__ = [
    "HeadCamera",
    "HeadImageMeasurement",
    "ImageMeasurement",
    "JointTable",
    "RecordError",
    "RenderedExperiment",
    "clear_placement",
    "measure_head_images",
    "measure_stereo_images",
    "read_joints_csv",
    "render_experiment",
    "render_head_experiment",
    "stage2_observations",
    "write_handeye_files",
    "write_joints_csv",
]
