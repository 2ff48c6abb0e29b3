"""``cpc2urdf check head.urdf --model MODEL``: three-parser FK cross-check of a URDF.

Exit code 0 when Pinocchio and yourdfpy agree with the CPC model to 1e-9 m / 1e-9 rad at every
frame and urdfdom parses the same tree; 1 on a discrepancy; 2 on bad input. For a model identified
from a user's URDF (or that URDF itself), URDF is the written-back file: every link on the paths
from its root to the model's frames is compared, by the URDF's own names, where the write-back puts
it (:func:`cpc2urdf.validation.crosscheck.cross_check_writeback`).

With ``--gaze-report``, a model with two camera frames is reported as a gaze head too: its kind
and, for two eyes, whether they can fixate exactly and their vertical disparity over the
workspace ahead (:func:`cpc2urdf.validation.gaze.head_report.head_report`; ``gaze_head`` in the
JSON). Without it, ``check`` builds no gaze solver (nothing is compiled).
"""

from __future__ import annotations

import argparse
import json
from typing import Any


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "check",
        help="cross-check a URDF against its CPC model (Pinocchio, yourdfpy, urdfdom)",
        description="Compare the pose of every frame of URDF with the CPC model at N random "
        "configurations within the limits, with Pinocchio, yourdfpy and urdfdom's check_urdf. "
        "For a model identified from your own URDF, URDF is the calibrated file export wrote back: "
        "every link on the paths from its root to the measured links is compared, by your URDF's "
        "link names, and every joint the model was built from must be as it recorded. "
        "Exit 0 all agree within 1e-9 m / 1e-9 rad, 1 discrepancy (naming the first link off, "
        "or the joint), 2 bad input.",
    )
    p.add_argument("urdf", help="URDF file")
    p.add_argument("--model", required=True, help="model file, robot spec or shipped robot name")
    p.add_argument(
        "-n",
        "--configurations",
        type=int,
        default=100,
        help="number of configurations (default 100)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the configurations (default 0)")
    p.add_argument(
        "--gaze-report",
        action="store_true",
        help="also report the model as a gaze head when it has two camera frames: its kind and, for two "
        "eyes, whether they can fixate exactly and their vertical disparity (builds the gaze solver)",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.api import check_urdf

    if args.configurations < 1:
        from cpc2urdf.errors import ConfigurationError

        raise ConfigurationError(f"--configurations must be at least 1, got {args.configurations}")
    report = check_urdf(args.model, args.urdf, args.configurations, args.seed)
    head = _gaze_head(args.model) if args.gaze_report else None
    if args.json:
        out = report.to_json()
        if head is not None:
            out["gaze_head"] = head
        print(json.dumps(out, indent=2))
    else:
        print(report.format())
        if head is not None:
            from cpc2urdf.validation.gaze.head_report import format_head_report

            print(
                "\n".join(format_head_report(head))
                if "error" not in head
                else f"gaze head: not analysed ({head['error']})"
            )
    return 0 if report.ok else 1


def _gaze_head(ref: str) -> dict[str, Any] | None:
    """The gaze head report of model ``ref`` when it has exactly two camera frames; None otherwise.
    A head the gaze solver cannot take (e.g. a joint without limits) is reported with its reason."""
    from cpc2urdf.errors import Cpc2UrdfError
    from cpc2urdf.files.robot_ref import is_urdf_ref, load_model

    if is_urdf_ref(ref):
        return None
    model = load_model(ref)
    cams = [f.name for f in model.structure.frames if f.kind == "camera"]
    if len(cams) != 2:
        return None
    from cpc2urdf.validation.gaze import GazeSolver
    from cpc2urdf.validation.gaze.head_report import head_report

    try:
        return head_report(GazeSolver.from_model(model, tuple(cams)))
    except Cpc2UrdfError as e:
        return {"cameras": cams, "error": str(e)}
