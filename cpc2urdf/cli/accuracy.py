"""``cpc2urdf accuracy model.json heldout.json``: the paper's Table 4 on held-out records."""

from __future__ import annotations

import argparse


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "accuracy",
        help="held-out positioning error of a model per branch (the paper's Table 4)",
        description="Compare a model's predicted frame origins with held-out measurements (a "
        "cpc2urdf/measurements@1 file, any configurations): per branch, the mean and standard "
        "deviation of |e_x|, |e_y|, |e_z| and the mean Euclidean error, in mm, and the rotation error.",
    )
    p.add_argument("model", help="model file (e.g. from 'cpc2urdf identify'), robot spec or shipped name")
    p.add_argument("heldout", help="held-out measurement file")
    p.add_argument("--json", action="store_true", help="print the table as JSON (mm, degrees)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import json

    from cpc2urdf.api import accuracy, load_measurements, load_model
    from cpc2urdf.validation.accuracy import format_table

    model = load_model(args.model)
    ms = load_measurements(args.heldout)
    report = accuracy(model, ms)
    if args.json:
        print(json.dumps({f: b.to_json() for f, b in report.items()}, indent=2))
    else:
        print(format_table(report))
    return 0
