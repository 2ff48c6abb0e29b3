"""Stage-1 measurements from images: stereo images of the plates -> a measurement set.

A calibrated stereo rig photographs the head's plates at every configuration (Shih et al.
sec. 3). The folder layout (``docs/images.md``)::

    IMAGES_DIR/
      left/<record>.png      # left rig camera (world frame), any format OpenCV reads
      right/<record>.png     # right rig camera
      joints.csv             # one row per record: record,<joint>[unit],...

:func:`measure_stereo_images` reads the joint readings
(:mod:`~cpc2urdf.identification.vision.joints_csv`), detects the plates in each pair,
triangulates and registers them (:mod:`~cpc2urdf.identification.vision.plate_poses`) and returns
a :class:`~cpc2urdf.files.measurements.MeasurementSet` with ``T_world_<plate>`` and the triangulated
circle centres (``points``). A plate that cannot be measured is handled by the ``on_error``
policy of :mod:`~cpc2urdf.identification.vision.image_folders`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from cpc2urdf.errors import ConfigurationError, DegenerateDataError, InputFileError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.boards.board_poses import stereo_board_pose
from cpc2urdf.identification.vision.detect import DetectionError
from cpc2urdf.identification.vision.image_folders import (
    IMAGE_EXTENSIONS,
    RecordError,
    check_on_error,
    find_image,
    read_grey,
    report_problem,
)
from cpc2urdf.identification.vision.joints_csv import read_joints_csv
from cpc2urdf.identification.vision.plate_poses import StereoPlatePose, stereo_plate_poses
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.identification.vision.targets import PlateDesign, robot_plate_designs
from cpc2urdf.model import RobotStructure
from cpc2urdf.progress import progress_checked

STEREO_FOLDERS = ("left", "right")


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


def measure_stereo_images(
    images_dir: str | Path,
    rig: StereoRig,
    structure: RobotStructure,
    *,
    joints: str | Path | None = None,
    designs: Sequence[PlateDesign] | None = None,
    boards: Mapping[str, Board] | None = None,
    on_error: str = "skip",
    correct_bias: bool = True,
    robot_ref: str | None = None,
    show_progress: bool = False,
    joint_aliases: Mapping[str, str] | None = None,
) -> ImageMeasurement:
    """Stage-1 measurements from stereo images of the plates.

    Args:
        images_dir: Folder with ``left/`` and ``right/`` images (module docstring).
        rig: A :class:`~cpc2urdf.identification.vision.stereo.StereoRig` (world = left camera).
        structure: The robot (joint names, plate frames and their layouts).
        joints: The ``joints.csv`` (default ``images_dir/joints.csv``).
        designs: Plate designs (default :func:`~cpc2urdf.identification.vision.targets.robot_plate_designs`).
        boards: Standard boards as the plates instead: plate frame -> board
            (:func:`check_plate_boards`); each is measured by
            :func:`~cpc2urdf.identification.vision.boards.board_poses.stereo_board_pose` (the corners both
            cameras see, triangulated, and the board registered to them). The measurement file then
            has no ``points`` (they are the board's corners, not the spec's layout).
        on_error: ``"skip"`` (the plate), ``"skip-record"`` or ``"stop"`` (module docstring).
        correct_bias: Remove the ellipse-centre offset (:mod:`~cpc2urdf.identification.vision.plate_poses`).
        robot_ref: Robot reference for the measurement file.
        show_progress: Progress bar on stderr.
        joint_aliases: Other names of the joint columns (a URDF's own joint names,
            :func:`~cpc2urdf.identification.vision.joints_csv.urdf_joint_columns`).

    Raises:
        InputFileError: A missing folder or bad ``joints.csv``; with ``on_error="stop"`` also a
            missing/corrupt image.
        DetectionError: With ``on_error="stop"``, the first plate that could not be measured.
        DegenerateDataError: No plate measured in any record.
    """
    check_on_error(on_error)
    root = Path(images_dir)
    _check_images_dir(root)
    table = read_joints_csv(joints or root / "joints.csv", structure, aliases=joint_aliases)
    plate_boards = check_plate_boards(boards, structure) if boards else None
    designs = [] if plate_boards else list(designs or robot_plate_designs(structure.frames))
    if not designs and not plate_boards:
        raise ConfigurationError(
            f"robot {structure.name!r} has no plate frames with a circle layout"
        )
    if tuple(rig.image_size) == (0, 0):
        raise ConfigurationError("the rig has no image size")
    names = list(plate_boards) if plate_boards else [d.name for d in designs]
    N = len(table.records)
    poses = {n: np.full((N, 4, 4), np.nan) for n in names}
    points = {d.name: np.full((N, d.n_circles, 3), np.nan) for d in designs}
    fit = {n: np.full(N, np.nan) for n in names}
    problems: list[str] = []
    details: dict[tuple[str, str], StereoPlatePose] = {}
    # The bar's "done" line only once the records are known to be usable (progress_checked).
    with progress_checked(range(N), "measure", show_progress) as bar:
        for i in bar:
            rec = table.records[i]
            imgs = _read_pair(root, rec, rig, on_error, problems)
            if len(imgs) != 2:
                continue
            result = _measure_pair(imgs, rig, designs, plate_boards, correct_bias)
            failed = [r for r in result.values() if isinstance(r, DetectionError)]
            for err in failed:
                report_problem(err, on_error, problems)
            if failed and on_error == "skip-record":
                continue
            for n in names:
                r = result[n]
                if isinstance(r, DetectionError):
                    continue
                poses[n][i] = r.T_world_plate
                if n in points:
                    points[n][i] = r.p_world
                fit[n][i] = r.fit_rms
                details[(rec, n)] = r
        keep = np.array(
            [any(np.isfinite(poses[n][i]).all() for n in names) for i in range(N)], dtype=bool
        )
        if not keep.any():
            raise DegenerateDataError(
                f"{root}: no plate could be measured in any of the {N} records"
                + (f"; first problem: {problems[0]}" if problems else "")
            )
    idx = np.flatnonzero(keep)
    ms = MeasurementSet(
        structure,
        table.q[idx],
        {n: poses[n][idx] for n in names},
        str(root),
        robot_ref,
        [table.labels[i] for i in idx],
        {n: p[idx] for n, p in points.items()},
        {n: fit[n][idx] for n in names},
        {
            "description": f"stage-1 measurements of {structure.name} from stereo images in {root}",
            "provenance": _provenance(
                root, N, int(keep.sum()), correct_bias, designs, plate_boards, rig, problems
            ),
        },
    )
    return ImageMeasurement(ms, problems, details)


def _check_images_dir(root: Path) -> None:
    """Refuse an images folder that is missing or lacks a ``left/`` or ``right/`` sub-folder."""
    if not root.is_dir():
        raise InputFileError(root, "no such images folder")
    for sub in STEREO_FOLDERS:
        if not (root / sub).is_dir():
            raise InputFileError(
                root,
                f"missing sub-folder {sub}/ (expected left/<record>.png and right/<record>.png)",
            )


def _read_pair(
    root: Path, rec: str, rig: StereoRig, on_error: str, problems: list[str]
) -> list[tuple[np.ndarray, str]]:
    """Record ``rec``'s left and right images (grey image, path); fewer than two when an image
    is missing, unreadable or not the rig's size (reported by the ``on_error`` policy)."""
    imgs = []
    for sub in STEREO_FOLDERS:
        path = find_image(root / sub, rec)
        try:
            if path is None:
                raise RecordError(
                    f"{sub}/{rec}.*",
                    "all plates",
                    f"no image file (looked for {', '.join(IMAGE_EXTENSIONS)})",
                )
            img = read_grey(path)
            if (img.shape[1], img.shape[0]) != tuple(rig.image_size):
                raise RecordError(
                    str(path),
                    "all plates",
                    f"image is {img.shape[1]} x {img.shape[0]} px, the rig file says {rig.image_size[0]} x {rig.image_size[1]}",
                )
            imgs.append((img, str(path)))
        except InputFileError as e:
            report_problem(RecordError(e.path, "all plates", e.problem), on_error, problems)
            break
        except RecordError as e:
            report_problem(e, on_error, problems)
            break
    return imgs


