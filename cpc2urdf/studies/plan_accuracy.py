"""Study: does the predicted accuracy of a plan match simulated experiments, and do optimal plans beat the protocol?

For the IIS-head and TIAGo's head (example-robot-data's URDF with a ``calib_plate`` link on
``head_2_link``, as ``tests/test_writeback.py`` builds it; the rig and placement are the
simulator's: :func:`~cpc2urdf.identification.planning.measuring.measuring_setup`), at equal N
(the paper's protocol with M values per joint, N = joints M + 1), four plans:

- ``protocol``: the paper's one-joint-at-a-time protocol (sec. 4.1);
- ``I-optimal``: greedy + exchange over 500 random candidates the rig sees, minimising the
  predicted held-out position error over the task region (the calibration ranges);
- ``I-optimal one-joint``: the same over one-joint candidates (the closed form applies);
- ``D-optimal``: the same candidates and algorithm, ``log det`` criterion.

Each plan's prediction (Cramér-Rao at the nominal model, :mod:`~cpc2urdf.identification.planning.
prediction`) is compared with ``--trials`` seeded experiments (:func:`~cpc2urdf.identification.
planning.experiment.simulate_plan`: true robot = nominal + 1 mm / 0.5 deg per placement, Fig. 10
noise; the same true robot for every plan of a seed), identified with the refinement (from the
closed form for one-joint plans, else from the nominal model), with the held-out error over the
task configurations (200, true poses). Every planned configuration is also checked visible on
every true robot with the simulator's own limits.

With ``--noise stereo`` the experiments are measured through the rig with ``--pixel-sigma`` pixel
noise (the simulator's stereo model) and the plans are made and predicted for that noise
(:class:`~cpc2urdf.identification.planning.information.StereoPoseMeasurement`): the prediction is
the sandwich covariance of the identification's scalar weighting, and the table also gives the
Cramér-Rao bound with per-view weights. Stereo noise needs circle layouts: the IIS-head only
(TIAGo's URDF plate has none).

With ``--markers K`` the setup is position-only: K markers of unknown position on each measured
frame (placed once, from the first seed, as ``simulate --markers K --seed SEED`` places them;
the same markers in every experiment, like a real setup), each point with ``--marker-sigma-mm``
noise; plans are made and predicted for that setup (:mod:`~cpc2urdf.identification.planning.
markers`), identified with :func:`~cpc2urdf.identification.kinematics.points.point_identify.
identify_points`, and the held-out error is the markers' point error (no orientation).

    cpc2urdf study plan [--trials 100] [--M 3,9] [--robots iis_head,tiago] [--noise fig10|stereo]
                        [--pixel-sigma 0.15] [--markers K --marker-sigma-mm 0.1] [--out study_plan]

Writes ``plan.md`` (table), ``plan.json`` and ``plan.png``.
"""

from __future__ import annotations

import math
import sysconfig
import time
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.progress import progress

STRATEGIES = ("protocol", "I-optimal", "I-optimal one-joint", "D-optimal")
TIAGO_PLATE = """  <link name="calib_plate"/>
  <joint name="calib_plate_joint" type="fixed">
    <parent link="head_2_link"/>
    <child link="calib_plate"/>
    <origin xyz="0.1 0.05 0.02" rpy="0.1 0.2 0.3"/>
  </joint>
"""


def tiago_with_plate(folder: Path) -> Path:
    """example-robot-data's TIAGo URDF with ``calib_plate`` on ``head_2_link`` (as tests/urdf_cases.py)."""
    from cpc2urdf.errors import ConfigurationError

    src = (
        Path(sysconfig.get_paths()["purelib"])
        / "cmeel.prefix/share/example-robot-data/robots/tiago_description/robots/tiago.urdf"
    )
    if not src.exists():
        raise ConfigurationError(
            f"TIAGo's URDF is not installed ({src}): pip install example-robot-data"
        )
    text = src.read_text()
    end = text.rindex("</robot>")
    path = folder / "tiago_plate.urdf"
    path.write_text(text[:end] + TIAGO_PLATE + text[end:])
    return path


