"""``cpc2urdf bench NAME``: speed/accuracy benchmarks, each against a reference in the same run."""

from __future__ import annotations

import argparse

from cpc2urdf.cli._registry import add_group

BENCHMARKS: dict[str, tuple[str, str]] = {
    "fk": ("cpc2urdf.studies.bench_fk", "vectorised CPC forward kinematics vs a Pinocchio loop"),
    "gaze": (
        "cpc2urdf.studies.bench_gaze",
        "gaze IK solve time and success vs scipy least_squares",
    ),
    "first-use": (
        "cpc2urdf.studies.first_use",
        "the first run of gaze, check and a Python solve after an install, against the second",
    ),
}


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    add_group(subparsers, "bench", "run a benchmark", BENCHMARKS)
