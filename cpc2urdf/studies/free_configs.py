"""Free configurations vs the one-joint-at-a-time protocol: refined held-out error, same number of records.

``cpc2urdf study free-configs [--seeds 20] [--M 9] [--out study_free_configs]``

Per seed: a true robot (the nominal plus 1 mm / 0.5 deg on every CPC placement, :mod:`truth`), the
one-joint-at-a-time protocol with M readings per joint (N = 1 + n M records, the closed form's
design) and N configurations drawn uniformly in the calibration ranges, each measured twice:
plate poses with Fig. 10 noise (sigma_t, sigma_r) and marker points (two unknown markers per
plate, ``sigma_p`` per coordinate). Each set is identified with the refinement the CLI runs
(``refined``): the protocol's starts from the closed form (poses) or the circle-point analysis
(points), the random sets' from the nominal model placed in world (the start each used is
recorded). Score: RMS 3-D error of the plate origins (poses) or marker positions (points) at
held-out random configurations against the truth. Writes ``free_configs.md``, ``.json`` and
``.png``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.progress import progress

DESIGNS = ("protocol", "random")
KINDS = ("poses", "points")


def _heldout_rms(
    model: Any,
    truth: Any,
    q: np.ndarray,
    positions: dict[str, tuple[str, np.ndarray]] | None,
    true_positions: dict[str, tuple[str, np.ndarray]] | None,
    frames: list[str],
) -> float:
    if positions is None or true_positions is None:
        T, Tt = model.fk(q, frames), truth.fk(q, frames)
        d = [np.linalg.norm(T[f][:, :3, 3] - Tt[f][:, :3, 3], axis=1) for f in frames]
    else:
        fr = list(dict.fromkeys(f for f, _ in true_positions.values()))
        T, Tt = model.fk(q, fr), truth.fk(q, fr)
        d = []
        for m, (f, p) in true_positions.items():
            pm = positions[m][1]
            d.append(
                np.linalg.norm(
                    (T[f][:, :3, :3] @ pm + T[f][:, :3, 3])
                    - (Tt[f][:, :3, :3] @ p + Tt[f][:, :3, 3]),
                    axis=1,
                )
            )
    return float(np.sqrt(np.mean(np.concatenate(d) ** 2)))


def run_trial(
    seed: int,
    M: int,
    sigma_t: float,
    sigma_r: float,
    sigma_p: float,
    n_heldout: int,
    robot: str = "iis_head",
) -> dict[str, Any]:
    """One seed: both designs, both kinds of data; held-out RMS [m], the start used, seconds."""
    import time

    from cpc2urdf.files.measurements import MeasurementSet
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.kinematics.methods import identify_refined
    from cpc2urdf.identification.kinematics.points.point_identify import (
        identify_points,
        marker_positions,
    )
    from cpc2urdf.identification.simulation.design import (
        measured_frames,
        protocol_q,
        random_configurations,
    )
    from cpc2urdf.identification.simulation.marker_points import place_markers_on, simulate_markers
    from cpc2urdf.identification.simulation.measurement_noise import fig10_noise
    from cpc2urdf.identification.simulation.truth import perturbed_model

    nominal = load_robot(robot).nominal_model()
    streams = np.random.SeedSequence(seed).spawn(4)
    g_truth, g_q, g_noise, g_held = (np.random.default_rng(s) for s in streams)
    truth = perturbed_model(nominal, g_truth, 1e-3, math.radians(0.5))
    s = truth.structure
    frames = measured_frames(s)
    markers = place_markers_on(truth, {f: 2 for f in frames}, g_truth)
    q_prot = protocol_q(truth, M)
    ranges = s.calibration_ranges()
    designs = {"protocol": q_prot, "random": random_configurations(ranges, len(q_prot), g_q)}
    q_held = random_configurations(ranges, n_heldout, g_held)
    out: dict[str, Any] = {"seed": seed, "records": len(q_prot)}
    for name, q in designs.items():
        T = truth.fk(q, frames)
        poses = {f: fig10_noise(T[f], sigma_t, sigma_r, g_noise) for f in frames}
        ms = MeasurementSet.from_arrays(
            s,
            q,
            poses,
            metadata={"noise": {"model": "fig10", "sigma_t_m": sigma_t, "sigma_r_rad": sigma_r}},
        )
        t0 = time.perf_counter()
        model = identify_refined(ms, nominal)
        out[f"poses/{name}"] = {
            "heldout_rms_m": _heldout_rms(model, truth, q_held, None, None, frames),
            "start": model.metadata.provenance.details["start"]
            if model.metadata.provenance
            else None,
            "seconds": time.perf_counter() - t0,
        }
        pts = simulate_markers(truth, markers, q, sigma_p=sigma_p, rng=g_noise)
        t0 = time.perf_counter()
        pm = identify_points(pts, "refined", nominal, accept_inconsistent=True)
        prov = pm.metadata.provenance
        out[f"points/{name}"] = {
            "heldout_rms_m": _heldout_rms(pm, truth, q_held, marker_positions(pm), markers, frames),
            "start": prov.details["start"] if prov else None,
            "consistent": bool(prov.details["consistency"]["consistent"]) if prov else None,
            "seconds": time.perf_counter() - t0,
        }
    return out


def summarise(trials: list[dict[str, Any]]) -> dict[str, Any]:
    """Per kind and design: mean / median / max held-out RMS [mm], starts used; ratio random/protocol."""
    out: dict[str, Any] = {}
    for kind in KINDS:
        for d in DESIGNS:
            v = np.array([t[f"{kind}/{d}"]["heldout_rms_m"] for t in trials]) * 1e3
            out[f"{kind}/{d}"] = {
                "mean_mm": float(v.mean()),
                "median_mm": float(np.median(v)),
                "max_mm": float(v.max()),
                "starts": sorted({str(t[f"{kind}/{d}"]["start"]) for t in trials}),
                "seconds_mean": float(np.mean([t[f"{kind}/{d}"]["seconds"] for t in trials])),
            }
        r = np.array(
            [
                t[f"{kind}/random"]["heldout_rms_m"] / t[f"{kind}/protocol"]["heldout_rms_m"]
                for t in trials
            ]
        )
        out[f"{kind}/ratio"] = {
            "median": float(np.median(r)),
            "min": float(r.min()),
            "max": float(r.max()),
            "random_better": int(np.sum(r < 1.0)),
        }
    return out


def format_table(s: dict[str, Any], n: int, setting: str) -> str:
    lines = [
        f"# Free configurations vs the one-joint protocol ({setting}, {n} seeds)",
        "",
        "| data | design | start | held-out RMS mean [mm] | median [mm] | max [mm] | fit [s] |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    for kind in KINDS:
        for d in DESIGNS:
            e = s[f"{kind}/{d}"]
            lines.append(
                f"| {kind} | {d} | {', '.join(e['starts'])} | {e['mean_mm']:.3f} | {e['median_mm']:.3f} | "
                f"{e['max_mm']:.3f} | {e['seconds_mean']:.2f} |"
            )
    lines.append("")
    for kind in KINDS:
        r = s[f"{kind}/ratio"]
        lines.append(
            f"- {kind}: random / protocol held-out RMS, median {r['median']:.2f} (range {r['min']:.2f}-"
            f"{r['max']:.2f}); random better in {r['random_better']} of {n} seeds"
        )
    return "\n".join(lines) + "\n"


def plot(trials: list[dict[str, Any]], path: Path, setting: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, kind in zip(axes, KINDS, strict=True):
        a = np.array([t[f"{kind}/protocol"]["heldout_rms_m"] for t in trials]) * 1e3
        b = np.array([t[f"{kind}/random"]["heldout_rms_m"] for t in trials]) * 1e3
        ax.scatter(a, b, s=20)
        top = float(max(a.max(), b.max())) * 1.1
        ax.plot([0, top], [0, top], "k--", lw=1, label="equal")
        ax.set_xlim(0, top)
        ax.set_ylim(0, top)
        ax.set_xlabel("one-joint protocol: held-out RMS [mm]")
        ax.set_ylabel("random configurations: held-out RMS [mm]")
        ax.set_title(f"{kind}: one point per seed")
        ax.legend(fontsize=8)
    fig.suptitle(f"cpc2urdf study free-configs: {setting}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str]) -> int:
    """``cpc2urdf study free-configs [options]``."""
    from cpc2urdf.errors import Cpc2UrdfError
    from cpc2urdf.files.jsonio import make_folder, write_atomic, write_json

    p = OneLineParser(prog="cpc2urdf study free-configs", description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=20, help="seeded trials (default 20)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument(
        "--M",
        type=int,
        default=9,
        help="protocol readings per joint (default 9); N = 1 + n M records",
    )
    p.add_argument(
        "--sigma-mm",
        type=float,
        default=0.5,
        help="pose translation noise per entry [mm] (default 0.5)",
    )
    p.add_argument(
        "--sigma-deg", type=float, default=0.5, help="pose rotation noise angle [deg] (default 0.5)"
    )
    p.add_argument(
        "--sigma-points-mm",
        type=float,
        default=0.5,
        help="marker noise per coordinate [mm] (default 0.5)",
    )
    p.add_argument(
        "--heldout", type=int, default=100, help="held-out configurations per seed (default 100)"
    )
    p.add_argument(
        "--robot", default="iis_head", help="robot with nominal geometry (default iis_head)"
    )
    p.add_argument(
        "--out", default="study_free_configs", help="output folder (default study_free_configs)"
    )
    args = p.parse_args(argv)
    if (
        args.seeds < 1
        or args.M < 2
        or args.heldout < 1
        or min(args.sigma_mm, args.sigma_deg, args.sigma_points_mm) <= 0
    ):
        raise Cpc2UrdfError("need --seeds >= 1, --M >= 2, --heldout >= 1 and positive sigmas")
    out = make_folder(args.out)
    trials = [
        run_trial(
            args.seed + k,
            args.M,
            args.sigma_mm * 1e-3,
            math.radians(args.sigma_deg),
            args.sigma_points_mm * 1e-3,
            args.heldout,
            args.robot,
        )
        for k in progress(range(args.seeds), "free-configs")
    ]
    s = summarise(trials)
    setting = (
        f"{args.robot}, M = {args.M} ({trials[0]['records']} records), poses {args.sigma_mm:g} mm / "
        f"{args.sigma_deg:g} deg, points {args.sigma_points_mm:g} mm"
    )
    table = format_table(s, len(trials), setting)
    write_atomic(out / "free_configs.md", table)
    write_json(out / "free_configs.json", {"setting": vars(args), "summary": s, "trials": trials})
    plot(trials, out / "free_configs.png", setting)
    print(table)
    print(
        f"wrote {out / 'free_configs.md'}, {out / 'free_configs.json'}, {out / 'free_configs.png'}"
    )
    return 0


__all__ = ["main", "run_trial", "summarise"]
