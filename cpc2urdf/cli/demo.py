"""``cpc2urdf demo``: the whole pipeline on the built-in IIS-head example.

Stages (each writes its artefacts into the output folder and prints one summary line):

1. nominal IIS-head (Shih et al. Tables 2-3) -> model file -> URDF -> three-parser cross-check.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "demo",
        help="run the pipeline on the built-in IIS-head example",
        description="Run the pipeline on the built-in IIS-head example and write every artefact "
        "into the output folder.",
    )
    p.add_argument("-o", "--output", default="demo-out", help="output folder (default: demo-out)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random step (default 0)")
    p.set_defaults(run=run)


def _step(title: str) -> float:
    print(f"\n== {title}")
    return time.perf_counter()


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.errors import OutputError
    from cpc2urdf.model_file import load_model, save_model
    from cpc2urdf.urdf import write_urdf
    from cpc2urdf.validation.crosscheck import cross_check

    out = Path(args.output)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"{out}: cannot create output folder ({e.strerror})") from e

    t = _step("1. nominal IIS-head -> model file -> URDF -> cross-check")
    nominal = load_model("iis_head")
    save_model(nominal, out / "nominal_model.json")
    write_urdf(nominal, out / "nominal.urdf", source="iis_head (nominal, Shih et al. Table 3)")
    report = cross_check(nominal, out / "nominal.urdf", n=100, seed=args.seed)
    print(report.format())
    print(f"   wrote {out / 'nominal_model.json'}, {out / 'nominal.urdf'} ({time.perf_counter() - t:.1f}s)")
    if not report.ok:
        return 1
    print(f"\ndemo finished: artefacts in {out}/")
    return 0
