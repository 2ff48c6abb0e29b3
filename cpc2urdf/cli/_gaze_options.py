"""The gaze solver's options, the same on every command that solves gaze (``gaze``, ``reach``):
which joints may move, when a target counts as fixated, and how near the policy brings a camera;
and what a drawn region says about them (``reach``, ``view --reach``)."""

from __future__ import annotations

import argparse
import math
from typing import Any


def add_solver_options(p: argparse.ArgumentParser) -> None:
    """``--joints``, ``--tolerance`` or ``--focal-px``, and ``--min-distance`` on parser ``p``."""
    p.add_argument(
        "--joints",
        nargs="+",
        metavar="JOINT",
        help="the joints that may move (default: every joint on the paths to the cameras; the others are held)",
    )
    tol = p.add_mutually_exclusive_group()
    tol.add_argument(
        "--tolerance",
        type=float,
        metavar="RAD",
        help="pointing error [rad] below which a target counts as fixated (default 1e-9: exact)",
    )
    tol.add_argument(
        "--focal-px",
        type=float,
        metavar="F",
        help="the cameras' focal length [px]: a target counts as fixated within 0.1 px",
    )
    p.add_argument(
        "--min-distance",
        type=float,
        metavar="M",
        help="nearest [m] the policy brings a camera to the target where it has the choice, "
        "e.g. a camera on an arm (default 0.1; 0: no limit)",
    )


def solver_options(args: argparse.Namespace) -> Any:
    """The :class:`~cpc2urdf.validation.gaze.GazeOptions` of :func:`add_solver_options`'s options
    (checked: a bad tolerance, focal length or distance is refused in one line)."""
    from cpc2urdf.validation.gaze import GazeOptions

    return GazeOptions(
        joints=tuple(args.joints) if args.joints else None,
        tolerance=args.tolerance,
        focal_px=args.focal_px,
        min_distance=args.min_distance,
    )


def region_notes(solver: Any, q_held: Any = None) -> list[str]:
    """What a reachable region of ``solver`` (a :class:`~cpc2urdf.validation.gaze.GazeSolver`)
    assumed, in one line for its PNG and legend: the joints that moved, those held (at the middle
    of their limits, or at ``q_held``: readings of shape (n,), the view's shown ones), and the
    tolerance of "fixated"."""
    moved = set(solver.free_joints("cyclopean").tolist())
    held = [i for i in solver.path_joints.tolist() if i not in moved]
    if q_held is None:
        where = (
            f"held at the middle of their limits: {', '.join(solver.joint_names[i] for i in held)}"
        )
    else:
        where = "held where shown: " + ", ".join(
            f"{solver.joint_names[i]}={float(q_held[i]):.4g}" for i in held
        )
    return [
        f"moving {', '.join(solver.moving)}"
        + (f"; {where}" if held else "")
        + f"; fixated: every axis within {math.degrees(solver.tolerance):.3g} deg"
    ]
