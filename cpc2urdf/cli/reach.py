"""``cpc2urdf reach ROBOT -o region.png [--json REGION.json] [--html REGION.html [--screenshot
VIEW.png]]``: draw where a head's cameras can fixate, as slices (PNG) and in the 3D view (a
self-contained meshcat page with the robot's own meshes and one point cloud per category).

Exit codes: 0 the region was drawn, 2 bad input (one line, nothing written).
"""

from __future__ import annotations

import argparse

from cpc2urdf.cli._gaze_options import add_solver_options, region_notes, solver_options

# Kept here so that `cpc2urdf --help` does not import numpy; tests check they match
# cpc2urdf.validation.gaze.reachable.
DEFAULT_CAMERAS = ("camera_left_optical", "camera_right_optical")
DEFAULT_RANGE = (0.2, 3.0)  # [m]
DEFAULT_SAMPLES = (16, 37, 25)
GRID_KINDS = ("shell", "box")


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "reach",
        help="draw the reachable region of a head: where its cameras can fixate a target",
        description="Solve gaze for a grid of targets in front of a head (a .urdf file, a model "
        "file, a robot spec or a shipped robot name) and draw which ones are fixated, and why the "
        "others are not (disparity, joint limits, behind, too close, no solution), as a PNG. The grid lies in "
        "the head frame: the cameras' mid-point at the middle of every joint's limits, x along "
        "the mean optical axis, z up. shell (default): distances NEAR..FAR, azimuth +-90 deg, "
        "elevation +-60 deg; box: forward NEAR..FAR, lateral +-FAR, vertical +-FAR/2. Exit code "
        "0 drawn, 2 bad input.",
    )
    p.add_argument(
        "robot", metavar="ROBOT", help=".urdf file, model file, robot spec or shipped robot name"
    )
    p.add_argument(
        "--camera",
        nargs="+",
        default=list(DEFAULT_CAMERAS),
        metavar="FRAME",
        help=f"camera optical frames (default {' '.join(DEFAULT_CAMERAS)})",
    )
    p.add_argument(
        "--range",
        nargs=2,
        type=float,
        default=list(DEFAULT_RANGE),
        metavar=("NEAR", "FAR"),
        help=f"distances of the grid [m] (default {DEFAULT_RANGE[0]:g} {DEFAULT_RANGE[1]:g})",
    )
    p.add_argument("--grid", choices=GRID_KINDS, default="shell", help="grid shape (default shell)")
    p.add_argument(
        "--samples",
        nargs=3,
        type=int,
        default=list(DEFAULT_SAMPLES),
        metavar=("D", "A", "E"),
        help="samples per axis: distance, azimuth, elevation (box: forward, lateral, vertical); "
        f"default {' '.join(str(k) for k in DEFAULT_SAMPLES)}",
    )
    add_solver_options(p)
    p.add_argument("-o", "--output", required=True, metavar="REGION.png", help="the PNG to write")
    p.add_argument(
        "--json", metavar="REGION.json", help="also write every target's point, status and error"
    )
    p.add_argument(
        "--html",
        metavar="REGION.html",
        help="also write the region in the 3D view: one self-contained page (no server, no network) "
        "with the robot from its URDF visuals and own meshes at the middle of its limits, and every "
        "target as a point coloured by category (the PNG's colours; not pointed at: translucent), each "
        "category a node under 'reach' in meshcat's controls",
    )
    p.add_argument(
        "--screenshot",
        metavar="VIEW.png",
        help="with --html: also render the page in headless Chromium",
    )
    p.add_argument(
        "--package-path",
        action="append",
        default=[],
        metavar="DIR",
        help="with --html: where package://NAME/... meshes are found (as for cpc2urdf view); repeatable",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import check_output_path, dumps, write_all_atomic
    from cpc2urdf.validation.gaze import solver_for
    from cpc2urdf.validation.gaze.reachable import (
        check_grid_args,
        make_grid,
        reachable_region,
        region_figure_png,
    )
    from cpc2urdf.validation.view import load_view_robot, static_view_html
    from cpc2urdf.validation.view.region import view_cameras
    from cpc2urdf.validation.view.screenshot import require_chromium, screenshot_page

    if Path(args.output).suffix.lower() != ".png":
        raise ConfigurationError(
            f"-o {args.output}: the region is drawn as PNG, expected a .png path"
        )
    check_grid_args(args.range[0], args.range[1], args.samples)
    check_output_path(args.output)
    if args.screenshot and not args.html:
        raise ConfigurationError("--screenshot needs --html (the page to render)")
    if args.package_path and not args.html:
        raise ConfigurationError(
            "--package-path needs --html (meshes are drawn only in the 3D view)"
        )
    if args.html and Path(args.html).suffix.lower() not in (".html", ".htm"):
        raise ConfigurationError(
            f"--html {args.html}: the view is a web page, expected an .html path"
        )
    if args.screenshot and Path(args.screenshot).suffix.lower() != ".png":
        raise ConfigurationError(
            f"--screenshot {args.screenshot}: the view is rendered as PNG, expected a .png path"
        )
    if args.screenshot:
        require_chromium()  # before the solve, not after it
    for path in (
        args.json,
        args.html,
        args.screenshot,
    ):  # (two outputs naming one file: refused by the CLI)
        if path is not None:
            check_output_path(path)
    # the robot as drawn (its meshes) loads before the grid is solved: a missing mesh fails at once
    view_robot = load_view_robot(args.robot, package_dirs=args.package_path) if args.html else None
    solver = solver_for(args.robot, tuple(args.camera), solver_options(args))
    grid = make_grid(solver, args.grid, args.range[0], args.range[1], args.samples)
    region = reachable_region(solver, grid)
    # render every output before writing any: a failure leaves nothing behind
    notes = region_notes(solver)
    png = region_figure_png(region, title=Path(args.robot).name, notes=notes)
    files: dict[str, str | bytes] = {args.output: png}
    if args.json:
        # what "fixated" meant: the tolerance, the unknowns that moved, the policy's nearest approach
        doc = {
            "format": "cpc2urdf/reach@1",
            "robot": str(args.robot),
            "cameras": list(solver.cameras),
            "tolerance_rad": solver.tolerance,
            "moving": list(solver.moving),
            "min_distance_m": solver.min_distance,
            **region.to_json(),
        }
        files[args.json] = dumps(doc)
    view = None
    if view_robot is not None:
        page, view = static_view_html(
            view_robot,
            region=region,
            region_notes=notes,
            cameras=view_cameras(view_robot, region.cameras),
        )
        files[args.html] = page
        if args.screenshot:
            files[args.screenshot] = screenshot_page(page, args.screenshot)
    write_all_atomic(files)
    counts = region.counts()
    total = region.points.shape[0]
    parts = ", ".join(f"{n} {c.replace('_', ' ')}" for c, n in counts.items() if n)
    print(f"{args.output}: {total} targets ({args.grid} grid): {parts}")
    if view is not None:
        print(f"{args.html}: the region in the 3D view (self-contained; open it in a browser)")
        if view.meshes is not None and view.meshes.n_meshes:
            print(f"  {view.meshes.format()}")
        if view.region is not None and view.region.moved():
            print(f"  {view.region.moved()}")
        if args.screenshot:
            print(f"{args.screenshot}: the page in headless Chromium")
    return 0
