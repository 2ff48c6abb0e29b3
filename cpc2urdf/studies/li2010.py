"""Study: Li, Wang & Wu (2010) Fig. 1, errors of X and Z against the number of poses.

Li et al.'s simulation: nominal X and Z are given, robot poses ``A_i`` drawn, ``B_i = Z^-1 A_i X``
computed; uniform noise, U(-1, 1) mm on each position component and U(-0.5, 0.5) deg on each
Z-Y-Z Euler angle, is added to A only (Fig. 1a), to B only (1b) or to both (1c); X and Z are
estimated by the Kronecker product method, the dual-quaternion method and Zhuang's quaternion
method; each pose count is repeated 10 times and the errors averaged. Their error is "the norm
of the difference between the computed X and theoretical X" (sigma_1; sigma_2 for Z). We report
it split into its two parts, since a 4x4 difference would add metres to cosines:

- rotation: Frobenius norm ``||R_est - R_true||_F`` (dimensionless; ~ sqrt(2) x angle [rad]);
- translation: Euclidean norm ``||t_est - t_true||`` [mm].

Conventions: ``A_i = T_base_hand``, ``B_i = T_target_camera``, ``X = T_hand_camera``,
``Z = T_base_target`` (see :mod:`cpc2urdf.identification.handeye.axxb`); poses in metres. The
Kronecker least squares is not unit-invariant (its translation rows scale with the length unit),
so it is also run in millimetres (``kronecker_mm``), the unit Li et al. presumably used.
The truth and the pose distribution are ours (the paper gives neither): X rotates by about 40 deg
and is offset by ~130 mm, Z by ~1 m; hand rotations have random axes and angles U(10, 150) deg,
positions U(-0.5, 0.5) m per axis.

Also measured on identical seeded data (noise on both): our Kronecker and Tsai solvers against
OpenCV's ``CALIB_ROBOT_WORLD_HAND_EYE_LI`` and ``CALIB_HAND_EYE_TSAI`` (ratio of mean errors).

    cpc2urdf study li2010 [--repeats 10] [--seed 0] [--max-poses 30] [--out study_li2010]

Writes ``li2010.md`` (tables, ranking verdict, OpenCV ratios) and ``li2010_fig1{a,b,c}.png``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.identification.handeye.axxb import HandEyeResult
from cpc2urdf.progress import progress
from cpc2urdf.transforms import Array, homogeneous, inverse, matrix_from_rpy

POSE_COUNTS = (3, 4, 5, 6, 8, 10, 12, 15, 20, 25, 30)
CASES = {
    "A": "noise on A only (Fig. 1a)",
    "B": "noise on B only (Fig. 1b)",
    "AB": "noise on A and B (Fig. 1c)",
}
PAPER_METHODS = ("kronecker", "dual_quaternion", "zhuang")  # Li et al.'s claimed order, best first
EXTRA_METHODS = ("kronecker_mm", "refined", "tsai")  # kronecker_mm: Kronecker solved in millimetres
POSITION_NOISE = 1e-3  # [m]: U(-1, 1) mm per position component
ANGLE_NOISE = math.radians(0.5)  # [rad]: U(-0.5, 0.5) deg per Z-Y-Z Euler angle
X_TRUE = homogeneous(matrix_from_rpy(np.radians([10.0, -20.0, 30.0])), [0.030, 0.050, 0.120])
Z_TRUE = homogeneous(matrix_from_rpy(np.radians([5.0, 10.0, 120.0])), [0.800, -0.300, 0.400])
RATIO_POSE_COUNTS = (5, 10, 20)
METRICS = ("X_rot", "X_mm", "Z_rot", "Z_mm")


def perturb_zyz(T: Array, rng: np.random.Generator) -> Array:
    """Li et al.'s noise: U(-0.5, 0.5) deg on each Z-Y-Z Euler angle, U(-1, 1) mm per position
    component. ``T`` shape (4, 4)."""
    zyz = Rotation.from_matrix(T[:3, :3]).as_euler("ZYZ")  # R = Rz(a) Ry(b) Rz(c)
    R = Rotation.from_euler("ZYZ", zyz + rng.uniform(-ANGLE_NOISE, ANGLE_NOISE, 3)).as_matrix()
    return homogeneous(R, T[:3, 3] + rng.uniform(-POSITION_NOISE, POSITION_NOISE, 3))


def simulate(n: int, rng: np.random.Generator, case: str) -> tuple[Array, Array]:
    """``n`` pose pairs ``(A, B)`` with noise per ``case``; each of shape (n, 4, 4)."""
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    ang = rng.uniform(math.radians(10.0), math.radians(150.0), n)
    A = np.array(
        [
            homogeneous(Rotation.from_rotvec(a * t).as_matrix(), rng.uniform(-0.5, 0.5, 3))
            for a, t in zip(axes, ang, strict=True)
        ]
    )
    B = inverse(Z_TRUE)[None] @ A @ X_TRUE[None]
    if "A" in case:
        A = np.array([perturb_zyz(T, rng) for T in A])
    if "B" in case:
        B = np.array([perturb_zyz(T, rng) for T in B])
    return A, B


def pose_errors(X: Array, Z: Array) -> dict[str, float]:
    """Li's metric split: Frobenius rotation difference and translation difference [mm]."""
    return {
        "X_rot": float(np.linalg.norm(X[:3, :3] - X_TRUE[:3, :3])),
        "X_mm": float(np.linalg.norm(X[:3, 3] - X_TRUE[:3, 3]) * 1e3),
        "Z_rot": float(np.linalg.norm(Z[:3, :3] - Z_TRUE[:3, :3])),
        "Z_mm": float(np.linalg.norm(Z[:3, 3] - Z_TRUE[:3, 3]) * 1e3),
    }


