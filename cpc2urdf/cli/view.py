"""``cpc2urdf view URDF_OR_MODEL [--target X Y Z] [--nominal [OTHER]] [--measurements FILE]
[--package-path DIR ...] [--html OUT]``.

Without ``--html`` the scene is served by meshcat on localhost: the URL is printed and the command
waits until interrupted (Ctrl-C stops the server and exits 0). With ``--html`` it writes one
self-contained page (no server, no network) and exits; ``--screenshot PNG`` also renders that page
in headless Chromium. See ``docs/view.md``.
"""

from __future__ import annotations

import argparse
from typing import Any

from cpc2urdf.argparsing import finite_numbers, joint_readings
from cpc2urdf.errors import ConfigurationError, OutputError

OWN_NOMINAL = ""  # --nominal without a value: the URDF the model was identified from


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "view",
        help="show a head (calibrated or nominal) in meshcat, in a browser",
        description="Show a robot from its URDF visuals (boxes, cylinders, spheres and its own "
        "STL/DAE/OBJ meshes) in meshcat, with axis triads on plate and camera frames; with "
        "--target the head fixates it (gaze solver) and a ray runs along each optical axis; "
        "--nominal adds another model as a translucent ghost and colours each link by how far "
        "calibration moved it (green < 1 mm, yellow, red >= 10 mm); --measurements draws "
        "measured plate positions and bars to the model's predictions. Serves on localhost until "
        "Ctrl-C, or writes a self-contained page with --html. Lengths in m, angles in rad.",
    )
    p.add_argument(
        "robot",
        metavar="URDF_OR_MODEL",
        help=".urdf, model file, robot spec, or shipped robot name",
    )
    p.add_argument(
        "--target", nargs=3, metavar=("X", "Y", "Z"), help="point to fixate, in world [m]"
    )
    p.add_argument(
        "--nominal",
        metavar="OTHER",
        nargs="?",
        const=OWN_NOMINAL,
        help="another model/URDF of the same robot (the nominal one), shown as a ghost (placed as "
        "--align says); each link is coloured by how far it moved from the ghost's link of the "
        "same name. Without OTHER (after URDF_OR_MODEL): for a model identified from your URDF, "
        "that URDF",
    )
    p.add_argument(
        "--align",
        choices=("auto", "base", "world"),
        default="auto",
        help="with --nominal: base = put the ghost's base link on the robot's and compare links "
        "relative to it; world = compare in one world; auto (default) = base when the two bases "
        "are 50 mm or 5 deg apart or more (different worlds: the rig, a gravity-aligned export, a "
        "spec's origin), else world",
    )
    p.add_argument(
        "--keep-colours",
        action="store_true",
        help="with --nominal: keep the URDF colours instead of colouring links by how far they moved",
    )
    p.add_argument(
        "--package-path",
        action="append",
        default=[],
        metavar="DIR",
        help="where package://NAME/... meshes are found (DIR/NAME, or DIR itself if named NAME); "
        "repeatable; searched before ROS_PACKAGE_PATH, AMENT_PREFIX_PATH and the folders above "
        "the URDF",
    )
    p.add_argument(
        "--measurements", metavar="FILE", help="a cpc2urdf/measurements@1 file of this robot"
    )
    p.add_argument(
        "--html", metavar="OUT.html", help="write a self-contained page instead of serving"
    )
    p.add_argument(
        "--screenshot", metavar="OUT.png", help="with --html: also render it in headless Chromium"
    )
    p.add_argument(
        "--q",
        nargs="+",
        metavar="Q",
        help="configuration: NAME=VALUE pairs (others mid-range) or one value per joint in order "
        "[rad]/[m]; with --target, where the gaze solve starts",
    )
    # --cameras takes exactly two, as it always has (so "--cameras L R ROBOT" still parses);
    # --camera one or two
    p.add_argument(
        "--cameras",
        dest="cameras",
        nargs=2,
        metavar=("LEFT", "RIGHT"),
        default=["camera_left_optical", "camera_right_optical"],
        help="the two camera optical frames of the gaze (two eyes, or a rigid pair) (default: %(default)s)",
    )
    p.add_argument(
        "--camera",
        dest="cameras",
        nargs="+",
        metavar="FRAME",
        help="instead of --cameras: one camera optical frame (look-at), or two",
    )
    p.add_argument(
        "--policy", default="cyclopean", help="gaze redundancy policy (default: %(default)s)"
    )
    p.add_argument("--no-sweep", action="store_true", help="leave out the joint sweep animation")
    p.add_argument(
        "--reach",
        action="store_true",
        help="also draw where the cameras (--camera/--cameras) can fixate: every target of cpc2urdf "
        "reach's default grid (a shell 0.2-3 m from the cameras, +-90 deg azimuth, +-60 deg "
        "elevation; 14,800 targets) as a point coloured by category (fixated, disparity, joint "
        "limits, behind, too close, no solution), the joints that do not move held where shown "
        "(--q, else the middle of their limits), the grid laid out about the cameras with the "
        "moving joints at the middle of theirs (as reach does; not where --q or --target turn "
        "them); for another grid or the solver's options, cpc2urdf reach --html",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from cpc2urdf.files.jsonio import check_output_path, write_all_atomic
    from cpc2urdf.validation.view import load_view_robot, static_view_html
    from cpc2urdf.validation.view.screenshot import require_chromium, screenshot_page
    from cpc2urdf.validation.view.view_robot import own_nominal

    if args.screenshot and not args.html:
        raise ConfigurationError("--screenshot needs --html (the page to render)")
    for path in (args.html, args.screenshot):
        if path:
            check_output_path(path)
    if args.screenshot:
        require_chromium()
    if len(args.cameras) > 2:
        raise ConfigurationError(
            f"--camera takes one or two optical frames, got {len(args.cameras)}"
        )
    target = finite_numbers(args.target, "--target X Y Z") if args.target else None
    robot = load_view_robot(args.robot, package_dirs=args.package_path)
    options: dict[str, Any] = {
        "q": joint_readings(args.q, "--q"),
        "target": target,
        "cameras": tuple(args.cameras),
        "policy": args.policy,
        "change_colours": not args.keep_colours,
        "align": args.align,
    }
    if args.nominal is not None:
        nominal = own_nominal(robot) if args.nominal == OWN_NOMINAL else args.nominal
        options["ghost"] = load_view_robot(nominal, package_dirs=args.package_path)
    if args.measurements:
        from cpc2urdf.files.measurements import load_measurements

        options["measurements"] = load_measurements(args.measurements)
    notes: list[str] = []
    if args.reach:  # solved on the robot as drawn, as --target is: one world, the view's names
        from cpc2urdf.cli._gaze_options import region_notes
        from cpc2urdf.validation.gaze import GazeSolver
        from cpc2urdf.validation.gaze.chain import mid_limits
        from cpc2urdf.validation.gaze.reachable import make_grid, reachable_region

        # the joints that do not move are held where shown (--q, else the middle of their limits);
        # the moving ones start, and the grid is laid out, at the middle of theirs, as reach does:
        # where the cameras look now (--q, --target) does not change where they can look
        posture = robot.q_from(options["q"])
        solver = GazeSolver(robot.pinocchio, tuple(args.cameras))
        moving = solver.free_joints("cyclopean")
        posture[moving] = mid_limits(solver.lower, solver.upper)[moving]
        options["region"] = reachable_region(
            solver, make_grid(solver, q=posture), q_current=posture
        )
        notes = region_notes(solver, posture)

    for line in notes:  # what the region assumed (a served view has no legend)
        print(f"reachable region: {line}")
    if args.html:
        # the page and its picture are rendered before either is written: a failure leaves neither
        page, summary = static_view_html(
            robot, sweep=not args.no_sweep, region_notes=notes, **options
        )
        files: dict[str, str | bytes] = {args.html: page}
        if args.screenshot:
            files[args.screenshot] = screenshot_page(page, args.screenshot)
        write_all_atomic(files)
        print(summary.format())
        print(f"wrote {args.html} (self-contained; open it in a browser)")
        if args.screenshot:
            print(f"wrote {args.screenshot}")
        return 0
    return _serve(robot, options, sweep=not args.no_sweep)


def _serve(robot: Any, options: dict[str, Any], *, sweep: bool) -> int:
    """Serve the scene with meshcat's server until Ctrl-C."""
    import signal
    import subprocess
    import time

    import meshcat

    from cpc2urdf.validation.view import build_view, static_visualizer

    build_view(static_visualizer(), robot, sweep=False, **options)  # bad input: fail before serving

    def stop(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    # Ctrl-C and `kill` both stop the server cleanly (a background job may start with SIGINT
    # ignored, and SIGTERM would otherwise skip the cleanup and orphan meshcat's server).
    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        vis = meshcat.Visualizer()  # starts meshcat's server on localhost; prints the URL
    except (RuntimeError, OSError) as e:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        raise OutputError(f"cannot start meshcat's server ({e})") from e
    try:
        summary = build_view(vis, robot, sweep=sweep, **options)
        print(summary.format())
        print(f"serving at {vis.url()} (Ctrl-C to stop)", flush=True)
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        print("stopped")
        return 0
    finally:
        proc = getattr(vis.window, "server_proc", None)
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:  # a stuck server is killed, never waited on forever
                proc.kill()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
