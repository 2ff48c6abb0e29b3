"""``cpc2urdf identify measurements.json -o model.json``: identify a robot's CPC model.

Reads stage-1 measurements: frame poses (``cpc2urdf/measurements@1``) or marker points
(``cpc2urdf/measurements@2``), or a tracker CSV export (``identify tracker.csv --robot R --marker
m0=LINK ...``, read by :func:`cpc2urdf.files.marker_csv.load_marker_csv`, docs/measurements.md sec. 1b),
at any configurations. It runs an identification method
(``--method``, default ``refined``: the closed form of Shih et al. sec. 4.2, then maximum-likelihood
refinement of every record, which reaches the Cramér-Rao bound (docs/refinement.md); the registry is
:data:`cpc2urdf.identification.kinematics.methods.METHODS`) and writes a model file with the sections
``provenance`` (method, data used, the start the refinement used, the consistency gate's verdict),
``residuals`` (per record and per branch or marker) and ``notes``.

Data that cannot determine the robot (a joint never moved, too few distinct configurations, copied
records), or that are inconsistent with the fit (residuals far above or below the file's stated
noise, an implausible robot size, gross outliers; the cause is diagnosed by refitting the likely
mistakes), are refused: one line on stderr, exit code 2, no file. ``--accept-inconsistent`` keeps
the model of inconsistent data with the diagnosis in its notes and provenance (docs/identification.md).
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cpc2urdf.files.measurements import MeasurementSet


NOT_BETTER_EXIT = (
    3  # --method map: no calibration predicts better than the URDF as it is (model still written)
)


def _add_image_options(p: argparse.ArgumentParser) -> None:
    """The options of a folder of the head's own images (the one-stage calibration)."""
    img = p.add_argument_group(
        "the head's own images (measurements: a folder <camera link>/<record>.png, "
        "<camera link>.yaml, joints.csv, board.json; one-stage fit on the board's corners)"
    )
    img.add_argument(
        "--cameras",
        nargs="+",
        metavar="LINK",
        help="the URDF's camera links (LINK:optical / LINK:body where the file cannot tell)",
    )
    img.add_argument(
        "--board", metavar="FILE", help="the board file (default: the folder's board.json)"
    )
    img.add_argument(
        "--board-link",
        metavar="LINK",
        help="the URDF link holding the board (a gripper): arm and head calibrated together; "
        "default: the board is fixed in the world",
    )
    img.add_argument(
        "--intrinsics", action="store_true", help="refine the cameras' fx, fy, cx, cy, k1, k2 too"
    )


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from cpc2urdf.files.units import ANGLE_UNITS, LENGTH_UNITS
    from cpc2urdf.identification.kinematics.methods import DEFAULT_METHOD, METHODS

    p = subparsers.add_parser(
        "identify",
        help="identify the CPC model from measured frame poses or marker points",
        description="Identify every CPC parameter of the robot from stage-1 measurements (plate "
        "poses or marker points with joint readings, at any configurations; moving one joint at a "
        "time from q0 lets the closed form start the refinement, otherwise it starts from the "
        "nominal model) and write a model file for 'cpc2urdf export'. Unmeasured frames (cameras) "
        "keep their nominal placement relative to a measured plate on the same link, or are dropped "
        "if the robot has no nominal geometry. A tracker CSV export (.csv) needs --robot and --marker.",
    )
    p.add_argument(
        "measurements",
        help="measurement file: cpc2urdf/measurements@1 (poses) or @2 (markers), "
        "or a tracker CSV export (.csv: config,marker,x,y,z[,joints...])",
    )
    p.add_argument("-o", "--output", required=True, help="model file to write (atomically)")
    p.add_argument(
        "--method",
        choices=sorted(METHODS),
        default=None,
        help=f"identification method (default {DEFAULT_METHOD}: closed form + maximum-likelihood "
        "refinement with covariance; closed-form: Shih et al. sec. 4.2 only; map: maximum a posteriori "
        "about the URDF, the model chosen by cross-validation, the default for a FIGAROH CSV; exit "
        "code 3 when no calibration predicts better than the URDF as it is)",
    )
    p.add_argument(
        "--robot",
        help="robot spec/model file, URDF or shipped name, instead of the file's 'robot' "
        "(required for a .csv)",
    )
    p.add_argument(
        "--joints",
        metavar="J1,J2,...",
        help="--method map: the joints to calibrate (URDF names); "
        "every other joint keeps the URDF's values (default: those the data move on the paths to the "
        "measured links)",
    )
    p.add_argument(
        "--level",
        choices=("frames", "offsets", "geometry", "compliance"),
        help="--method map: fit this level alone instead of choosing one by cross-validation",
    )
    p.add_argument(
        "--noise",
        metavar="MM[,DEG]",
        help="the measurements' noise, one standard deviation: of each "
        "position coordinate in mm (and, for frame poses, of the orientation error's angle in deg, as "
        "simulate's Fig. 10 noise); default: the file's "
        "noise section, else estimated from the data (map) or 0.5 mm / 0.5 deg with the a-posteriori "
        "scale (refined)",
    )
    p.add_argument(
        "--accept-inconsistent",
        action="store_true",
        help="keep the model even when the data are inconsistent with it (a fit far from the file's "
        "stated noise, an implausible size, gross outliers); the diagnosis is stored in the model's "
        "notes and provenance",
    )
    _add_image_options(p)
    csv = p.add_argument_group("tracker CSV export or FIGAROH CSV (measurements ending in .csv)")
    csv.add_argument(
        "--link",
        help="FIGAROH CSV (a row per posture: x1,y1,z1[,phix1,phiy1,phiz1] ... and the "
        "URDF's joints): the URDF link the measured points ride on",
    )
    csv.add_argument(
        "--marker",
        action="append",
        default=[],
        metavar="NAME=LINK",
        help="the link (a spec frame or URDF link) marker NAME is fixed to (repeat for each marker)",
    )
    csv.add_argument(
        "--joints-csv",
        metavar="FILE",
        help="joint readings config,<joint>,... when the points file has no joint columns",
    )
    csv.add_argument(
        "--units-length",
        choices=sorted(LENGTH_UNITS),
        help="length unit of the CSV if its '# units:' header does not say (default m)",
    )
    csv.add_argument(
        "--units-angle",
        choices=sorted(ANGLE_UNITS),
        help="angle unit of the CSV if its '# units:' header does not say (default rad)",
    )
    p.set_defaults(run=run)


