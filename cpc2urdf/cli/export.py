"""``cpc2urdf export MODEL -o head.urdf``: a model file or shipped robot to URDF."""

from __future__ import annotations

import argparse


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "export",
        help="write the URDF of a model file or shipped robot",
        description="Write a tree URDF of a model file, robot spec with nominal geometry, or shipped "
        "robot name (e.g. iis_head), ready for simulators: inertials, collisions, camera body frames. "
        "Root link 'world' is gravity-aligned (+z up) at the robot's base (the spec's 'up'), or with "
        "--mount rig the measuring rig the model was identified in. A model identified from your own "
        "URDF (or that URDF) is written back into it instead (docs/urdf.md).",
    )
    p.add_argument("model", help="model file, robot spec, or shipped robot name")
    p.add_argument("-o", "--output", required=True, help="URDF file to write (atomically)")
    p.add_argument(
        "--mount",
        choices=("base", "rig"),
        help="what root link 'world' is: 'base' (default) gravity-aligned at the base origin; "
        "'rig' the model's world, the measuring rig (T_world_base)",
    )
    p.add_argument(
        "--up",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="the up direction in base coordinates (default: the robot spec's 'up', else base +z)",
    )
    p.set_defaults(run=run, written=reports)


def reports(args: argparse.Namespace) -> dict[str, str]:
    """The calibration report written next to the URDF when a model is written back into its
    user's URDF (a model file with a ``urdf`` section; checked against the inputs before the
    command runs)."""
    import os

    from cpc2urdf.argparsing import json_object
    from cpc2urdf.urdf.report import written_reports

    doc = json_object(args.model) if os.path.isfile(args.model) else None
    if doc is None or not isinstance(doc.get("urdf"), dict):
        return {}
    return written_reports(args.output)


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.api import export_urdf
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import check_output_path
    from cpc2urdf.urdf.document import total_mass
    from cpc2urdf.urdf.export_plan import describe, plan_export
    from cpc2urdf.urdf.robot import urdf_source

    check_output_path(args.output)  # before any work (-o . is a folder: one line, no traceback)
    plan = plan_export(args.model, up=args.up)
    s = plan.model.structure
    if urdf_source(plan.model) is not None:  # a user's URDF: written back into it (docs/urdf.md)
        if args.mount is not None or args.up is not None:
            raise ConfigurationError(
                f"{args.model}: --mount and --up are for URDFs cpc2urdf writes; a robot described by "
                "its own URDF is written back into that URDF, root and inertials as they are"
            )
        path = export_urdf(plan.model, args.output, source=str(args.model))
        print(
            f"wrote {path}: {s.n_joints} joints, {len(s.frames)} frames, from the robot's own URDF"
        )
        return 0
    mount = args.mount or "base"
    path = export_urdf(args.model, args.output, source=str(args.model), mount=mount, up=args.up)
    print(
        f"wrote {path}: {s.n_joints} joints, {len(s.frames)} frames ({', '.join(s.frame_names)}); "
        f"total mass {total_mass(plan.model, plan.physical):.4g} kg"
    )
    print(f"  {describe(plan, mount)}")
    return 0