def run_robot(
    name: str,
    folder: Path,
    M: int,
    trials: int,
    seed: int,
    *,
    noise: str = "fig10",
    pixel_sigma: float = 0.15,
    markers: int = 0,
    marker_sigma: float = 0.1e-3,
) -> dict[str, Any]:
    """Plans, predictions and observed held-out errors for one robot."""
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.planning.experiment import (
        heldout_errors,
        heldout_point_errors,
        simulate_plan,
        simulate_plan_markers,
    )
    from cpc2urdf.identification.planning.measuring import measuring_setup
    from cpc2urdf.identification.planning.plan_selection import (
        Planner,
        candidate_configurations,
        task_configurations,
    )
    from cpc2urdf.urdf.robot import load_urdf_robot

    spec = (
        load_urdf_robot(tiago_with_plate(folder), ["calib_plate"])
        if name == "tiago"
        else load_robot(name)
    )
    nominal = spec.nominal_model()
    setup = measuring_setup(
        nominal,
        noise=noise,
        pixel_sigma=pixel_sigma,
        markers=markers,
        marker_sigma=marker_sigma,
        marker_seed=seed,
    )
    q_task = task_configurations(setup)
    n = nominal.structure.n_joints * M + 1
    free = Planner(setup, candidate_configurations(setup), q_task)
    one = Planner(setup, candidate_configurations(setup, one_joint=True), q_task)
    plans = {
        "protocol": free.design("protocol", n),
        "I-optimal": free.design("I-optimal", n),
        "I-optimal one-joint": one.design("I-optimal", n),
        "D-optimal": free.design("D-optimal", n),
    }
    rows: dict[str, Any] = {}
    for strategy, (q, _) in plans.items():
        p = free.predict(q)
        rows[strategy] = {
            "predicted_position_rms_mm": p.position_rms * 1e3,
            "predicted_orientation_rms_deg": math.degrees(p.orientation_rms),
            "bound_position_rms_mm": p.bound_position_rms * 1e3,
            "rank": p.rank,
            "n_params": p.n_params,
            "ms_p": [],
            "ms_r": [],
            "starts": {},
            "unmeasurable_views": 0,
            "plan_measurable_on_nominal": bool(setup.measurable(q).all()),
        }
    t0 = time.perf_counter()
    for s in progress(range(seed, seed + trials), f"study plan {name}"):
        for strategy, (q, labels) in plans.items():
            r = rows[strategy]
            if markers:
                mexp = simulate_plan_markers(setup, q, labels, seed=s, q_heldout=q_task)
                r["unmeasurable_views"] += len(setup.problems(q, labels, model=mexp.truth))
                err, start = heldout_point_errors(mexp, nominal)
                r["ms_p"].append(float(np.mean(err**2)))
                r["ms_r"].append(math.nan)
                r["starts"][start] = r["starts"].get(start, 0) + 1
                continue
            exp = simulate_plan(
                setup, q, labels, seed=s, noise=noise, q_heldout=q_task, require_view=False
            )
            r["unmeasurable_views"] += len(exp.measured.metadata["provenance"]["view"]["problems"])
            e = heldout_errors(exp, nominal)
            r["ms_p"].append(float(np.mean(e.position**2)))
            r["ms_r"].append(float(np.mean(e.angle**2)))
            r["starts"][e.start] = r["starts"].get(e.start, 0) + 1
    for r in rows.values():
        obs = math.sqrt(float(np.mean(r["ms_p"]))) * 1e3
        r["observed_position_rms_mm"] = obs
        r["observed_orientation_rms_deg"] = math.degrees(math.sqrt(float(np.mean(r["ms_r"]))))
        r["ratio_observed_predicted"] = obs / r["predicted_position_rms_mm"]
        r["ratio_orientation"] = (
            r["observed_orientation_rms_deg"] / r["predicted_orientation_rms_deg"]
        )
        # Spread of the observed RMS from trial to trial (bootstrap-free: std of the per-trial MS).
        r["observed_rms_rel_se"] = float(
            np.std(r["ms_p"]) / np.mean(r["ms_p"]) / math.sqrt(len(r["ms_p"])) / 2
        )
    base = rows["protocol"]["observed_position_rms_mm"]
    for r in rows.values():
        r["vs_protocol"] = r["observed_position_rms_mm"] / base
        for k, v in r.items():  # marker setups predict and observe no orientation: null, not NaN
            if isinstance(v, float) and math.isnan(v):
                r[k] = None
    curve = [
        (c.strategy, c.n, c.position_rms * 1e3)
        for c in free.curve(
            [nominal.structure.n_joints * m + 1 for m in (2, 3, 5, 9)],
            ("I-optimal", "D-optimal", "protocol"),
        )
    ]
    return {
        "robot": name,
        "N": n,
        "M": M,
        "trials": trials,
        "seconds": time.perf_counter() - t0,
        "noise": noise,
        "pixel_sigma_px": pixel_sigma if noise == "stereo" else None,
        "markers": markers,
        "marker_sigma_mm": marker_sigma * 1e3 if markers else None,
        "n_task": len(q_task),
        "rows": rows,
        "curve": curve,
    }