def _noise(text: str, poses: bool) -> dict[str, float | str]:
    """``--noise MM[,DEG]`` as a measurement set's ``noise`` section (SI); ``poses``: the data are
    frame poses, whose orientation noise must then be given too."""
    import math

    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.identification.kinematics.problem import DEFAULT_SIGMA_R

    parts = text.split(",")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        values = []
    if len(parts) > 2 or not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise ConfigurationError(
            f"--noise {text!r}: expected MM or MM,DEG (positive numbers: position noise "
            "in mm, orientation noise in deg)"
        )
    if poses and len(values) == 1:
        raise ConfigurationError(
            f"--noise {text!r}: the data are frame poses; give their orientation noise too (MM,DEG)"
        )
    sigma_r = (
        math.radians(values[1]) if len(values) == 2 else DEFAULT_SIGMA_R
    )  # unused by marker points
    return {"model": "stated", "sigma_t_m": values[0] * 1e-3, "sigma_r_rad": sigma_r}


def _markers(items: list[str]) -> dict[str, str]:
    """``--marker NAME=LINK`` values: marker name -> link."""
    from cpc2urdf.errors import ConfigurationError

    out: dict[str, str] = {}
    for item in items:
        name, sep, link = (t.strip() for t in item.partition("="))
        if not sep or not name or not link:
            raise ConfigurationError(
                f"--marker {item!r}: expected NAME=LINK (the link the marker is fixed to)"
            )
        if name in out:
            raise ConfigurationError(
                f"--marker {name!r} is given twice ({out[name]!r} and {link!r})"
            )
        out[name] = link
    return out