def _measure_pair(
    imgs: list[tuple[np.ndarray, str]],
    rig: StereoRig,
    designs: list[PlateDesign],
    plate_boards: dict[str, Board] | None,
    correct_bias: bool,
) -> dict[str, StereoPlatePose | DetectionError]:
    """Each plate's pose (or why not) in one stereo pair: the boards if given, else the circle
    plates of ``designs``."""
    if plate_boards:
        return {
            n: stereo_board_pose(imgs[0][0], imgs[1][0], rig, b, names=(imgs[0][1], imgs[1][1]))
            for n, b in plate_boards.items()
        }
    return stereo_plate_poses(
        imgs[0][0],
        imgs[1][0],
        rig,
        designs,
        names=(imgs[0][1], imgs[1][1]),
        correct_bias=correct_bias,
    )


def _provenance(
    root: Path,
    n_records: int,
    n_measured: int,
    correct_bias: bool,
    designs: list[PlateDesign],
    plate_boards: dict[str, Board] | None,
    rig: StereoRig,
    problems: list[str],
) -> dict[str, object]:
    """The measurement file's ``provenance`` section: images, counts, plates, rig, skips."""
    return {
        "source": "cpc2urdf measure (identification/measure_images.py)",
        "images": str(root),
        "records_in_joints_csv": n_records,
        "records_measured": n_measured,
        "ellipse_bias_corrected": bool(correct_bias),
        "plate_designs": {
            d.name: {"radii_m": d.radii.tolist(), "marker_index": d.marker_index} for d in designs
        },
        **(
            {"plate_boards": {n: b.to_json() for n, b in plate_boards.items()}}
            if plate_boards
            else {}
        ),
        "rig": rig.to_json(),
        "skipped": problems[:200],
    }


