"""``cpc2urdf gaze HEAD --target X Y Z``: joint readings that fixate a target with both cameras;
``cpc2urdf gaze HEAD --report``: the head itself (kind; for two eyes, whether they can fixate
exactly and their vertical disparity over the workspace ahead).

Exit codes: 0 the target is fixated (or the report alone), 1 it is not fixated within the
tolerance: unreachable, or on a head that cannot fixate exactly the policy's posture (status
``disparity``); the best in-limit readings and the residual are still printed. 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import math
import re

from cpc2urdf.cli._gaze_options import add_solver_options, solver_options

# Kept here so that `cpc2urdf --help` does not import numpy; tests check they match
# cpc2urdf.validation.gaze.
POLICIES = ("cyclopean", "min-motion", "eyes-only")
DEFAULT_CAMERAS = ("camera_left_optical", "camera_right_optical")
# argparse reads "-1.7e308" as an option (its own pattern has no exponent): numbers, inf and nan
NEGATIVE_NUMBER = re.compile(
    r"^-(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE
)


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "gaze",
        help="solve gaze IK: joint readings that point both cameras at a 3D target",
        description="Point both camera optical axes at a target (world frame, metres) on a head "
        "given as a .urdf file, a model file, a robot spec or a shipped robot name (e.g. "
        "iis_head). Prints the readings, reachability and residuals; moves nothing. Exit code "
        "0 fixated, 1 not fixated within the tolerance (unreachable, or the posture of a head that cannot "
        "fixate exactly: status disparity), 2 bad input.",
    )
    p._negative_number_matcher = NEGATIVE_NUMBER  # --target -1 -2e3 0
    p.add_argument(
        "head",
        metavar="URDF_OR_MODEL",
        help=".urdf file, model file, robot spec or shipped robot name",
    )
    p.add_argument(
        "--target", nargs=3, type=float, metavar=("X", "Y", "Z"), help="target in world [m]"
    )
    p.add_argument(
        "--report",
        action="store_true",
        help="report the head once: its kind and, for two eyes, whether they can fixate exactly and their "
        "vertical disparity over the workspace ahead (with or without --target)",
    )
    p.add_argument(
        "--policy",
        choices=POLICIES,
        default="cyclopean",
        help="redundancy policy (default cyclopean)",
    )
    p.add_argument(
        "--q-current",
        nargs="+",
        metavar="Q",
        help="current readings [rad]/[m]: NAME=VALUE pairs (the joints not named at the middle of their "
        "limits), or one value per joint in the order the solution lists them (Pinocchio's model order, "
        "not the order of the URDF file) (default: the middle of the limits)",
    )
    p.add_argument(
        "--camera",
        "--cameras",
        dest="cameras",
        nargs="+",
        default=list(DEFAULT_CAMERAS),
        metavar="FRAME",
        help="one camera optical frame (look-at) or two (left right: binocular, or a rigid pair) "
        f"(default {' '.join(DEFAULT_CAMERAS)})",
    )
    add_solver_options(p)
    p.add_argument("--json", action="store_true", help="print the solution as JSON (SI units)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.argparsing import joint_readings
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.validation.gaze import solver_for

    if len(args.cameras) > 2:
        raise ConfigurationError(
            f"--camera takes one or two optical frames, got {len(args.cameras)}"
        )
    if args.target is None and not args.report:
        raise ConfigurationError("give --target X Y Z, or --report for the head alone")
    q_given = joint_readings(
        args.q_current, "--q-current"
    )  # refused before anything is loaded or printed
    solver = solver_for(args.head, tuple(args.cameras), solver_options(args))
    if isinstance(q_given, dict):  # the joints not named: the middle of their limits
        q_given = {**dict(zip(solver.joint_names, solver.home.tolist(), strict=True)), **q_given}
    q_current = solver.check_q(q_given)  # refused before the report is printed
    head = None
    if args.report:
        from cpc2urdf.validation.gaze.head_report import format_head_report, head_report

        head = head_report(solver)
        if not args.json:
            print("\n".join(format_head_report(head)))
    if args.target is None:
        if args.json:
            print(json.dumps({"head": head}, indent=2))
        return 0
    sol = solver.solve(args.target, q_current, args.policy)
    if args.json:
        print(
            json.dumps(
                sol.to_json() if head is None else {"head": head, "solution": sol.to_json()},
                indent=2,
            )
        )
        return 0 if sol.reachable else 1
    t = ", ".join(f"{v:.10g}" for v in sol.target)
    print(f"target ({t}) m, policy {sol.policy}: {sol.status} after {sol.iterations} iterations")
    kinds = solver.joint_kinds
    # the joints on the cameras' paths; the others (a robot's arms, wheels) keep their readings
    on_path = {solver.joint_names[i] for i in solver.path_joints.tolist()}
    names = [name for name in sol.joints if name in on_path]
    width = max([16, *(len(name) for name in names)])
    for name in names:
        v = sol.joints[name]
        shown = f"{math.degrees(v):10.4f} deg" if kinds[name] == "revolute" else f"{v:10.6f} m"
        flag = "  (at limit)" if name in sol.at_limit else ""
        print(f"  {name:{width}s} {shown}{flag}")
    if len(names) < len(sol.joints):
        print(
            f"  ({len(sol.joints) - len(names)} other joints, off the cameras' paths, at --q-current or the middle "
            "of their limits; --json lists every joint)"
        )
    e, m = sol.pointing_error, sol.miss_distance
    if len(e) == 2:
        print(f"pointing error: left {e[0]:.3g} rad, right {e[1]:.3g} rad")
        print(f"miss distance:  left {m[0]:.3g} m, right {m[1]:.3g} m")
        fix = (
            "none (axes parallel)"
            if sol.fixation_point is None
            else "(" + ", ".join(f"{v:.10g}" for v in sol.fixation_point) + ") m"
        )
        print(f"fixation point: {fix}; vergence {math.degrees(sol.vergence):.4f} deg")
    else:
        print(f"pointing error: {e[0]:.3g} rad; miss distance {m[0]:.3g} m")
    return 0 if sol.reachable else 1