def _opencv_li(A: Array, B: Array) -> tuple[Array, Array]:
    import cv2

    C, Hi = inverse(B), inverse(A)  # world2cam = T_camera_target, base2gripper = T_hand_base
    R_bw, t_bw, R_gc, t_gc = cv2.calibrateRobotWorldHandEye(
        list(C[:, :3, :3]),
        list(C[:, :3, 3]),
        list(Hi[:, :3, :3]),
        list(Hi[:, :3, 3]),
        method=cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI,
    )
    return (
        inverse(homogeneous(R_gc, np.asarray(t_gc).ravel())),
        inverse(homogeneous(R_bw, np.asarray(t_bw).ravel())),
    )


def _opencv_tsai(A: Array, B: Array) -> Array:
    import cv2

    C = inverse(B)  # gripper2base = T_base_hand, target2cam = T_camera_target
    R, t = cv2.calibrateHandEye(
        list(A[:, :3, :3]),
        list(A[:, :3, 3]),
        list(C[:, :3, :3]),
        list(C[:, :3, 3]),
        method=cv2.CALIB_HAND_EYE_TSAI,
    )
    return homogeneous(R, np.asarray(t).ravel())


def run_study(
    *,
    repeats: int = 10,
    seed: int = 0,
    pose_counts: tuple[int, ...] = POSE_COUNTS,
    methods: tuple[str, ...] = PAPER_METHODS + EXTRA_METHODS,
    ratio_counts: tuple[int, ...] = RATIO_POSE_COUNTS,
) -> dict[str, Any]:
    """Monte Carlo of Li et al.'s Fig. 1 and the OpenCV comparison.

    Returns:
        ``{"rows": [{case, n, method, X_rot, X_mm, Z_rot, Z_mm, refused}], "ratios": [...]}``:
        mean errors over ``repeats`` (refused runs excluded and counted).
    """
    from cpc2urdf.errors import DegenerateDataError
    from cpc2urdf.identification.handeye.axzb import solve_kronecker
    from cpc2urdf.identification.handeye.solvers import calibrate

    rng = np.random.default_rng(seed)
    rows: list[dict[str, Any]] = []
    jobs = [(c, n) for c in CASES for n in pose_counts]
    for case, n in progress(jobs, "li2010"):
        acc: dict[str, list[dict[str, float]]] = {m: [] for m in methods}
        refused = dict.fromkeys(methods, 0)
        for _ in range(repeats):
            A, B = simulate(n, rng, case)
            for m in methods:
                try:
                    if m == "kronecker_mm":
                        calibrate(A, inverse(B), "kronecker")  # the same checks
                        acc[m].append(pose_errors(*solve_kronecker(A, B, length_unit=1e-3)))
                        continue
                    r = calibrate(A, inverse(B), m)
                except DegenerateDataError:
                    refused[m] += 1
                    continue
                acc[m].append(pose_errors(r.X, r.Z))
        for m in methods:
            row: dict[str, Any] = {"case": case, "n": n, "method": m, "refused": refused[m]}
            for k in METRICS:
                row[k] = float(np.mean([e[k] for e in acc[m]])) if acc[m] else math.nan
            rows.append(row)

    ratios: list[dict[str, Any]] = []
    rng = np.random.default_rng(seed + 1)
    for n in progress(ratio_counts, "li2010 vs OpenCV"):
        ours_k, cv_li, ours_t, cv_t = [], [], [], []
        for _ in range(repeats):
            A, B = simulate(n, rng, "AB")
            ours_k.append(pose_errors(*_xz(calibrate(A, inverse(B), "kronecker"))))
            cv_li.append(pose_errors(*_opencv_li(A, B)))
            ours_t.append(pose_errors(calibrate(A, inverse(B), "tsai").X, Z_TRUE))
            cv_t.append(pose_errors(_opencv_tsai(A, B), Z_TRUE))
        mean = lambda es, k: float(np.mean([e[k] for e in es]))  # noqa: E731
        ratios.append(
            {
                "n": n,
                **{f"kron_{k}": mean(ours_k, k) for k in METRICS},
                **{f"cvli_{k}": mean(cv_li, k) for k in METRICS},
                **{f"tsai_{k}": mean(ours_t, k) for k in ("X_rot", "X_mm")},
                **{f"cvtsai_{k}": mean(cv_t, k) for k in ("X_rot", "X_mm")},
            }
        )
    return {
        "rows": rows,
        "ratios": ratios,
        "repeats": repeats,
        "seed": seed,
        "methods": list(methods),
    }