def dictionary_family(name: str) -> str:
    """The marker family of an OpenCV ArUco dictionary name: ``DICT_4X4`` for ``DICT_4X4_50``,
    ``DICT_4X4_100``, ... (their markers are prefixes of one list, so equal ids are equal
    markers); any other name is its own family."""
    m = re.fullmatch(r"(DICT_\d+X\d+)_\d+", name)
    return m.group(1) if m else name


def check_plate_boards(boards: Mapping[str, Board], structure: RobotStructure) -> dict[str, Board]:
    """Boards as stage-1 plates: plate frame -> board, each named after its frame.

    Raises:
        ConfigurationError: A frame the robot does not have; a board without a unique pose
            (:attr:`Board.pose_ambiguity`); several boards that the detector cannot tell apart
            (two boards in one image must be ChArUco boards with disjoint marker ids).
    """
    known = [f.name for f in structure.frames]
    out: dict[str, Board] = {}
    for frame, b in boards.items():
        if frame not in known:
            raise ConfigurationError(
                f"board {b.name}: robot {structure.name!r} has no frame {frame!r} (frames: {', '.join(known)})"
            )
        if b.pose_ambiguity:
            raise ConfigurationError(
                f"board {b.name} for {frame}: {b.pose_ambiguity}, so it gives no unique plate pose"
            )
        out[frame] = replace(b, name=frame)
    if len(out) > 1:
        items = list(boards.values())
        if any(b.kind != "charuco" for b in items):
            raise ConfigurationError(
                "several plates need boards the detector can tell apart in one image: ChArUco boards "
                "with disjoint marker ids (first_marker_id); chessboards and circle grids all look alike"
            )
        # OpenCV's DICT_NxN_50/100/250/1000 share their first markers (the smaller is a prefix of
        # the larger): ids overlap within a marker size, whatever the dictionary's length
        spans = sorted(
            (
                dictionary_family(b.dictionary),
                b.first_marker_id,
                b.first_marker_id + b.n_markers,
                b.name,
                b.dictionary,
            )
            for b in items
        )
        for a, c in zip(spans, spans[1:], strict=False):
            if a[0] == c[0] and c[1] < a[2]:
                same = a[4] if a[4] == c[4] else f"{a[4]} and {c[4]}"
                raise ConfigurationError(
                    f"boards {a[3]} and {c[3]} share marker ids of {same} ({c[1]}..{min(a[2], c[2]) - 1}); "
                    "give each plate's board its own first_marker_id"
                )
    return out


__all__ = [
    "STEREO_FOLDERS",
    "ImageMeasurement",
    "check_plate_boards",
    "dictionary_family",
    "measure_stereo_images",
]
