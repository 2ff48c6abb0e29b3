"""``cpc2urdf identify measurements.json -o model.json``: identify a robot's CPC model.

Reads stage-1 measurements (``cpc2urdf/measurements@1``), runs an identification method
(``--method``, default ``refined``: the closed form of Shih et al. sec. 4.2, then maximum-likelihood
refinement of every record, which reaches the Cramér-Rao bound (docs/refinement.md); the registry is
:data:`cpc2urdf.identification.kinematics.methods.METHODS`) and writes a model file with the sections
``provenance`` (method, data used, the consistency gate's verdict), ``residuals`` (per record and per
branch) and ``notes``.

Data that cannot determine the robot (a joint never moved, too few distinct configurations, copied
records), or that are inconsistent with the fit (residuals far above or below the file's stated
noise, an implausible robot size, gross outliers; the cause is diagnosed by refitting the likely
mistakes), are refused: one line on stderr, exit code 2, no file. ``--accept-inconsistent`` keeps
the model of inconsistent data with the diagnosis in its notes and provenance (docs/identification.md).
"""

from __future__ import annotations

import argparse


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from cpc2urdf.identification.kinematics.methods import DEFAULT_METHOD, METHODS

    p = subparsers.add_parser(
        "identify",
        help="identify the CPC model from one-joint-at-a-time measurements",
        description="Identify every CPC parameter of the robot from stage-1 measurements (plate "
        "poses with joint readings, one joint moved at a time from q0) and write a model file "
        "for 'cpc2urdf export'. Unmeasured frames (cameras) keep their nominal placement relative "
        "to a measured plate on the same link, or are dropped if the robot has no nominal geometry.",
    )
    p.add_argument("measurements", help="measurement file (cpc2urdf/measurements@1)")
    p.add_argument("-o", "--output", required=True, help="model file to write (atomically)")
    p.add_argument("--method", choices=sorted(METHODS), default=DEFAULT_METHOD,
                   help="identification method (default refined: closed form + maximum-likelihood "
                   "refinement with covariance; closed-form: Shih et al. sec. 4.2 only)")
    p.add_argument("--robot", help="robot spec/model file or shipped name, instead of the file's 'robot'")
    p.add_argument("--accept-inconsistent", action="store_true",
                   help="keep the model even when the data are inconsistent with it (a fit far from the file's "
                   "stated noise, an implausible size, gross outliers); the diagnosis is stored in the model's "
                   "notes and provenance")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import time

    from cpc2urdf.api import identify, load_measurements, load_robot, save_model
    from cpc2urdf.fileio import check_output_path

    check_output_path(args.output)  # a bad -o is refused before the identification, not after it
    ms = load_measurements(args.measurements, robot=load_robot(args.robot) if args.robot else None)
    start = time.perf_counter()
    model = identify(ms, args.method, accept_inconsistent=args.accept_inconsistent)
    elapsed = time.perf_counter() - start
    import math

    from cpc2urdf.model_metadata import Provenance

    prov = (model.metadata.provenance or Provenance(method=args.method)).with_details(identification_time_s=elapsed)
    meta = model.metadata.replace(provenance=prov)
    path = save_model(model.with_params(metadata=meta), args.output)
    count = prov.details.get("identified_parameters", {}).get("total")
    print(f"wrote {path}: {args.method} identification of {ms.structure.name!r} from {ms.n_records} records "
          f"in {elapsed * 1e3:.0f} ms" + (f", {count} independent parameters" if count else ""))
    for f, r in (meta.residuals.per_frame if meta.residuals else {}).items():
        print(f"  {f}: fit residual rms {r.rms_translation_m * 1e3:.3f} mm (max "
              f"{r.max_translation_m * 1e3:.3f} mm), {math.degrees(r.rms_rotation_rad):.3f} deg rms")
    for note in meta.notes:
        print(f"  note: {note}")
    consistency = prov.details.get("consistency", {})
    if consistency.get("accepted"):
        print(f"warning: the data are INCONSISTENT with the model; kept because of --accept-inconsistent: "
              f"{consistency['diagnosis']['cause']} (stored in the model's notes)")
    return 0
