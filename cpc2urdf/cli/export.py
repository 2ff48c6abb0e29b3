"""``cpc2urdf export MODEL -o head.urdf``: a model file or shipped robot to URDF."""

from __future__ import annotations

import argparse


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "export",
        help="write the URDF of a model file or shipped robot",
        description="Write a tree URDF (root link 'world') of a model file, robot spec with "
        "nominal geometry, or shipped robot name (e.g. iis_head).",
    )
    p.add_argument("model", help="model file, robot spec, or shipped robot name")
    p.add_argument("-o", "--output", required=True, help="URDF file to write (atomically)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.api import export_urdf, load_model

    model = load_model(args.model)
    path = export_urdf(model, args.output, source=str(args.model))
    s = model.structure
    print(f"wrote {path}: {s.n_joints} joints, {len(s.frames)} frames ({', '.join(s.frame_names)})")
    return 0