def table(results: list[dict[str, Any]]) -> str:
    lines = [
        "| robot | noise | N | plan | predicted RMS [mm] | observed RMS [mm] | observed / predicted "
        "| orientation pred / obs [deg] | vs protocol | bound, per-view weights [mm] | views not measurable "
        "| refinement start |",
        "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for res in results:
        for strategy, r in res["rows"].items():
            starts = ", ".join(f"{k} {v}" for k, v in r["starts"].items())
            lines.append(
                f"| {res['robot']} | {_noise(res)} | {res['N']} | {strategy} | {r['predicted_position_rms_mm']:.3f} | "
                f"{r['observed_position_rms_mm']:.3f} | {r['ratio_observed_predicted']:.3f} | "
                f"{_f(r['predicted_orientation_rms_deg'])} / {_f(r['observed_orientation_rms_deg'])} | "
                f"{r['vs_protocol']:.2f} | {r['bound_position_rms_mm']:.3f} | {r['unmeasurable_views']} | {starts} |"
            )
    return "\n".join(lines) + "\n"


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def _noise(res: dict[str, Any]) -> str:
    if res.get("markers"):
        return f"{res['markers']} markers/frame, {res['marker_sigma_mm']:g} mm"
    return f"stereo {res['pixel_sigma_px']:g} px" if res.get("noise") == "stereo" else "fig10"


def plot(results: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(2, len(results))
    rows = math.ceil(len(results) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 4.5 * rows), squeeze=False)
    for ax in axes.ravel()[len(results) :]:
        ax.set_visible(False)
    for ax, res in zip(axes.ravel(), results, strict=False):
        for strategy, style in (("I-optimal", "o-"), ("D-optimal", "s--"), ("protocol", "^:")):
            pts = sorted((n, v) for s, n, v in res["curve"] if s == strategy)
            ax.plot(
                [p[0] for p in pts], [p[1] for p in pts], style, label=f"{strategy} (predicted)"
            )
        for k, (strategy, r) in enumerate(res["rows"].items()):
            ax.plot(
                [res["N"] + 0.4 * (k - 1.5)],
                [r["observed_position_rms_mm"]],
                "x",
                ms=9,
                label=f"{strategy}: observed over {res['trials']} experiments",
            )
        ax.set_xlabel("configurations measured N")
        ax.set_ylabel("held-out RMS position error [mm]")
        ax.set_title(f"{res['robot']}, {_noise(res)}, N = {res['N']} (protocol M = {res['M']})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str]) -> int:
    """``cpc2urdf study plan [options]``."""
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import make_folder, write_atomic, write_json

    p = OneLineParser(prog="cpc2urdf study plan", description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--trials", type=int, default=100, help="seeded experiments per plan (default 100)"
    )
    p.add_argument(
        "--M",
        default="3,9",
        help="protocol values per joint, comma-separated; N = joints M + 1 (default 3,9)",
    )
    p.add_argument(
        "--robots",
        default="iis_head,tiago",
        help="robots: iis_head, tiago, a spec (default iis_head,tiago)",
    )
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument(
        "--noise",
        choices=("fig10", "stereo"),
        default="fig10",
        help="fig10: pose noise 0.5 mm / 0.5 deg; stereo: pixel noise through the rig (default fig10)",
    )
    p.add_argument(
        "--pixel-sigma",
        type=float,
        default=0.15,
        help="stereo: pixel noise per coordinate [px] (default 0.15)",
    )
    p.add_argument(
        "--markers",
        type=int,
        default=0,
        metavar="K",
        help="position-only data: K markers of unknown position on each measured frame (default 0: poses)",
    )
    p.add_argument(
        "--marker-sigma-mm",
        type=float,
        default=0.1,
        help="--markers: noise per point coordinate [mm] (default 0.1)",
    )
    p.add_argument("--out", default="study_plan", help="output folder (default study_plan)")
    args = p.parse_args(argv)
    try:
        Ms = [int(v) for v in args.M.split(",")]
    except ValueError:
        raise ConfigurationError(f"--M {args.M!r}: expected integers like 3,9") from None
    if args.trials < 1 or min(Ms) < 2:
        raise ConfigurationError("--trials must be >= 1 and every --M >= 2")
    if not (math.isfinite(args.pixel_sigma) and args.pixel_sigma > 0):
        raise ConfigurationError(
            f"--pixel-sigma must be a positive number of px, got {args.pixel_sigma}"
        )
    if args.markers < 0 or not (math.isfinite(args.marker_sigma_mm) and args.marker_sigma_mm > 0):
        raise ConfigurationError(
            "--markers must be >= 0 and --marker-sigma-mm a positive number of mm"
        )
    out = make_folder(args.out)
    results = [
        run_robot(
            r,
            out,
            M,
            args.trials,
            args.seed,
            noise=args.noise,
            pixel_sigma=args.pixel_sigma,
            markers=args.markers,
            marker_sigma=args.marker_sigma_mm * 1e-3,
        )
        for r in args.robots.split(",")
        for M in Ms
    ]
    for res in results:
        for r in res["rows"].values():
            del r["ms_p"], r["ms_r"]
    text = table(results)
    write_atomic(out / "plan.md", text)
    write_json(out / "plan.json", {"results": results})
    plot(results, out / "plan.png")
    print(text)
    return 0
