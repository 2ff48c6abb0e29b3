"""``cpc2urdf accuracy model.json heldout.json``: the paper's Table 4 on held-out records.

When the model carries a covariance (``identify --method refined``), the held-out errors are tested
against the model's own prediction; errors far above or below it (beyond chance, false-alarm
probability 1e-6) are refused with one line naming the likely cause (exit code 2), unless
``--accept-inconsistent``, which prints the table and the mismatch as a warning.
"""

from __future__ import annotations

import argparse


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "accuracy",
        help="held-out positioning error of a model per branch (the paper's Table 4)",
        description="Compare a model's predicted frame origins with held-out measurements (a "
        "cpc2urdf/measurements@1 file, any configurations): per branch, the mean and standard "
        "deviation of |e_x|, |e_y|, |e_z| and the mean Euclidean error, in mm, and the rotation error. "
        "Errors inconsistent with the model's own predicted uncertainty are refused (exit code 2).",
    )
    p.add_argument(
        "model", help="model file (e.g. from 'cpc2urdf identify'), robot spec or shipped name"
    )
    p.add_argument("heldout", help="held-out measurement file")
    p.add_argument("--json", action="store_true", help="print the table as JSON (mm, degrees)")
    p.add_argument(
        "--accept-inconsistent",
        action="store_true",
        help="print the table even when the held-out errors are inconsistent with the model's own "
        "prediction (the mismatch is printed as a warning)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import json

    from cpc2urdf.api import accuracy, load_measurements, load_model
    from cpc2urdf.validation.heldout import format_table, prediction_check

    model = load_model(args.model)
    ms = load_measurements(args.heldout)
    report = accuracy(model, ms, accept_inconsistent=args.accept_inconsistent)
    if args.json:
        print(json.dumps({f: b.to_json() for f, b in report.items()}, indent=2))
    else:
        print(format_table(report))
    check = prediction_check(model, ms) if args.accept_inconsistent else None
    if check is not None and not check.consistent:
        print(f"warning: INCONSISTENT, kept because of --accept-inconsistent: {check.line()}")
    return 0
