"""Study: plate pose error of the stereo rig vs pixel noise, at the paper's geometry (sec. 6).

Shih et al. measure the plates with a 600 mm-baseline rig "which provides the accuracy of 0.5 mm
if the object distance is approximately 1.5 meter". This study simulates that measurement
(:func:`cpc2urdf.identification.simulation.measurement_noise.stereo_noise`: project the nine circle centres into both
cameras, add N(0, sigma_px) to each pixel coordinate, triangulate, register the layout) for the
IIS-head's plates at random configurations inside the calibration range, placed in front of the
default rig exactly as ``cpc2urdf simulate`` places them, and reports per pixel noise:

- the 3D error of one triangulated circle centre (the rig's point accuracy, the paper's 0.5 mm),
  next to its first-order prediction ``sigma_z = z^2 sqrt(2) sigma_px / (f B)`` for depth (the reference
  computed in the same run);
- the plate position error (the origin is the centroid of nine circles) and orientation error;
- the equivalent Fig. 10 parameters: RMS per translation entry [mm] and RMS rotation angle [deg].

    cpc2urdf study stereo [--samples 2000] [--seed 0] [--out study_stereo]

Writes ``stereo_noise.md`` (table) and ``stereo_noise.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.progress import progress

PIXEL_SIGMAS = (0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 0.75, 1.0)  # [px]
PAPER_ACCURACY = 0.5e-3  # [m]: sec. 6, the rig's accuracy at ~1.5 m


def run_study(
    *,
    samples: int = 2000,
    seed: int = 0,
    pixel_sigmas: tuple[float, ...] = PIXEL_SIGMAS,
    robot: str = "iis_head",
) -> dict[str, Any]:
    """Monte Carlo of the stereo noise model; returns rows of errors per pixel noise.

    Args:
        samples: Random configurations (each measures every plate) per pixel noise.
        seed: Random seed.
        pixel_sigmas: Pixel noise levels [px].
        robot: Robot whose plates are measured (placed as ``cpc2urdf simulate`` places it).

    Returns:
        ``{"rows": [...], "rig": {...}, "fit": {...}}``; errors in mm and deg.
    """
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.simulation.design import (
        calibration_ranges,
        measured_frames,
        random_configurations,
    )
    from cpc2urdf.identification.simulation.measurement_noise import stereo_noise
    from cpc2urdf.identification.simulation.placement import place_in_front_of_rig
    from cpc2urdf.identification.vision.stereo import StereoRig
    from cpc2urdf.transforms import rotation_error

    rng = np.random.default_rng(seed)
    rig = StereoRig.verged()
    nominal = load_robot(robot).nominal_model()
    s = nominal.structure
    frames = measured_frames(s)
    q = random_configurations(calibration_ranges(s), samples, rng)
    model = nominal.with_params(world_to_base=place_in_front_of_rig(nominal, rig, q, frames))
    true = model.fk(q, frames)
    f = float(rig.K1[0, 0])
    B = rig.baseline
    rows = []
    for sigma in progress(pixel_sigmas, "study stereo"):
        circle, pos, ang, entry, depth, depth_pred = [], [], [], [], [], []
        for name in frames:
            layout = np.array(s.frame(name).layout)
            T = true[name]
            T_meas, p_meas = stereo_noise(T, layout, rig, sigma, rng)
            p_true = np.einsum("nij,kj->nki", T[:, :3, :3], layout) + T[:, None, :3, 3]
            circle.append(np.linalg.norm(p_meas - p_true, axis=-1).ravel())
            # Depth error vs the first-order formula z^2 sigma_d / (f B); the disparity is a
            # difference of two noisy pixel coordinates, so sigma_d = sqrt(2) sigma_px.
            z = p_true[..., 2]
            depth.append((p_meas[..., 2] - z).ravel())
            depth_pred.append((z**2 * math.sqrt(2) * sigma / (f * B)).ravel())
            pos.append(np.linalg.norm(T_meas[:, :3, 3] - T[:, :3, 3], axis=1))
            entry.append((T_meas[:, :3, 3] - T[:, :3, 3]).ravel())
            ang.append(rotation_error(T_meas[:, :3, :3], T[:, :3, :3]))
        c, p, a, e = (np.concatenate(x) for x in (circle, pos, ang, entry))
        d, dp = np.concatenate(depth), np.concatenate(depth_pred)
        rows.append(
            {
                "pixel_sigma": sigma,
                "circle_rms_mm": float(np.sqrt(np.mean(c**2)) * 1e3),
                "depth_rms_mm": float(np.sqrt(np.mean(d**2)) * 1e3),
                "depth_pred_mm": float(np.sqrt(np.mean(dp**2)) * 1e3),
                "plate_pos_rms_mm": float(np.sqrt(np.mean(p**2)) * 1e3),
                "plate_entry_rms_mm": float(np.sqrt(np.mean(e**2)) * 1e3),
                "plate_rot_rms_deg": float(np.degrees(np.sqrt(np.mean(a**2)))),
            }
        )
    # Errors are linear in sigma_px (first order): the slopes answer "which pixel noise is 0.5 mm".
    sig = np.array([r["pixel_sigma"] for r in rows])

    def slope(key: str) -> float:
        v = np.array([r[key] for r in rows])
        return float(sig @ v / (sig @ sig))

    distances = np.linalg.norm(np.concatenate([true[n][:, :3, 3] for n in frames]), axis=1)
    fit = {
        k: slope(k)
        for k in ("circle_rms_mm", "plate_pos_rms_mm", "plate_entry_rms_mm", "plate_rot_rms_deg")
    }
    return {
        "rows": rows,
        "fit": fit,
        "sigma_for_paper_circle_px": PAPER_ACCURACY * 1e3 / fit["circle_rms_mm"],
        "sigma_for_fig10_entry_px": PAPER_ACCURACY * 1e3 / fit["plate_entry_rms_mm"],
        "rig": {
            "baseline_m": B,
            "focal_px": f,
            "image_size": list(rig.image_size),
            "plate_distance_m": [float(distances.min()), float(distances.max())],
        },
        "samples": samples,
        "seed": seed,
    }


def format_table(result: dict[str, Any]) -> str:
    """The result as a Markdown table with a short conclusion."""
    rig = result["rig"]
    lines = [
        f"Stereo rig: baseline {rig['baseline_m'] * 1e3:.0f} mm, f = {rig['focal_px']:.0f} px, "
        f"{rig['image_size'][0]}x{rig['image_size'][1]} px; IIS-head plates "
        f"{rig['plate_distance_m'][0]:.2f}-{rig['plate_distance_m'][1]:.2f} m away; "
        f"{result['samples']} configurations x 2 plates per row, seed {result['seed']}.",
        "",
        "| pixel σ [px] | circle 3D RMS [mm] | depth RMS [mm] | depth z²√2σ/(fB) [mm] | plate pos. RMS [mm] "
        "| per entry RMS [mm] | plate rot. RMS [deg] |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['pixel_sigma']:.2f} | {r['circle_rms_mm']:.3f} | {r['depth_rms_mm']:.3f} | "
            f"{r['depth_pred_mm']:.3f} | {r['plate_pos_rms_mm']:.3f} | {r['plate_entry_rms_mm']:.3f} | "
            f"{r['plate_rot_rms_deg']:.3f} |"
        )
    fit = result["fit"]
    lines += [
        "",
        f"Per pixel of noise: circle {fit['circle_rms_mm']:.2f} mm, plate position {fit['plate_pos_rms_mm']:.2f} mm "
        f"({fit['plate_entry_rms_mm']:.2f} mm per entry), plate rotation {fit['plate_rot_rms_deg']:.2f} deg.",
        f"The paper's 0.5 mm rig accuracy (one circle) corresponds to σ ≈ {result['sigma_for_paper_circle_px']:.2f} px; "
        f"Fig. 10's σ_t = 0.5 mm per plate-position entry to σ ≈ {result['sigma_for_fig10_entry_px']:.2f} px, "
        f"which comes with {fit['plate_rot_rms_deg'] * result['sigma_for_fig10_entry_px']:.1f} deg of rotation noise.",
    ]
    return "\n".join(lines) + "\n"


def plot(result: dict[str, Any], path: Path) -> None:
    """Errors vs pixel noise, with the paper's 0.5 mm marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    sig = [r["pixel_sigma"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    ax1.plot(sig, [r["circle_rms_mm"] for r in rows], "o-", label="one circle, 3D RMS")
    ax1.plot(sig, [r["depth_pred_mm"] for r in rows], "k:", label="depth z²√2σ/(fB) (first order)")
    ax1.plot(sig, [r["plate_pos_rms_mm"] for r in rows], "s-", label="plate origin, 3D RMS")
    ax1.plot(sig, [r["plate_entry_rms_mm"] for r in rows], "^-", label="plate origin, per entry")
    ax1.axhline(0.5, color="r", lw=0.8, ls="--", label="paper: 0.5 mm")
    ax1.set_xlabel("pixel noise σ [px]")
    ax1.set_ylabel("error [mm]")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    ax2.plot(sig, [r["plate_rot_rms_deg"] for r in rows], "o-")
    ax2.set_xlabel("pixel noise σ [px]")
    ax2.set_ylabel("plate orientation RMS error [deg]")
    ax2.grid(alpha=0.3)
    rig = result["rig"]
    fig.suptitle(
        f"Stereo plate measurement, baseline {rig['baseline_m'] * 1e3:.0f} mm, "
        f"plates {rig['plate_distance_m'][0]:.2f}-{rig['plate_distance_m'][1]:.2f} m"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """``cpc2urdf study stereo [--samples N] [--seed S] [--out DIR]``."""
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import make_folder, write_atomic

    parser = OneLineParser(
        prog="cpc2urdf study stereo",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--samples", type=int, default=2000, help="configurations per pixel noise (default 2000)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--out", default="study_stereo", help="output folder (default study_stereo)"
    )
    args = parser.parse_args(argv)
    if args.samples < 1:
        raise ConfigurationError(f"--samples must be >= 1, got {args.samples}")
    out = Path(args.out)
    make_folder(out)
    result = run_study(samples=args.samples, seed=args.seed)
    table = format_table(result)
    print(table, end="")
    write_atomic(out / "stereo_noise.md", table)
    png = out / "stereo_noise.png"
    tmp = out / ".stereo_noise.tmp.png"
    plot(result, tmp)
    tmp.replace(png)
    print(f"wrote {out / 'stereo_noise.md'} and {png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["format_table", "main", "plot", "run_study"]