def _read(args: argparse.Namespace) -> MeasurementSet:
    """The measurement set: a measurement file, or a tracker CSV export with ``--robot`` and ``--marker``."""
    from cpc2urdf.api import load_measurements, load_robot
    from cpc2urdf.errors import ConfigurationError

    csv_only = {
        "--marker": args.marker,
        "--joints-csv": args.joints_csv,
        "--link": args.link,
        "--units-length": args.units_length,
        "--units-angle": args.units_angle,
    }
    if not str(args.measurements).lower().endswith(".csv"):
        given = [k for k, v in csv_only.items() if v]
        if given:
            raise ConfigurationError(
                f"{given[0]} applies to a tracker CSV export (.csv); "
                f"{args.measurements} is a measurement file"
            )
        return load_measurements(
            args.measurements, robot=load_robot(args.robot) if args.robot else None
        )
    from cpc2urdf.files.marker_csv import load_marker_csv

    if args.link:
        from cpc2urdf.files.figaroh_csv import load_figaroh_csv
        from cpc2urdf.urdf.robot import UrdfRobot

        robot = load_robot(args.robot) if args.robot else None
        if not isinstance(robot, UrdfRobot):
            raise ConfigurationError(
                f"{args.measurements}: a FIGAROH CSV needs --robot ROBOT.urdf (the URDF it was "
                "recorded against)"
            )
        if args.marker:
            raise ConfigurationError(
                "--marker applies to a tracker export; a FIGAROH CSV names its points x1, y1, z1 ..."
            )
        return load_figaroh_csv(args.measurements, robot, args.link, robot_ref=args.robot)
    if not args.robot:
        raise ConfigurationError(
            f"{args.measurements}: a tracker CSV export needs --robot (the robot the markers are on)"
        )
    if not args.marker:
        raise ConfigurationError(
            f"{args.measurements}: a tracker CSV export needs --marker NAME=LINK for each marker "
            "(the export does not say which link a marker is on)"
        )
    return load_marker_csv(
        args.measurements,
        load_robot(args.robot),
        _markers(args.marker),
        robot_ref=args.robot,
        joints_csv=args.joints_csv,
        length=args.units_length,
        angle=args.units_angle,
    )


def _run_images(args: argparse.Namespace) -> int:
    """``identify IMAGES_DIR --robot ROBOT.urdf --cameras LINK ...``: the one-stage calibration."""
    from cpc2urdf.api import calibrate_head, save_model
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.robot_ref import is_urdf_ref

    if not args.robot or not is_urdf_ref(args.robot) or not args.cameras:
        raise ConfigurationError(
            f"{args.measurements}: is a folder; a folder of the head's own images needs --robot "
            "ROBOT.urdf and --cameras LINK ... (the camera links the images come from)"
        )
    for option in ("method", "level", "joints", "noise", "link", "joints_csv"):
        if getattr(args, option):
            raise ConfigurationError(
                f"--{option.replace('_', '-')} does not apply to a folder of images"
            )
    model = calibrate_head(
        args.measurements,
        args.robot,
        args.cameras,
        board=args.board,
        board_link=args.board_link,
        intrinsics=args.intrinsics,
        accept_inconsistent=args.accept_inconsistent,
        show_progress=True,
    )
    path = save_model(model, args.output)
    prov = model.metadata.provenance
    assert prov is not None
    d = prov.details
    noise = ", ".join(f"{c} {s:.3f} px" for c, s in d["pixel_noise_px"].items())
    print(
        f"wrote {path}: one-stage calibration of {model.structure.name!r} from {d['images']} images, "
        f"{d['corners']} corners in {d['seconds']:.1f} s; corner noise {noise}"
    )
    print(f"  start: {d['start']}")
    for note in model.metadata.notes:
        print(f"  note: {note}")
    return 0


