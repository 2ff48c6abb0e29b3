"""Study: Shih et al. Fig. 11, positioning error vs measurements per joint and observation noise.

For each noise level σ (Fig. 10 model: N(0, σ) mm on each translation entry and a rotation about a
random axis by N(0, σ) degrees, the paper's single σ_O) and each number M of measurements per joint
(M = 2..15), several seeded trials each: simulate the IIS-head (a true robot = nominal + random
geometric error, :func:`cpc2urdf.identification.simulation.stage1_experiment.simulate_experiment`), identify it in
closed form (sec. 4.2), and compute the mean positioning error (Euclidean distance between the true
and the predicted plate origins, both plates) over held-out configurations drawn from the
calibration range. A noise-free run in the same study is the reference (the method is exact, so
every millimetre comes from the noise).

    cpc2urdf study fig11 [--M 2:15] [--sigmas 0.1,0.25,0.5,1.0] [--trials 10] [--seed 0] [--out study_fig11]

Writes ``fig11.md`` (table and verdict on the paper's conclusion), ``fig11.json`` and ``fig11.png``.
The trial seed fixes the true robot and held-out set, so every (σ, M) cell sees the same robots.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.progress import progress

SIGMAS_MM = (0.1, 0.25, 0.5, 1.0)  # [mm], with the same number of degrees (the paper's σ_O)
M_VALUES = tuple(range(2, 16))
TRIALS = 10  # "Each data point is the average of ten random trials" (sec. 6)
PAPER_SIGMA_MAX = 0.5  # [mm]: "the observation error should be controlled below 0.5mm"
PAPER_M_MIN = 5  # "and the number of measurement should be more than five"
PAPER_TARGET = 1.0  # [mm]: "for the requirement of 1mm calibration accuracy"
COMPARE_M, COMPARE_SIGMA = 9, 0.5  # the paper's choice of M, and its rig's accuracy [mm]


def trial_error(
    robot: str, seed: int, M: int, sigma_mm: float, n_heldout: int
) -> tuple[float, float]:
    """One simulate-identify-test run: (mean held-out positioning error [m], identification time [s])."""
    from cpc2urdf.identification.kinematics.closed_form import identify_closed_form
    from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment

    truth, measured, heldout = simulate_experiment(
        robot,
        seed=seed,
        M=M,
        noise="fig10" if sigma_mm > 0 else "none",
        sigma_t=sigma_mm * 1e-3,
        sigma_r=math.radians(sigma_mm),
        n_heldout=n_heldout,
    )
    start = time.perf_counter()
    model, _ = identify_closed_form(measured)
    elapsed = time.perf_counter() - start
    frames = heldout.frames
    T = model.fk(heldout.q, frames)
    errors = [np.linalg.norm(T[f][:, :3, 3] - heldout.poses[f][:, :3, 3], axis=1) for f in frames]
    return float(np.mean(np.concatenate(errors))), elapsed


def shared_vs_paper(
    robot: str, seed: int, M: int, sigma_mm: float, n_heldout: int
) -> tuple[float, float]:
    """Mean held-out error [m] of the tree model (one tilt axis, 32 parameters) and of the paper's
    eq. (15) model (one tilt axis frame per branch, ``l_3L`` and ``l_3R``: 34), same data."""
    from cpc2urdf.identification.kinematics.closed_form import (
        identify_closed_form,
        identify_paper_branches,
    )
    from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment

    _, measured, heldout = simulate_experiment(
        robot,
        seed=seed,
        M=M,
        noise="fig10",
        sigma_t=sigma_mm * 1e-3,
        sigma_r=math.radians(sigma_mm),
        n_heldout=n_heldout,
    )
    tree, _ = identify_closed_form(measured)
    paper = identify_paper_branches(measured)
    e_tree, e_paper = [], []
    for f in heldout.frames:
        p = heldout.poses[f][:, :3, 3]
        e_tree.append(np.linalg.norm(tree.fk(heldout.q, [f])[f][:, :3, 3] - p, axis=1))
        e_paper.append(np.linalg.norm(paper[f].fk(heldout.q, [f])[f][:, :3, 3] - p, axis=1))
    return float(np.mean(np.concatenate(e_tree))), float(np.mean(np.concatenate(e_paper)))


def run_study(
    *,
    M_values: tuple[int, ...] = M_VALUES,
    sigmas_mm: tuple[float, ...] = SIGMAS_MM,
    trials: int = TRIALS,
    seed: int = 0,
    n_heldout: int = 50,
    robot: str = "iis_head",
) -> dict[str, Any]:
    """Run the grid; returns ``{"rows": [{sigma_mm, M, mean_mm, std_mm, max_mm}], ...}``."""
    cells = [(s, M) for s in sigmas_mm for M in M_values]
    rows = []
    times: list[float] = []
    for sigma, M in progress(cells, "study fig11"):
        errs = []
        for t in range(trials):
            e, dt = trial_error(robot, seed + t, M, sigma, n_heldout)
            errs.append(e)
            times.append(dt)
        a = np.array(errs) * 1e3
        rows.append(
            {
                "sigma_mm": sigma,
                "M": M,
                "mean_mm": float(a.mean()),
                "std_mm": float(a.std()),
                "max_mm": float(a.max()),
            }
        )
    reference = [
        trial_error(robot, seed + t, min(M_values), 0.0, n_heldout)[0] * 1e3 for t in range(trials)
    ]
    # 32 vs 34 parameters (docs/identification.md on l_3R): same data, the paper's M = 9, sigma = 0.5 mm.
    pairs = (
        np.array(
            [
                shared_vs_paper(robot, seed + t, COMPARE_M, COMPARE_SIGMA, n_heldout)
                for t in range(max(trials, 20))
            ]
        )
        * 1e3
    )
    claim = [r for r in rows if r["sigma_mm"] <= PAPER_SIGMA_MAX and r["M"] >= PAPER_M_MIN]
    return {
        "rows": rows,
        "shared_vs_paper": {
            "M": COMPARE_M,
            "sigma_mm": COMPARE_SIGMA,
            "trials": len(pairs),
            "tree_32_mean_mm": float(pairs[:, 0].mean()),
            "tree_32_std_mm": float(pairs[:, 0].std()),
            "paper_34_mean_mm": float(pairs[:, 1].mean()),
            "paper_34_std_mm": float(pairs[:, 1].std()),
            "tree_better_fraction": float(np.mean(pairs[:, 0] < pairs[:, 1])),
        },
        "reference_noise_free_max_mm": float(max(reference)),
        "identification_time_s": {"mean": float(np.mean(times)), "max": float(np.max(times))},
        "paper_claim_cells": len(claim),
        "paper_claim_holds": bool(claim) and all(r["mean_mm"] < PAPER_TARGET for r in claim),
        "paper_claim_worst_mm": max((r["mean_mm"] for r in claim), default=None),
        "trials": trials,
        "seed": seed,
        "n_heldout": n_heldout,
        "robot": robot,
    }


def format_table(result: dict[str, Any]) -> str:
    """Markdown: mean error [mm] (± std over trials) per M and σ, then the verdict."""
    rows = result["rows"]
    sigmas = sorted({r["sigma_mm"] for r in rows})
    Ms = sorted({r["M"] for r in rows})
    cell = {(r["sigma_mm"], r["M"]): r for r in rows}
    lines = [
        f"Mean held-out positioning error [mm] of the closed-form identification of {result['robot']}, "
        f"{result['trials']} seeded trials per cell (seed {result['seed']}), {result['n_heldout']} held-out "
        "configurations x 2 plates per trial; Fig. 10 noise σ mm per translation entry and σ deg about a "
        "random axis.",
        "",
        "| M | " + " | ".join(f"σ = {s:g} mm" for s in sigmas) + " |",
        "|---:|" + "---:|" * len(sigmas),
    ]
    for M in Ms:
        lines.append(
            f"| {M} | "
            + " | ".join(
                f"{cell[(s, M)]['mean_mm']:.3f} ± {cell[(s, M)]['std_mm']:.3f}" for s in sigmas
            )
            + " |"
        )
    if not result["paper_claim_cells"]:
        verdict = f"cannot be checked (no cell with σ ≤ {PAPER_SIGMA_MAX} mm and M ≥ {PAPER_M_MIN})"
        worst = ""
    else:
        verdict = "holds here" if result["paper_claim_holds"] else "does NOT hold here"
        worst = (
            f": worst mean error over those {result['paper_claim_cells']} cells is "
            f"{result['paper_claim_worst_mm']:.3f} mm"
        )
    c = result["shared_vs_paper"]
    lines += [
        "",
        f"One shared tilt axis (tree, 32 parameters) vs the paper's eq. (15) (own l_3 per branch, 34), "
        f"same data, M = {c['M']}, σ = {c['sigma_mm']:g} mm, {c['trials']} trials: "
        f"{c['tree_32_mean_mm']:.3f} ± {c['tree_32_std_mm']:.3f} mm vs "
        f"{c['paper_34_mean_mm']:.3f} ± {c['paper_34_std_mm']:.3f} mm; the tree is better in "
        f"{c['tree_better_fraction'] * 100:.0f}% of the trials.",
        "",
        f"Reference (same run, noise-free data): largest error {result['reference_noise_free_max_mm']:.2e} mm.",
        f"Identification time: mean {result['identification_time_s']['mean'] * 1e3:.1f} ms, "
        f"max {result['identification_time_s']['max'] * 1e3:.1f} ms.",
        f"The paper's conclusion (σ ≤ {PAPER_SIGMA_MAX} mm and M ≥ {PAPER_M_MIN} give < {PAPER_TARGET:g} mm) "
        f"{verdict}{worst}.",
    ]
    return "\n".join(lines) + "\n"


def plot(result: dict[str, Any], path: Path) -> None:
    """Fig. 11: mean error vs M, one line per σ (error bars: std over trials)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for s in sorted({r["sigma_mm"] for r in result["rows"]}):
        rs = [r for r in result["rows"] if r["sigma_mm"] == s]
        ax.errorbar(
            [r["M"] for r in rs],
            [r["mean_mm"] for r in rs],
            yerr=[r["std_mm"] for r in rs],
            marker="o",
            capsize=3,
            label=f"σ = {s:g} mm / {s:g}°",
        )
    ax.axhline(PAPER_TARGET, color="k", ls="--", lw=1, label="1 mm")
    ax.axvline(PAPER_M_MIN, color="grey", ls=":", lw=1)
    ax.set_xlabel("measurements per joint M")
    ax.set_ylabel("mean positioning error [mm]")
    ax.set_title(f"Closed-form identification of {result['robot']} (cf. Shih et al. Fig. 11)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _ints(text: str) -> tuple[int, ...]:
    if ":" in text:
        lo, hi = (int(v) for v in text.split(":"))
        return tuple(range(lo, hi + 1))
    return tuple(int(v) for v in text.split(","))


def main(argv: list[str]) -> int:
    """``cpc2urdf study fig11 [options]``."""
    from cpc2urdf.errors import Cpc2UrdfError
    from cpc2urdf.files.jsonio import make_folder, write_atomic, write_json

    p = OneLineParser(prog="cpc2urdf study fig11", description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--M", default="2:15", help="measurements per joint: LO:HI or a,b,c (default 2:15)"
    )
    p.add_argument(
        "--sigmas",
        default="0.1,0.25,0.5,1.0",
        help="noise levels [mm and deg] (default 0.1,0.25,0.5,1.0)",
    )
    p.add_argument(
        "--trials", type=int, default=TRIALS, help="seeded trials per point (default 10)"
    )
    p.add_argument("--seed", type=int, default=0, help="first trial seed (default 0)")
    p.add_argument(
        "--heldout", type=int, default=50, help="held-out configurations per trial (default 50)"
    )
    p.add_argument(
        "--robot", default="iis_head", help="robot with nominal geometry (default iis_head)"
    )
    p.add_argument("--out", default="study_fig11", help="output folder (default study_fig11)")
    args = p.parse_args(argv)
    try:
        M_values = _ints(args.M)
        sigmas = tuple(float(v) for v in args.sigmas.split(","))
    except ValueError as e:
        raise Cpc2UrdfError(f"--M/--sigmas: {e}") from e
    if min(M_values) < 2 or args.trials < 1 or args.heldout < 1 or min(sigmas) < 0:
        raise Cpc2UrdfError("need M >= 2, --trials >= 1, --heldout >= 1 and sigmas >= 0")
    from cpc2urdf.files.robot_ref import load_robot

    load_robot(
        args.robot
    ).nominal_model()  # a robot that is missing or has no nominal geometry: before --out
    out = make_folder(args.out)
    result = run_study(
        M_values=M_values,
        sigmas_mm=sigmas,
        trials=args.trials,
        seed=args.seed,
        n_heldout=args.heldout,
        robot=args.robot,
    )
    table = format_table(result)
    write_atomic(out / "fig11.md", table)
    write_json(out / "fig11.json", result)
    plot(result, out / "fig11.png")
    print(table)
    print(f"wrote {out / 'fig11.md'}, {out / 'fig11.json'}, {out / 'fig11.png'}")
    return 0


__all__ = [
    "M_VALUES",
    "PAPER_M_MIN",
    "PAPER_SIGMA_MAX",
    "PAPER_TARGET",
    "SIGMAS_MM",
    "TRIALS",
    "format_table",
    "main",
    "plot",
    "run_study",
    "shared_vs_paper",
    "trial_error",
]