def _xz(r: HandEyeResult) -> tuple[Array, Array]:
    return r.X, r.Z


def ranking_verdict(result: dict[str, Any]) -> list[str]:
    """Does Kronecker < dual quaternion < quaternion hold? Per case and metric, the number of
    pose counts (n >= 4) where it does, and which method is best on average."""
    rows = result["rows"]
    lines = []
    for case in CASES:
        for k in METRICS:
            ns = sorted({r["n"] for r in rows if r["case"] == case and r["n"] >= 4})
            holds = 0
            means = dict.fromkeys(PAPER_METHODS, 0.0)
            for n in ns:
                v = {r["method"]: r[k] for r in rows if r["case"] == case and r["n"] == n}
                if v["kronecker"] < v["dual_quaternion"] < v["zhuang"]:
                    holds += 1
                for m in PAPER_METHODS:
                    means[m] += v[m] / len(ns)
            order = " < ".join(sorted(PAPER_METHODS, key=lambda m: means[m]))
            lines.append(f"| {case} | {k} | {holds}/{len(ns)} | {order} |")
    return lines


def format_report(result: dict[str, Any]) -> str:
    """Markdown: per case a table of mean errors per pose count and method, the verdict, ratios."""
    rows = result["rows"]
    methods = result["methods"]
    out = [
        f"# Li et al. (2010) Fig. 1 reproduction: {result['repeats']} repeats, seed {result['seed']}",
        "",
        "Cells: X error / Z error, each `rotation ||dR||_F ; translation mm` (means over repeats).",
        "",
    ]
    for case, title in CASES.items():
        out += [
            f"## {title}",
            "",
            "| n | " + " | ".join(methods) + " |",
            "|---:|" + "---|" * len(methods),
        ]
        for n in sorted({r["n"] for r in rows}):
            cells = []
            for m in methods:
                r = next(r for r in rows if r["case"] == case and r["n"] == n and r["method"] == m)
                c = f"{r['X_rot']:.4f}; {r['X_mm']:.2f} / {r['Z_rot']:.4f}; {r['Z_mm']:.2f}"
                if r["refused"]:
                    c += f" ({r['refused']} refused)"
                cells.append(c)
            out.append(f"| {n} | " + " | ".join(cells) + " |")
        out.append("")
    out += [
        "## Ranking (Li et al.: Kronecker < dual quaternion < quaternion)",
        "",
        "| noise | error | pose counts where it holds | order of the means over n >= 4 |",
        "|---|---|---|---|",
        *ranking_verdict(result),
        "",
    ]
    out += [
        "## Ours against OpenCV on identical seeded data (noise on A and B)",
        "",
        "Ratio = our mean error / OpenCV's mean error (below 1: ours is more accurate).",
        "",
        "| n | Kronecker/LI X rot | X mm | Z rot | Z mm | Tsai/TSAI X rot | X mm |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["ratios"]:
        kr = [r[f"kron_{k}"] / r[f"cvli_{k}"] for k in METRICS]
        ts = [r[f"tsai_{k}"] / r[f"cvtsai_{k}"] for k in ("X_rot", "X_mm")]
        out.append(f"| {r['n']} | " + " | ".join(f"{v:.3f}" for v in kr + ts) + " |")
    out += [
        "",
        "Absolute mean errors (rot ||dR||_F; mm):",
        "",
        "| n | ours Kronecker X | OpenCV LI X | ours Kronecker Z | OpenCV LI Z | ours Tsai X | OpenCV TSAI X |",
        "|---:|---|---|---|---|---|---|",
    ]
    for r in result["ratios"]:
        f = lambda p, a, r=r: f"{r[p + '_' + a + '_rot']:.4f}; {r[p + '_' + a + '_mm']:.2f}"  # noqa: E731
        out.append(
            f"| {r['n']} | {f('kron', 'X')} | {f('cvli', 'X')} | {f('kron', 'Z')} | {f('cvli', 'Z')} | "
            f"{f('tsai', 'X')} | {f('cvtsai', 'X')} |"
        )
    return "\n".join(out) + "\n"


def plot(result: dict[str, Any], folder: Path) -> list[Path]:
    """One PNG per noise case (Fig. 1a-c): 2 x 2 panels, X/Z rotation/translation vs n."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    paths = []
    for letter, (case, title) in zip("abc", CASES.items(), strict=True):
        fig, axes = plt.subplots(2, 2, figsize=(10, 7))
        for ax, k, label in zip(
            axes.ravel(),
            METRICS,
            [
                "X rotation ||dR||_F",
                "X translation [mm]",
                "Z rotation ||dR||_F",
                "Z translation [mm]",
            ],
            strict=True,
        ):
            for m in result["methods"]:
                rr = sorted(
                    (r for r in rows if r["case"] == case and r["method"] == m),
                    key=lambda r: r["n"],
                )
                ax.plot(
                    [r["n"] for r in rr],
                    [r[k] for r in rr],
                    "o-" if m in PAPER_METHODS else ".--",
                    label=m,
                    ms=4,
                )
            ax.set_yscale("log")
            ax.set_xlabel("number of poses")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3, which="both")
        axes[0, 0].legend(fontsize=8)
        fig.suptitle(
            f"Li et al. 2010, {title}: U(±1 mm), U(±0.5°) on ZYZ angles, "
            f"{result['repeats']} repeats"
        )
        fig.tight_layout()
        path = folder / f"li2010_fig1{letter}.png"
        tmp = folder / f".li2010_fig1{letter}.tmp.png"
        fig.savefig(tmp, dpi=110)
        plt.close(fig)
        tmp.replace(path)
        paths.append(path)
    return paths


def main(argv: list[str] | None = None) -> int:
    """``cpc2urdf study li2010 [--repeats N] [--seed S] [--max-poses M] [--out DIR]``."""
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import make_folder, write_atomic

    parser = OneLineParser(
        prog="cpc2urdf study li2010",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--repeats", type=int, default=10, help="repeats per pose count (default 10, as the paper)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--max-poses", type=int, default=30, help="largest pose count (default 30)")
    parser.add_argument(
        "--out", default="study_li2010", help="output folder (default study_li2010)"
    )
    args = parser.parse_args(argv)
    if args.repeats < 1:
        raise ConfigurationError(f"--repeats must be >= 1, got {args.repeats}")
    if args.max_poses < 3:
        raise ConfigurationError(f"--max-poses must be >= 3, got {args.max_poses}")
    out = Path(args.out)
    make_folder(out)
    counts = tuple(n for n in POSE_COUNTS if n <= args.max_poses) or (3,)
    ratio_counts = tuple(n for n in RATIO_POSE_COUNTS if n <= args.max_poses) or (args.max_poses,)
    result = run_study(
        repeats=args.repeats, seed=args.seed, pose_counts=counts, ratio_counts=ratio_counts
    )
    report = format_report(result)
    print(report, end="")
    write_atomic(out / "li2010.md", report)
    pngs = plot(result, out)
    print(f"wrote {out / 'li2010.md'} and {', '.join(str(p) for p in pngs)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = [
    "format_report",
    "main",
    "plot",
    "pose_errors",
    "ranking_verdict",
    "run_study",
    "simulate",
]