def run(args: argparse.Namespace) -> int:
    import math
    import time
    from pathlib import Path

    from cpc2urdf.api import identify, save_model
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import check_output_path
    from cpc2urdf.identification.kinematics.methods import DEFAULT_METHOD
    from cpc2urdf.model_metadata import Provenance

    check_output_path(args.output)  # a bad -o is refused before the identification, not after it
    images = ("--cameras", args.cameras), ("--board", args.board), ("--board-link", args.board_link)
    if Path(args.measurements).is_dir():
        return _run_images(args)
    given = [k for k, v in (*images, ("--intrinsics", args.intrinsics)) if v]
    if given:
        raise ConfigurationError(
            f"{given[0]} applies to a folder of images; {args.measurements} is a file"
        )
    ms = _read(args)
    if args.noise is not None:
        ms.metadata["noise"] = _noise(args.noise, bool(ms.frames))
    args.method = args.method or ("map" if args.link else DEFAULT_METHOD)
    start = time.perf_counter()
    for option, value in (("--level", args.level), ("--joints", args.joints)):
        if value is not None and args.method != "map":
            raise ConfigurationError(f"{option} applies to --method map, not {args.method}")
    joints = (
        [j.strip() for j in args.joints.split(",") if j.strip()]
        if args.joints is not None
        else None
    )
    if joints is not None and not joints:
        raise ConfigurationError(
            "--joints: name at least one joint to calibrate (URDF names, comma-separated)"
        )
    model = identify(
        ms,
        args.method,
        accept_inconsistent=args.accept_inconsistent,
        level=args.level,
        joints=joints,
    )
    elapsed = time.perf_counter() - start
    prov = (model.metadata.provenance or Provenance(method=args.method)).with_details(
        identification_time_s=elapsed
    )
    meta = model.metadata.replace(provenance=prov)
    path = save_model(model.with_params(metadata=meta), args.output)
    count = prov.details.get("identified_parameters", {}).get("total")
    print(
        f"wrote {path}: {args.method} identification of {ms.structure.name!r} from {ms.n_records} records "
        f"in {elapsed * 1e3:.0f} ms" + (f", {count} independent parameters" if count else "")
    )
    if "start" in prov.details:  # closed-form, circle-point or nominal
        print(f"  start: {prov.details['start']}")
    points_only = bool(ms.marker_points) and not ms.frames  # marker rows carry no rotation
    for f, r in (meta.residuals.per_frame if meta.residuals else {}).items():
        rotation = "" if points_only else f", {math.degrees(r.rms_rotation_rad):.3f} deg rms"
        print(
            f"  {f}: fit residual rms {r.rms_translation_m * 1e3:.3f} mm (max "
            f"{r.max_translation_m * 1e3:.3f} mm){rotation}"
        )
    for note in meta.notes:
        print(f"  note: {note}")
    consistency = prov.details.get("consistency", {})
    if consistency.get("accepted"):
        print(
            f"warning: the data are INCONSISTENT with the model; kept because of --accept-inconsistent: "
            f"{consistency['diagnosis']['cause']} (stored in the model's notes)"
        )
    if "cross_validation_rms_m" in prov.details:
        scores = prov.details["cross_validation_rms_m"]
        print(
            "  left-out RMS by level: "
            + ", ".join(f"{lv} {v * 1e3:.2f} mm" for lv, v in scores.items())
            + f"; chosen: {prov.details['chosen_level']}"
        )
        whole = prov.details.get("whole_range")
        if whole and whole["joints"]:
            w = whole["whole_range_m"]
            j, r = max(whole["joints"].items(), key=lambda kv: kv[1]["whole_range_m"])
            print(
                f"  over the whole joint range the measured point moves from your URDF's prediction by "
                f"{w['median'] * 1e3:.1f} / {w['p95'] * 1e3:.1f} / {w['max'] * 1e3:.1f} mm (median / p95 / max); "
                f"most by {j} ({r['whole_range_m'] * 1e3:.1f} mm over its range, {r['within_data_m'] * 1e3:.1f} mm "
                "within the data)"
            )
        if prov.details["beats_urdf"] is False:
            return NOT_BETTER_EXIT
    return 0
