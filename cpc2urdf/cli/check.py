"""``cpc2urdf check head.urdf --model MODEL``: three-parser FK cross-check of a URDF.

Exit code 0 when Pinocchio and yourdfpy agree with the CPC model to 1e-9 m / 1e-9 rad at every
frame and urdfdom parses the same tree; 1 on a discrepancy; 2 on bad input. For a model identified
from a user's URDF (or that URDF itself), URDF is the written-back file: every link on the paths
from its root to the model's frames is compared, by the URDF's own names, where the write-back puts
it (:func:`cpc2urdf.validation.crosscheck.cross_check_writeback`).
"""

from __future__ import annotations

import argparse
import json


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
    p.add_argument("-n", "--configurations", type=int, default=100, help="number of configurations (default 100)")
    p.add_argument("--seed", type=int, default=0, help="seed of the configurations (default 0)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.api import check_urdf

    if args.configurations < 1:
        from cpc2urdf.errors import ConfigurationError

        raise ConfigurationError(f"--configurations must be at least 1, got {args.configurations}")
    report = check_urdf(args.urdf, args.model, args.configurations, args.seed)
    print(json.dumps(report.to_json(), indent=2) if args.json else report.format())
    return 0 if report.ok else 1
