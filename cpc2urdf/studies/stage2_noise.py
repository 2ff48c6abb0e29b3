"""Study: camera-frame error of stage 2 (Shih et al. sec. 5) vs pixel noise, per hand-eye solver.

The IIS-head nominal model with its camera mounts perturbed (3 deg, 5 mm) is the truth; the
identified model equals the truth apart from the cameras (stage 1 perfect), so the numbers
isolate stage 2: pixel noise -> solvePnP -> hand-eye
(:func:`cpc2urdf.identification.handeye.stage2.run_stage2`).

    cpc2urdf study stage2 [--poses 20] [--seeds 10] [--noise 0 0.05 0.1 0.2 0.5] [--methods ...]

Prints a table of the median ``T_link_camera`` error (translation [mm] / rotation [deg]) per
pixel noise and solver (``docs/handeye.md``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.progress import progress

NOISE_LEVELS = (0.0, 0.05, 0.1, 0.2, 0.5)  # [px]
METHODS = ("tsai", "park_martin", "kronecker", "refined", "ml")


def run_study(
    *,
    poses: int = 20,
    seeds: int = 10,
    noise: Sequence[float] = NOISE_LEVELS,
    methods: Sequence[str] = METHODS,
) -> dict[tuple[float, str], tuple[float, float]]:
    """Run stage 2 ``seeds`` times per pixel noise [px] and solver.

    Returns:
        Per ``(noise, method)``, the median over seeds and both cameras of the ``T_link_camera``
        error: ``(translation [m], rotation [rad])``.
    """
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.identification.handeye.stage2 import perturb_cameras, run_stage2

    nominal = load_model("iis_head")
    truth = perturb_cameras(nominal, np.random.default_rng(1))
    identified = truth.without_frames(["camera"])
    jobs = [(s, m) for s in noise for m in methods]
    out: dict[tuple[float, str], tuple[float, float]] = {}
    for sigma, m in progress(jobs, "stage2"):
        et, er = [], []
        for seed in range(seeds):
            r = run_stage2(identified, truth, n_poses=poses, pixel_noise=sigma, method=m, seed=seed)
            for t, a in r.errors.values():
                et.append(t)
                er.append(a)
        out[(sigma, m)] = (float(np.median(et)), float(np.median(er)))
    return out


def main(argv: list[str] | None = None) -> int:
    """``cpc2urdf study stage2``: camera-frame error of stage 2 vs pixel noise, per solver.

    The IIS-head nominal model with its camera mounts perturbed (3 deg, 5 mm) is the truth; the
    identified model equals the truth apart from the cameras (stage 1 perfect), so the numbers
    isolate stage 2: pixel noise -> solvePnP -> hand-eye.
    """
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.identification.handeye.solvers import ALL_METHODS
    from cpc2urdf.identification.handeye.stage2 import DEFAULT_INTRINSICS, DEFAULT_TARGET_DISTANCE
    from cpc2urdf.identification.vision.targets import TARGET_COLS, TARGET_PITCH, TARGET_ROWS

    parser = OneLineParser(
        prog="cpc2urdf study stage2",
        description=main.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--poses", type=int, default=20, help="head configurations per run (default 20)"
    )
    parser.add_argument("--seeds", type=int, default=10, help="runs per noise level (default 10)")
    parser.add_argument(
        "--noise",
        type=float,
        nargs="+",
        default=list(NOISE_LEVELS),
        help="pixel noise levels [px] (default 0 0.05 0.1 0.2 0.5)",
    )
    parser.add_argument(
        "--methods",
        nargs="+",
        default=list(METHODS),
        choices=ALL_METHODS,
        metavar="METHOD",
        help=f"hand-eye solvers, some of {', '.join(ALL_METHODS)} (default {' '.join(METHODS)})",
    )
    args = parser.parse_args(argv)
    if args.poses < 3 or args.seeds < 1:
        raise ConfigurationError("--poses must be >= 3 and --seeds >= 1")
    bad = [v for v in args.noise if not (math.isfinite(v) and v >= 0)]
    if bad:
        raise ConfigurationError(
            f"--noise: pixel noise levels must be finite numbers >= 0 [px], got {bad[0]:g}"
        )
    print(
        f"stage 2 on iis_head: {args.poses} configurations, {args.seeds} seeds, target "
        f"{TARGET_ROWS}x{TARGET_COLS} disks at {TARGET_PITCH * 1e3:.0f} mm pitch, "
        f"{DEFAULT_TARGET_DISTANCE:.1f} m ahead; f = {DEFAULT_INTRINSICS.fx:.0f} px"
    )
    print(
        "median over seeds and both cameras of the T_link_camera error: translation [mm] / rotation [deg]"
    )
    print(f"{'noise [px]':>10s} " + " ".join(f"{m:>20s}" for m in args.methods))
    errors = run_study(poses=args.poses, seeds=args.seeds, noise=args.noise, methods=args.methods)
    cells = {k: f"{t * 1e3:9.4f} / {math.degrees(r):7.4f}" for k, (t, r) in errors.items()}
    for sigma in args.noise:
        print(f"{sigma:10.2f} " + " ".join(f"{cells[(sigma, m)]:>20s}" for m in args.methods))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["METHODS", "NOISE_LEVELS", "main", "run_study"]
