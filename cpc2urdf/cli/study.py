"""``cpc2urdf study NAME``: seeded Monte Carlo studies that reproduce the papers' figures."""

from __future__ import annotations

import argparse

from cpc2urdf.cli._registry import add_group

STUDIES: dict[str, tuple[str, str]] = {
    "stereo": ("cpc2urdf.identification.study_stereo_noise", "plate pose error of the stereo rig vs pixel noise"),
    "fig11": ("cpc2urdf.identification.study_fig11", "Shih et al. Fig. 11: positioning error vs M and noise"),
}


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    add_group(subparsers, "study", "run a study (tables and PNG plots)", STUDIES)
