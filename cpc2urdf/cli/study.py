"""``cpc2urdf study NAME``: seeded Monte Carlo studies that reproduce the papers' figures."""

from __future__ import annotations

import argparse

from cpc2urdf.cli._registry import add_group

STUDIES: dict[str, tuple[str, str]] = {
    "stereo": (
        "cpc2urdf.studies.stereo_noise",
        "plate pose error of the stereo rig vs pixel noise",
    ),
    "stage2": (
        "cpc2urdf.studies.stage2_noise",
        "stage-2 camera frame error vs pixel noise, per hand-eye solver",
    ),
    "li2010": ("cpc2urdf.studies.li2010", "Li et al. 2010 Fig. 1: AX=ZB errors vs number of poses"),
    "fig11": ("cpc2urdf.studies.fig11", "Shih et al. Fig. 11: positioning error vs M and noise"),
    "gate": (
        "cpc2urdf.studies.gate",
        "stage-1 consistency gate: clean data passed, mistakes named, over seeded trials",
    ),
    "crb": (
        "cpc2urdf.studies.crb",
        "closed form and refinement vs the Cramér-Rao bound (M = 9, 0.5 mm)",
    ),
    "plan": (
        "cpc2urdf.studies.plan_accuracy",
        "experiment planning: predicted vs observed held-out error, optimal plans vs protocol",
    ),
    "images": (
        "cpc2urdf.studies.image_pipeline",
        "image pipeline: centre, pose and identification errors from rendered images",
    ),
    "boards": (
        "cpc2urdf.studies.board_pipeline",
        "standard boards: poses vs pixel noise, calibrateCamera/stereoCalibrate, both stages",
    ),
    "free-configs": (
        "cpc2urdf.studies.free_configs",
        "refined held-out error: random configurations vs the one-joint protocol",
    ),
    "selfcal": (
        "cpc2urdf.studies.selfcal",
        "a head calibrated by its own cameras: one stage vs two, covariance and CRB checks",
    ),
    "real-data": (
        "cpc2urdf.studies.real_data",
        "calibration held out on three real robots (TIAGo, TALOS, UR10) vs their URDFs and FIGAROH",
    ),
    "handeye-pairs": (
        "cpc2urdf.studies.handeye_pairs",
        "AX = XB from all pose pairs, ours (O(N)) or consecutive ones: X's error on the same data",
    ),
    "kinhec": (
        "cpc2urdf.studies.handeye_kinhec",
        "the default hand-eye solver on KinHEC's tracks vs its baselines (pip install kinhec)",
    ),
    "gaze-ahead": (
        "cpc2urdf.studies.gaze_ahead",
        "calibrated demo heads (seeds 0-9) answer targets ahead facing them, vs the nominal head",
    ),
}


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    add_group(subparsers, "study", "run a study (tables and PNG plots)", STUDIES)
