"""Study: which pose pairs an ``A X = X B`` solver needs (all pairs, ours, consecutive only).

The ``A X = X B`` solvers (Tsai-Lenz, Park-Martin, Daniilidis) take relative motions between pose
pairs. All ``N(N-1)/2`` pairs (OpenCV's choice) cost O(N^2) time and memory: 499,500 motions at
1,000 poses. :func:`~cpc2urdf.identification.handeye.axxb.motion_pairs` keeps all pairs up to 31
poses and pairs each pose with 15 others spread over the sequence beyond (O(N)). This study
measures, on identical seeded noisy data, the error of X with

- ``all``: every pair ``i < j`` (the solvers before, and OpenCV),
- ``ours``: :func:`~cpc2urdf.identification.handeye.axxb.motion_pairs` (the solvers now),
- ``consecutive``: ``(i, i + 1)`` only (what many tools do with a recorded sequence),

and OpenCV's all-pairs ``CALIB_HAND_EYE_TSAI`` for reference, on two pose distributions:

- ``random``: Li et al. 2010's setup (:mod:`cpc2urdf.studies.li2010`: random axes, angles
  U(10, 150) deg, noise U(-1, 1) mm / U(-0.5, 0.5) deg Z-Y-Z on A and B);
- ``stream``: the same noise on a smooth recorded path (rotation vector and position each a sum
  of two sinusoids over the sequence, amplitude ~1 rad / 0.3 m), so that consecutive poses
  are close.

    cpc2urdf study handeye-pairs [--repeats 20] [--seed 0] [--poses 40 60 100 200]

Prints a markdown table of mean X rotation (``||dR||_F``) and translation [mm] errors.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.identification.handeye.axxb import (
    motion_pairs,
    relative_motions,
    solve_daniilidis,
    solve_park_martin,
    solve_tsai,
)
from cpc2urdf.studies.li2010 import X_TRUE, Z_TRUE, _opencv_tsai, perturb_zyz, simulate
from cpc2urdf.transforms import Array, homogeneous, inverse

SOLVERS = {"tsai": solve_tsai, "park_martin": solve_park_martin, "daniilidis": solve_daniilidis}
PAIRINGS = ("all", "ours", "consecutive")


def stream(n: int, rng: np.random.Generator) -> tuple[Array, Array]:
    """``n`` poses ``(A, B)`` along a smooth path, Li et al.'s noise on both."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    f = rng.uniform(0.5, 2.0, (2, 6))
    ph = rng.uniform(0.0, 2.0 * math.pi, (2, 6))
    w = np.sin(2.0 * math.pi * f[0] * s + ph[0]) + 0.5 * np.sin(2.0 * math.pi * f[1] * s + ph[1])
    A = np.array(
        [
            homogeneous(Rotation.from_rotvec(0.8 * r).as_matrix(), 0.25 * p)
            for r, p in zip(w[:, :3], w[:, 3:], strict=True)
        ]
    )
    B = inverse(Z_TRUE)[None] @ A @ X_TRUE[None]
    return np.array([perturb_zyz(T, rng) for T in A]), np.array([perturb_zyz(T, rng) for T in B])


def _pairs(kind: str, n: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    if kind == "all":
        return np.triu_indices(n, k=1)
    if kind == "ours":
        return motion_pairs(n)
    i = np.arange(n - 1, dtype=np.intp)
    return i, i + 1


def run(repeats: int, seed: int, poses: list[int]) -> list[str]:
    """Rows of the markdown table: distribution, n, pairing, then per solver X rot; X mm."""
    rng = np.random.default_rng(seed)
    out = []
    for dist in ("random", "stream"):
        for n in poses:
            err: dict[tuple[str, str], list[tuple[float, float]]] = {}
            for _ in range(repeats):
                A, B = simulate(n, rng, "AB") if dist == "random" else stream(n, rng)
                C = inverse(B)  # T_camera_target
                for kind in PAIRINGS:
                    Am, Bm = relative_motions(A, C, _pairs(kind, n))
                    for name, solve in SOLVERS.items():
                        X = solve(Am, Bm)
                        err.setdefault((kind, name), []).append(
                            (
                                float(np.linalg.norm(X[:3, :3] - X_TRUE[:3, :3])),
                                float(np.linalg.norm(X[:3, 3] - X_TRUE[:3, 3]) * 1e3),
                            )
                        )
                X = _opencv_tsai(A, B)
                err.setdefault(("opencv", "tsai"), []).append(
                    (
                        float(np.linalg.norm(X[:3, :3] - X_TRUE[:3, :3])),
                        float(np.linalg.norm(X[:3, 3] - X_TRUE[:3, 3]) * 1e3),
                    )
                )
            for kind in (*PAIRINGS, "opencv"):
                cells = []
                for name in SOLVERS:
                    e = np.array(err.get((kind, name), [(math.nan, math.nan)]))
                    cells.append(f"{e[:, 0].mean():.4f}; {e[:, 1].mean():.2f}")
                npairs = len(_pairs("all" if kind == "opencv" else kind, n)[0])
                out.append(f"| {dist} | {n} | {kind} ({npairs}) | " + " | ".join(cells) + " |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = OneLineParser(prog="cpc2urdf study handeye-pairs", description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--poses", type=int, nargs="+", default=[40, 60, 100, 200])
    a = ap.parse_args(argv)
    print(
        f"mean X error over {a.repeats} repeats (seed {a.seed}), cells ||dR||_F; mm (opencv: its TSAI)\n"
    )
    print("| poses | n | pairs | " + " | ".join(SOLVERS) + " |")
    print("|---|---:|---|" + "---|" * len(SOLVERS))
    for row in run(a.repeats, a.seed, a.poses):
        print(row, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
